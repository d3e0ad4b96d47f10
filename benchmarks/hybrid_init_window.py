"""Issue 34, item 1: a hybrid trained from its FMU's estimator against one trained from the init rule.

The truth is the two tanks of examples/two_tanks.py with an upper tank that overflows into the lower one above
``H_MAX`` (the Cascaded Tanks benchmark's effect); the user's model (examples/two_tanks.py) has no overflow,
and only the lower level is measured. The commands a user runs:

1. ``nnfmu fit examples/two_tanks.py:two_tanks --init-window N``: the outlet areas and the pump gain, scored
   from the state the FMU's estimator fits over the first N samples;
2. ``nnfmu train --arch hybrid --physics fit.json``, over whole records (the default) and over windows of
   ``--truncate`` samples cut inside them, each
   - at the default (``--init-window 1``): every window starts from the init rule at its first sample (the
     upper tank at rest);
   - with ``--init-window N``: every window starts from the estimator's state, as the FMU will.

Each hybrid is scored as its FMU with an init window of N runs (``nnfmu export --init-window N``; the torch
model with the same weights and the estimator, which equals the FMU to 1e-9, tests/test_hybrid_trained_window.py):
free-run NRMSE after the window, on validation and (reported only) on test. CPU seconds of each command.

    python benchmarks/hybrid_init_window.py                     # N = 20, 100 epochs, windows of 50
    python benchmarks/hybrid_init_window.py --epochs 40 --seeds 0 1
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
import time
from pathlib import Path

import casadi as ca
import torch

from nnfmu.cli import main as nnfmu
from nnfmu.data import load_dataset, save_dataset
from nnfmu.greybox import load_fit
from nnfmu.models import build_model, load_model
from nnfmu.physics import ModelBuilder, generate_model_dataset
from nnfmu.training.evaluate import free_run_nrmse

ROOT = Path(__file__).resolve().parents[1]
USER_MODEL = f"{ROOT / 'examples' / 'two_tanks.py'}:two_tanks"
H_MAX = 0.25  # m: the upper tank's rim
G, H_EPS = 9.81, 1e-3


def _outflow(a, h):
    return a * ca.sqrt(2 * G) * h / (h * h + H_EPS * H_EPS) ** 0.25


def tanks_overflow():
    """The truth: examples/two_tanks.py, plus the upper tank's overflow into the lower one above H_MAX."""
    m = ModelBuilder("tanks_overflow", Ts=1.0, n_sub=2, settle_time=100.0,
                     description="two tanks in cascade; the upper one overflows into the lower")
    h1 = m.state("h1", "m", "level of the upper tank", scale=0.3)
    h2 = m.state("h2", "m", "level of the lower tank", scale=0.3)
    u = m.input("u", "V", "pump voltage", min=0.0, max=10.0)
    A1, A2 = m.parameter("A1", 0.0154, "m2"), m.parameter("A2", 0.0154, "m2")
    a1, a2 = m.parameter("a1", 5e-5, "m2"), m.parameter("a2", 6e-5, "m2")
    k_p = m.parameter("k_p", 1.5e-5, "m3/(s.V)")
    k_o = m.parameter("k_o", 2e-3, "m2/s", "overflow conductance above the rim")
    over = k_o * ca.log1p(ca.exp((h1 - H_MAX) / 0.005)) * 0.005  # smooth max(h1 - H_MAX, 0), in m
    m.ode(h1=(k_p * u - _outflow(a1, h1) - over) / A1,
          h2=(_outflow(a1, h1) + over - _outflow(a2, h2)) / A2)
    y0 = m.output("h2", "m", "measured level of the lower tank", h2, start=0.1, min=0.0, max=0.5)
    m.init(h1=y0 * (a2 / a1) ** 2)
    return m.build()


def _quiet(args) -> float:
    """Run one nnfmu command, its output swallowed; CPU seconds of this process."""
    start = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = nnfmu([str(a) for a in args])
    if code != 0:
        raise SystemExit(f"nnfmu {' '.join(map(str, args))} exited {code}")
    return time.process_time() - start


def _scores(path: Path, ds, window: int) -> tuple[float, float]:
    """(valid, test) free-run NRMSE after an init window of ``window``, from the estimator, as the FMU runs."""
    model = load_model(path).double()
    if model.config.init_window != window:  # the same weights, started by the FMU's estimator
        twin = build_model(model.config.replace(init_window=window), model.meta).double()
        twin.load_state_dict(model.state_dict())
        model = twin
    return tuple(free_run_nrmse(model, split, float64=True, context=window).mean for split in (ds.valid, ds.test))


def run(work: Path, *, window: int, epochs: int, truncate: int, seed: int) -> None:
    truth = f"{Path(__file__).resolve()}:tanks_overflow"
    data = save_dataset(generate_model_dataset(truth, size="small", noise=0.01, seed=seed), work / f"data{seed}")
    ds = load_dataset(data)
    fit = work / f"fit{seed}.json"
    seconds = _quiet(["fit", USER_MODEL, "--data", data, "--init-window", window, "-o", fit, "--quiet",
                                   "--report-test"])
    scores = load_fit(fit)[1]["scores"]
    print(f"\nseed {seed}: the fit (no overflow), scored after its window of {window}: valid "
          f"{scores['valid']['nrmse']:.4f}, test {scores['test']['nrmse']:.4f}, {seconds:.0f} CPU s")
    print("| windows | the hybrid starts each from | valid | test (reported) | CPU s |")
    print("|---|---|---:|---:|---:|")
    for cut in (None, truncate):
        for start, option in (("the init rule (the default)", []),
                              (f"the estimator (`--init-window {window}`)", ["--init-window", window])):
            out = work / f"h{seed}_{cut}_{len(option)}.pt"
            args = ["train", "--data", data, "--arch", "hybrid", "--physics", fit, "--epochs", epochs,
                    "--seed", seed, "-o", out, *option, *(["--truncate", cut] if cut else [])]
            seconds = _quiet(args)
            valid, test = _scores(out, ds, window)
            print(f"| {'whole records' if cut is None else f'{cut} samples'} | {start} | {valid:.4f} | {test:.4f} "
                  f"| {seconds:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--window", type=int, default=20)
    parser.add_argument("--epochs", type=int, default=100)
    parser.add_argument("--truncate", type=int, default=50)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    args = parser.parse_args()
    torch.set_num_threads(1)
    names = [line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
             if line.startswith("model name")] if Path("/proc/cpuinfo").exists() else []
    print(f"CPU: {names[0] if names else 'unknown'} ({torch.backends.cpu.get_cpu_capability()}); one torch thread")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            run(Path(tmp), window=args.window, epochs=args.epochs, truncate=args.truncate, seed=seed)


if __name__ == "__main__":
    main()
