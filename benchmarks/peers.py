"""nnfmu against deepSI 0.4.4 and tsfast 0.5.0: trajectory-steps per CPU-second and free-run test NRMSE.

Every contender trains on the same arrays (generated valve data, 5 % measurement noise as in
the study, 10 % of the training trajectories set aside for validation) for the same CPU
budget: process CPU time, one torch thread, pinned to one core (``taskset``), the
contenders interleaved round by round. Each uses its own training loop with its defaults:

- nnfmu: ``nnfmu.train`` (GRU-32, parallel, batch 64, validation free run and best-epoch
  keeping every epoch; whole trajectories, or windows of ``--truncate`` samples);
- deepSI: ``deepSI.fit`` (windows of T=50, batch 256, Adam, validation every 250 iterations)
  on its own SUBNET model (``deepsi-subnet``: deepSI 0.4.4 has no recurrent network, so this is
  its closest real model), and on nnfmu's GRU-32 with output feedback written in torch as a
  deepSI ``Custom_SUBNET`` (``deepsi-fit-nnfmu-gru``: deepSI's training loop, nnfmu's network);
- tsfast: ``AR_RNNLearner`` (``tsfast-ar-gru``: its output-feedback GRU-32, trained one step
  ahead with the measured outputs fed back, free-run at test; see peers_train.py), windows of
  100, batch 64, 300 batches per epoch, validation every epoch; ``RNNLearner`` (``tsfast-gru``:
  a GRU-32 from inputs to outputs only) on request.

A trajectory-step is one sample of one training sequence through forward pass, backward pass
and update; the CPU time includes everything else the loop does (validation, batching). The
peers receive the arrays standardised with the training statistics (nnfmu standardises inside
its models). Every model is scored the same way: given the first 50 measured samples of each
test trajectory (to set its state: nnfmu and the deepSI-fit GRU start from sample 49, SUBNET's
encoder reads 20 samples, tsfast's GRUs run through them), NRMSE of the free run over the rest
(docs/design.md's rule: mean over outputs and trajectories of RMSE / std).

Installing the peers (once, into their own virtual environment: their dependencies are not
nnfmu's, and torch must be the CPU wheel, pinned first as in the Makefile)::

    python3 -m venv peers-venv
    peers-venv/bin/pip install torch==2.13.0
    echo "torch==2.13.0" > constraints.txt
    peers-venv/bin/pip install -c constraints.txt deepSI==0.4.4 tsfast==0.5.0

or, without a second torch, into a folder on top of nnfmu's environment (which already has
numpy, scipy, h5py, pandas, tqdm and nonlinear_benchmarks; ``--no-deps`` keeps pip off torch)::

    .venv/bin/pip install --no-deps --target /tmp/peers deepSI==0.4.4 tsfast==0.5.0 identibench==0.4.0 cloudpickle
    export PYTHONPATH=/tmp/peers   # then pass --peers-python .venv/bin/python

Running (from the repository, with nnfmu's own environment)::

    python benchmarks/peers.py --peers-python peers-venv/bin/python --sets small --budget 20 --rounds 3 \
        --truncate 200

It prints each contender's rate and NRMSE in every round, so the spread over repeats shows.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
INIT = 50  # as peers_train.INIT
HIDDEN = 32
CONTENDERS = ("nnfmu", "deepsi-subnet", "deepsi-fit-nnfmu-gru", "tsfast-ar-gru", "tsfast-gru")
DEFAULT_CONTENDERS = ("nnfmu", "deepsi-subnet", "deepsi-fit-nnfmu-gru", "tsfast-ar-gru")


def make_data(size: str, seed: int, folder: Path) -> Path:
    """The valve set (noise, validation carved out) as an nnfmu dataset folder and standardised arrays."""
    from nnfmu.data import save_dataset
    from nnfmu.physics import generate_dataset

    ds = generate_dataset("valve", size=size, seed=seed).with_measurement_noise(0.05, seed=seed)
    ds = ds.with_validation(0.1, seed=seed)
    save_dataset(ds, folder / "dataset")
    st = ds.norm_stats("train")
    arrays = {}
    for split in ("train", "valid", "test"):
        tr = ds.split(split)
        arrays[f"{split}_u"] = (np.stack(tr.u) - st.u_mean) / st.u_std
        arrays[f"{split}_y"] = (np.stack(tr.y) - st.y_mean) / st.y_std
    np.savez(folder / "arrays.npz", **arrays)
    return folder


def train_nnfmu(data: Path, out: Path, budget_s: float, seed: int, truncate: int | None) -> None:
    """The nnfmu worker: ``nnfmu.train`` until ``budget_s`` CPU-seconds, then the test free runs."""
    import torch

    from nnfmu.data import load_dataset
    from nnfmu.models import ModelConfig
    from nnfmu.training import StopTraining, TrainConfig, train

    ds = load_dataset(data / "dataset")
    fit_on = ds.replace(splits={"train": ds.train, "valid": ds.valid})  # no test scoring inside the budget
    trained = count_trained_steps()
    cpu0, wall0 = time.process_time(), time.perf_counter()

    def stop_when_spent(epoch: int, metrics: dict) -> None:
        if time.process_time() - cpu0 > budget_s:
            raise StopTraining

    result = train(fit_on, ModelConfig(arch="gru", n_u=ds.n_u, n_y=ds.n_y, hidden=HIDDEN),
                   TrainConfig(epochs=10**6, patience=0, seed=seed, truncate=truncate), callback=stop_when_spent)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    epochs = len(result.history) - 1
    test = ds.test
    pred = np.full(np.stack(test.y).shape, np.nan)
    for i, (u, y) in enumerate(zip(test.u, test.y)):
        pred[i, INIT:] = result.model.simulate(u[INIT - 1:], y[INIT - 1])[1:]
    st = ds.norm_stats("train")
    np.savez(out.with_suffix(".npz"), pred=(pred - st.y_mean) / st.y_std)
    info = {"trajectory_steps": trained[0], "cpu_s": cpu, "wall_s": wall, "epochs": epochs,
            "batch_size": 64, "truncate": truncate, "torch": torch.__version__}
    out.with_suffix(".json").write_text(json.dumps(info))


def count_trained_steps() -> list[int]:
    """A counter of the samples in every batch nnfmu's trainer draws (windows, no padding), updated as it trains."""
    import nnfmu.training.session as session

    drawn, counted = session.epoch_batches, [0]

    def counting(*args, **kwargs):
        for batch in drawn(*args, **kwargs):
            counted[0] += int(batch.un.shape[0] * batch.un.shape[1]) if batch.mask is None else int(batch.mask.sum())
            yield batch

    session.epoch_batches = counting
    return counted


def run_worker(name: str, data: Path, out: Path, args) -> dict:
    """One pinned training of ``name``; returns its JSON report with the test NRMSE added."""
    if name == "nnfmu":
        command = [sys.executable, __file__, "--worker", str(data), "--out", str(out)]
        command += [] if args.truncate is None else ["--truncate", str(args.truncate)]
    else:
        command = [args.peers_python, str(HERE / "peers_train.py"), name, "--arrays", str(data / "arrays.npz"),
                   "--out", str(out)]
    command += ["--budget", str(args.budget), "--seed", str(args.seed)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(["taskset", "-c", str(args.cpu), *command], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{name} failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    report = json.loads(out.with_suffix(".json").read_text())
    report["nrmse"] = score(np.load(out.with_suffix(".npz"))["pred"], np.load(data / "arrays.npz")["test_y"])
    return report


def score(pred: np.ndarray, y: np.ndarray) -> float:
    """Mean over trajectories and outputs of RMSE / std over samples INIT.. (standardised units: same ratio)."""
    from nnfmu.metrics import nrmse

    return nrmse([t[INIT:] for t in y], [p[INIT:] for p in pred]).mean


def warm_up() -> None:
    """Compile nnfmu's C free run before any timing (a cached library is loaded, not rebuilt)."""
    import torch

    from nnfmu.models import ModelConfig, build_model
    from nnfmu.training.compiled_rollout import compiled_rollout

    for dtype in (torch.float32, torch.float64):
        compiled_rollout(build_model(ModelConfig(arch="gru", n_u=1, n_y=1, hidden=2)).to(dtype))


def report(size: str, results: dict) -> None:
    rates = {k: [r["trajectory_steps"] / r["cpu_s"] for r in v] for k, v in results.items()}
    rounds = len(next(iter(rates.values())))
    print(f"\nvalve {size}: trajectory-steps per CPU-second (median of {rounds} interleaved runs), "
          "free-run test NRMSE (median; each run in brackets)")
    base = statistics.median(rates["nnfmu"]) if "nnfmu" in rates else None
    for name, runs in results.items():
        rate, nrmse_ = statistics.median(rates[name]), statistics.median(r["nrmse"] for r in runs)
        ratio = "" if name == "nnfmu" or base is None else (
            f"   nnfmu / {name}: {base / rate:.2f}x (rounds: "
            + ", ".join(f"{a / b:.2f}" for a, b in zip(rates["nnfmu"], rates[name])) + ")")
        spread = ", ".join(f"{x / 1e3:.0f}k" for x in rates[name])
        each = ", ".join(f"{r['nrmse']:.4f}" for r in runs)
        print(f"  {name:14s} {rate / 1e3:7.0f}k /CPU-s ({spread})   NRMSE {nrmse_:.4f} ({each}){ratio}", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--peers-python", default=os.environ.get("NNFMU_PEERS_PYTHON", "peers-venv/bin/python"),
                   help="python of the peers' virtual environment (see above)")
    p.add_argument("--sets", nargs="+", default=["small", "paper"], choices=["small", "paper"])
    p.add_argument("--contenders", nargs="+", default=list(DEFAULT_CONTENDERS), choices=CONTENDERS)
    p.add_argument("--budget", type=float, default=60.0, help="CPU-seconds of training per run")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--cpu", type=int, default=1, help="the core every run is pinned to")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--truncate", type=int, default=None,
                   help="nnfmu trains on windows of this many samples (default: whole trajectories)")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    p.add_argument("--out", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        return train_nnfmu(Path(args.worker), Path(args.out), args.budget, args.seed, args.truncate)
    if not Path(args.peers_python).exists() and set(args.contenders) - {"nnfmu"}:
        raise SystemExit(f"peers.py: no python at {args.peers_python!r}; install the peers as the docstring says "
                         "and pass --peers-python")
    warm_up()
    with tempfile.TemporaryDirectory(prefix="nnfmu_peers_") as tmp:
        for size in args.sets:
            data = make_data(size, args.seed, Path(tmp) / size)
            results = {name: [] for name in args.contenders}
            for r in range(args.rounds):
                order = args.contenders[r % len(args.contenders):] + args.contenders[:r % len(args.contenders)]
                for name in order:
                    results[name].append(run_worker(name, data, Path(tmp) / size / f"{name}-{r}", args))
            report(size, results)


if __name__ == "__main__":
    main()
