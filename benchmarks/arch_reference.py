"""Record, then compare, what the six networks give from one fixed seed: the redesign of the architecture
records (issue 35) must change no number.

    python benchmarks/arch_reference.py record DIR     # trains mlp, rnn, lstm, gru, tcn, ss for 2 epochs
    python benchmarks/arch_reference.py compare A B    # bit-identical weights, CasADi outputs and NRMSE lines

``record`` runs the ``nnfmu`` that ``PYTHONPATH`` selects: run it once in the tree before the change and once
in the tree after it, then ``compare`` the two folders. Every weight, every CasADi free-run output and every
printed NRMSE must be equal to the last bit; the script exits 1 naming what differs.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ARCHS = ("mlp", "rnn", "lstm", "gru", "tcn", "ss")
#: Each network on the linear path the data give (the default), and alone (``--linear-path off``).
RUNS = ARCHS + tuple(f"{a}-alone" for a in ARCHS if a != "ss")


def _nnfmu(*args: str) -> str:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-m", "nnfmu", *args], env=env, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"nnfmu {' '.join(args)} failed:\n{out.stderr}")
    return out.stdout + out.stderr


def _casadi_run(ckpt: Path) -> "object":
    """The exported CasADi model's free run on a fixed input (float64), from the checkpoint."""
    import numpy as np

    from nnfmu.export import to_casadi
    from nnfmu.models import load_model

    model = load_model(ckpt).double()
    init, step = to_casadi(model, verify=True)
    rng = np.random.default_rng(0)
    x = init(*[rng.standard_normal(init.sparsity_in(i).shape) for i in range(init.n_in())])
    u = rng.standard_normal((50, model.config.n_u))
    ys = []
    for k in range(len(u)):
        x, y = step(x, u[k])
        ys.append(np.asarray(y).ravel())
    return np.array(ys)


def record(folder: Path) -> None:
    import numpy as np

    data = folder / "slider"
    folder.mkdir(parents=True, exist_ok=True)
    if not data.exists():
        _nnfmu("generate", "slider", "--size", "small", "-o", str(data), "--quiet")
    for arch in RUNS:
        name, _, off = arch.partition("-")
        ckpt = folder / f"{arch}.pt"
        log = _nnfmu("train", "--data", str(data), "--arch", name, "--epochs", "2", "--patience", "0", "--seed", "0",
                     "--threads", "1", "--quiet", "--force", "-o", str(ckpt), *(["--linear-path", "off"] if off else []))
        (folder / f"{arch}.log").write_text(log)
        np.save(folder / f"{arch}_casadi.npy", _casadi_run(ckpt))
        print(arch, " | ".join(_nrmse_lines(log)))


def _nrmse_lines(log: str) -> list[str]:
    """The lines with an NRMSE, without what may differ between two runs: paths and timings."""
    lines = [line.strip() for line in log.splitlines() if re.search(r"nrmse", line, re.I)]
    return [re.sub(r"[\d.]+ CPU-s|checkpoint \S+", "", line) for line in lines]


def compare(a: Path, b: Path) -> int:
    import numpy as np
    import torch

    bad = []
    for arch in RUNS:
        sa = torch.load(a / f"{arch}.pt", weights_only=False)
        sb = torch.load(b / f"{arch}.pt", weights_only=False)
        wa, wb = sa["state_dict"], sb["state_dict"]
        if wa.keys() != wb.keys() or not all(torch.equal(wa[k], wb[k]) for k in wa):
            bad.append(f"{arch}: weights differ")
        if sa["model_config"] != sb["model_config"]:
            bad.append(f"{arch}: configs differ: {sa['model_config']} / {sb['model_config']}")
        if not np.array_equal(np.load(a / f"{arch}_casadi.npy"), np.load(b / f"{arch}_casadi.npy")):
            bad.append(f"{arch}: CasADi free runs differ")
        la, lb = (_nrmse_lines((f / f"{arch}.log").read_text()) for f in (a, b))
        if la != lb or not la:
            bad.append(f"{arch}: NRMSE lines differ or are missing: {la} / {lb}")
        print(arch, "identical" if not any(m.startswith(arch + ":") for m in bad) else "DIFFERENT",
              "|", " | ".join(la))
    for message in bad:
        print(message)
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "record":
        record(Path(sys.argv[2]))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        raise SystemExit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        raise SystemExit(__doc__)
