"""fmusim, the Reference FMUs' importer (v0.0.39), on nnfmu's FMUs: the strictest importer users meet.

Marked slow: it builds ten FMUs (about 100 s on 2 cores).

- every kind of FMU nnfmu exports passes fmusim's validation of ``modelDescription.xml`` against the FMI 2 and 3
  schemas, and runs in co-simulation;
- Model Exchange integrated by fmusim's CVode, with each input step given as an event (two rows at one time),
  agrees with co-simulation (RK4 at Ts) for a physics model, a hybrid and a model of the user's own, FMI 2 and
  3, to :data:`ME_CS_TOLERANCE` of each output's range (docs/fmu-platforms.md);
- a co-simulation saved with ``--final-fmu-state-file`` and resumed in a fresh process with
  ``--initial-fmu-state-file`` continues bit-identically, with the plain v0.0.39 (whose FreeFMUState bug the FMU
  survives).

fmusim is built once from ``../shared/tools/fmusim`` (beside the repository) into pytest's cache; set
``NNFMU_FMUSIM`` to use a binary built elsewhere. Where it cannot be built, every test here skips with the reason.
"""

from __future__ import annotations

import csv
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from fmu_cases import oscillator_dataset
from test_fmu_model_exchange import _hybrid

from nnfmu.cli import main as nnfmu_main
from nnfmu.export import build_fmu, casadi_model
from nnfmu.physics import resolve_physics

SOURCES = Path(__file__).resolve().parents[2] / "shared" / "tools" / "fmusim"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: CVode (fmusim's default relative tolerance) against the FMU's RK4 at Ts, as a fraction of each output's range.
ME_CS_TOLERANCE = 1e-4

pytestmark = [pytest.mark.usefixtures("one_thread"), pytest.mark.slow]


def _build(cache: Path) -> Path | str:
    """fmusim built into ``cache`` (or the reason it could not be)."""
    script, archive = SOURCES / "build.sh", SOURCES / "reference-fmus-v0.0.39-fmusim-src.tar.gz"
    if not script.is_file() or not archive.is_file():
        return f"its sources are not at {SOURCES} (build.sh and the archive)"
    done = cache / f"fmusim-{hashlib.sha1(script.read_bytes() + archive.read_bytes()).hexdigest()[:12]}"
    if (done / "fmusim").is_file():
        return done / "fmusim"
    partial = cache / f".{done.name}.{os.getpid()}"  # a parallel session builds its own and the first rename wins
    run = subprocess.run(["bash", str(script), str(partial)], capture_output=True, text=True, timeout=900)
    if run.returncode != 0 or not (partial / "fmusim").is_file():
        shutil.rmtree(partial, ignore_errors=True)
        return f"build.sh failed: {(run.stderr.strip().splitlines() or ['no message'])[-1]}"
    try:
        partial.rename(done)
    except OSError:
        shutil.rmtree(partial, ignore_errors=True)
    return done / "fmusim"


@pytest.fixture(scope="session")
def fmusim(request, tmp_path_factory) -> Path:
    if os.environ.get("NNFMU_FMUSIM"):
        return Path(os.environ["NNFMU_FMUSIM"])
    cache = getattr(request.config, "cache", None)  # None under -p no:cacheprovider: build it for this run only
    built = _build(Path(cache.mkdir("fmusim")) if cache is not None else tmp_path_factory.mktemp("fmusim"))
    if isinstance(built, str):
        pytest.skip(f"fmusim cannot be built here: {built}")
    return built


def run_fmusim(fmusim: Path, fmu: Path, out: Path, *options: str) -> np.ndarray:
    """fmusim's output CSV as an array (time first); the run must succeed."""
    run = subprocess.run([str(fmusim), *options, "--output-file", str(out), str(fmu)], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, f"fmusim {' '.join(options)} {fmu.name}: {run.stderr or run.stdout}"
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    return np.array(rows[1:], dtype=float)


def write_inputs(path: Path, t: np.ndarray, u: np.ndarray, names: list[str], events: bool) -> Path:
    """fmusim's input CSV: ``time`` then one column per input; with ``events`` every step is two rows at its time,
    the old value then the new, so that CVode meets an event rather than a ramp."""
    row = lambda time, values: ",".join(f"{float(v):.17g}" for v in (time, *values))  # noqa: E731
    lines = [",".join(["time", *names])]
    for k in range(len(t)):
        if events and k and np.any(u[k] != u[k - 1]):
            lines.append(row(t[k], u[k - 1]))
        lines.append(row(t[k], u[k]))
    path.write_text("\n".join(lines) + "\n")
    return path


def held(inputs, n: int, hold: int, seed: int = 0) -> np.ndarray:
    """Piecewise-constant inputs (n, n_u) inside each input's range, a new value every ``hold`` samples."""
    rng = np.random.default_rng(seed)
    lo = np.array([-1.0 if v.min is None else v.min for v in inputs])
    hi = np.array([1.0 if v.max is None else v.max for v in inputs])
    return np.repeat(lo + (hi - lo) * rng.uniform(0.1, 0.9, size=(n // hold + 1, len(inputs))), hold, axis=0)[:n]


CASES = {  # kind -> the physics-fmu SPEC
    "physics": "valve",
    "user": f"{EXAMPLES / 'two_tanks.py'}:two_tanks",
}


class ModelExchangeFmus(dict):
    """Model Exchange FMUs, built on first use: ``[kind, version]`` -> (path, inputs, Ts) for a built-in physics
    model, a model file of the user's own and a hybrid, FMI ``"2"`` or ``"3"``."""

    def __init__(self, root: Path):
        super().__init__()
        self.root = root

    def __missing__(self, key):
        kind, version = key
        out = self.root / f"{kind}{version}.fmu"
        if kind == "hybrid":
            model = casadi_model(_hybrid(), name="valve_hybrid")
            build_fmu(model, out, fmi_version=int(version))
            self[key] = (out, resolve_physics("valve").inputs, model.spec.Ts)
        else:
            assert nnfmu_main(["physics-fmu", CASES[kind], "--fmi-version", version, "-o", str(out)]) == 0
            system = resolve_physics(CASES[kind])
            self[key] = (out, system.inputs, system.Ts)
        return self[key]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return ModelExchangeFmus(tmp_path_factory.mktemp("fmusim"))


@pytest.mark.parametrize("version", ["2", "3"])
@pytest.mark.parametrize("kind", ["physics", "hybrid", "user"])
def test_fmusim_model_exchange_with_cvode_at_input_steps_matches_co_simulation(fmusim, fmus, tmp_path, kind,
                                                                               version):
    fmu, inputs, Ts = fmus[kind, version]
    n, hold = 500, 25  # 20 ms of the valve, as docs/fmu-platforms.md measures
    t, u = np.arange(n) * Ts, held(inputs, n, hold)
    names = [v.name for v in inputs]
    stop = ["--stop-time", repr((n - 1) * Ts), "--output-interval", repr(Ts)]
    cs = run_fmusim(fmusim, fmu, tmp_path / "cs.csv", "--interface-type", "cs", *stop,
                    "--input-file", str(write_inputs(tmp_path / "u_cs.csv", t, u, names, events=False)))
    me = run_fmusim(fmusim, fmu, tmp_path / "me.csv", "--interface-type", "me", "--solver", "cvode",
                    "--tolerance", "1e-10", *stop,
                    "--input-file", str(write_inputs(tmp_path / "u_me.csv", t, u, names, events=True)))
    at_samples = [np.flatnonzero(np.abs(me[:, 0] - k * Ts) < 1e-6 * Ts)[-1] for k in range(n)]  # after events
    me = me[at_samples]
    np.testing.assert_allclose(me[:, 0], cs[:, 0], rtol=0, atol=1e-9 * n * Ts)
    error = np.abs(me[:, 1:] - cs[:, 1:]).max(axis=0) / np.ptp(cs[:, 1:], axis=0)
    print(f"{kind} FMI {version}: ME (CVode) against CS, max error / range per output: {error}")
    assert error.max() < ME_CS_TOLERANCE, error


@pytest.mark.parametrize("version", ["2", "3"])
def test_fmusim_saves_and_resumes_a_co_simulation_bit_identically(fmusim, fmus, tmp_path, version):
    fmu, inputs, Ts = fmus["user", version]
    n = 120
    t, u = np.arange(n) * Ts, held(inputs, n, 10, seed=1)
    signal = write_inputs(tmp_path / "u.csv", t, u, [v.name for v in inputs], events=False)
    common = ["--interface-type", "cs", "--output-interval", repr(Ts), "--input-file", str(signal)]
    middle, end, state = repr(60 * Ts), repr((n - 1) * Ts), tmp_path / "state.bin"
    full = run_fmusim(fmusim, fmu, tmp_path / "full.csv", *common, "--stop-time", end)
    run_fmusim(fmusim, fmu, tmp_path / "first.csv", *common, "--stop-time", middle, "--final-fmu-state-file",
               str(state))
    resumed = run_fmusim(fmusim, fmu, tmp_path / "second.csv", *common, "--start-time", middle, "--stop-time", end,
                         "--initial-fmu-state-file", str(state))
    assert state.stat().st_size > 0 and len(resumed) == n - 60
    np.testing.assert_array_equal(resumed, full[60:])  # bit-identical after a fresh process restored the state


@pytest.fixture(scope="module")
def every_kind(tmp_path_factory):
    """The kinds of FMU nnfmu exports beyond the Model Exchange ones (which fmusim loads, and so validates, in the
    tests above): the linear baseline, a network (FMI 2 and 3), a physics model in co-simulation only."""
    root = tmp_path_factory.mktemp("kinds")
    data = str(oscillator_dataset(root / "data"))
    made = {}
    assert nnfmu_main(["linear", "--data", data, "--order", "2", "--no-refine", "--quiet",
                       "-o", str(root / "linear.fmu")]) == 0
    assert nnfmu_main(["train", "--data", data, "--arch", "gru", "--hidden", "4", "--epochs", "1", "--seeds", "1",
                       "--linear-path", "off", "--quiet", "-o", str(root / "gru.pt")]) == 0
    for version in ("2", "3"):
        assert nnfmu_main(["export", str(root / "gru.pt"), "--fmi-version", version,
                           "-o", str(root / f"gru{version}.fmu")]) == 0
        made[f"network FMI {version}"] = root / f"gru{version}.fmu"
    assert nnfmu_main(["physics-fmu", "slider", "--no-model-exchange", "-o", str(root / "cs_only.fmu")]) == 0
    made["linear"], made["co-simulation only"] = root / "linear.fmu", root / "cs_only.fmu"
    return made


def test_fmusim_validates_and_runs_every_kind_of_exported_fmu(fmusim, every_kind, tmp_path):
    """fmusim validates modelDescription.xml against the FMI schema as it loads an FMU, and refuses one that fails
    (an unknown attribute: "The attribute 'bogus' is not allowed", status 3)."""
    for name, fmu in every_kind.items():
        out = run_fmusim(fmusim, fmu, tmp_path / "out.csv", "--interface-type", "cs", "--stop-time", "0")
        assert out.shape[0] >= 1, name
