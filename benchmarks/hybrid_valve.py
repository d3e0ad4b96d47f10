"""Hybrid vs physics vs network on the valve, with little data and a deliberately wrong physics model.

Valve data are generated with the TRUE parameters; only a reduced training set is used
(``--train-trajectories`` of the generated ones). The physics model is mis-specified:
spring stiffness +30 %, orifice conductance -30 %, no end-stop damping. Four models are
turned into FMUs and scored by the one scoring path (fmpy co-simulation of each FMU on the
test split, :func:`nnfmu.cosim.evaluate`):

- physics alone (wrong parameters), RK4 as in every physics FMU;
- a pure network (GRU, parallel training) on the same reduced data;
- the hybrid (wrong physics + derivative correction), network only;
- the hybrid that also trains k_s and C_max (log-space) with the network.

It also times the torch physics paths (compiled C vs SX translation). Timings on a shared
machine are noisy. Not part of the test run::

    python benchmarks/hybrid_valve.py                       # paper-size test set, 40 train trajectories
    python benchmarks/hybrid_valve.py --size small --hybrid-epochs 10 --gru-epochs 60   # a few minutes
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from nnfmu.cosim import evaluate
from nnfmu.export import build_fmu
from nnfmu.export import casadi_model
from nnfmu.hybrid import HybridConfig, casadi_to_torch, physics_system
from nnfmu.models import ModelConfig
from nnfmu.physics import ValveParams, generate_dataset, valve_system
from nnfmu.training import TrainConfig, train

NOMINAL = ValveParams()
WRONG = {"k_s": 1.3 * NOMINAL.k_s, "C_max": 0.7 * NOMINAL.C_max, "d_c": 0.0}


def reduced_data(size: str, n_train: int, seed: int):
    """Generated valve data (true parameters) with only the first ``n_train`` training trajectories."""
    ds = generate_dataset("valve", size=size, seed=seed)
    return ds.replace(splits={"train": ds.train.subset(range(n_train)), "test": ds.test})


def physics_fmu(out: Path) -> Path:
    import dataclasses

    return build_fmu(valve_system(dataclasses.replace(NOMINAL, **WRONG)).model(), out / "physics.fmu")


def fit(ds, config, train_config, out: Path, name: str):
    """Train, export and return (fmu path, result, seconds)."""
    t0 = time.perf_counter()
    result = train(ds, config, train_config, out=out / f"{name}.pt")
    seconds = time.perf_counter() - t0
    model = result.model
    model.provenance = {"checkpoint": str(out / f"{name}.pt")}
    path = build_fmu(casadi_model(model, name=f"valve_{name}"), out / f"{name}.fmu")
    epochs = len(result.history) - 1
    print(f"  {name}: {epochs} epochs in {seconds:.0f} s ({seconds / max(epochs, 1):.1f} s/epoch), best epoch "
          f"{result.best_epoch}, validation NRMSE {result.best_valid_nrmse:.4f}", flush=True)
    return path, result, seconds


def physics_speed(batches=(1, 36)) -> dict:
    """Microseconds per valve ODE call (forward, forward + backward) for each torch physics backend."""
    system = physics_system("valve")
    p = torch.tensor(system.parameter_values())
    x0 = torch.tensor(np.asarray(system.init_state([5e-4, 3e5], [100.0, 50.0], p.numpy())).ravel())
    out = {}
    for backend in ("compiled", "sx"):
        ode = casadi_to_torch(system.ode, backend=backend)
        for b in batches:
            x, u = x0.repeat(b, 1).requires_grad_(), torch.full((b, 2), 100.0, dtype=torch.float64)
            with torch.no_grad():
                out[f"{backend} B={b} forward"] = _time(ode, (x, u, p))
            out[f"{backend} B={b} forward+backward"] = _time(_forward_backward, (ode, x, u, p))
    return out


def _forward_backward(ode, x, u, p) -> None:
    ode(x, u, p)[0].sum().backward()


def _time(call, args: tuple, repeat: int = 30) -> float:
    call(*args)
    t0 = time.perf_counter()
    for _ in range(repeat):
        call(*args)
    return (time.perf_counter() - t0) / repeat * 1e6


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="paper", help="generated valve size whose test set is used (paper, small)")
    p.add_argument("--train-trajectories", type=int, default=40, help="training trajectories kept (paper: 900)")
    p.add_argument("--hybrid-epochs", type=int, default=40)
    p.add_argument("--gru-epochs", type=int, default=300)
    p.add_argument("--truncate", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="hybrid_valve_out", help="folder for checkpoints, FMUs and results.json")
    args = p.parse_args()
    torch.set_num_threads(1)  # hybrid steps are hundreds of tiny operations; extra threads only contend
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ds = reduced_data(args.size, args.train_trajectories, args.seed)
    print(f"data: {ds.train.n_traj} train trajectories x {len(ds.train.u[0])} samples (true parameters), "
          f"test {ds.test.n_traj} x {len(ds.test.u[0])}\nwrong physics: {WRONG}", flush=True)
    common = {"truncate": args.truncate, "seed": args.seed, "patience": 0}
    fmus = {"physics (wrong parameters)": physics_fmu(out)}
    seconds, learned = {}, {}
    gru = ModelConfig(arch="gru", n_u=2, n_y=2, hidden=32)
    fmus["GRU-32 (parallel)"], _, seconds["GRU-32 (parallel)"] = fit(
        ds, gru, TrainConfig(epochs=args.gru_epochs, batch_size=16, **common), out, "gru")
    hybrid_train = TrainConfig(epochs=args.hybrid_epochs, batch_size=36, dtype="float64", **common)
    for label, name, trained in (("hybrid (network)", "hybrid", ()),
                                 ("hybrid (network + k_s, C_max)", "hybrid_params", ("k_s", "C_max"))):
        config = HybridConfig(n_u=2, n_y=2, physics="valve", physics_params=WRONG, train_physics=trained)
        fmus[label], result, seconds[label] = fit(ds, config, hybrid_train, out, name)
        values = result.model.physics_parameter_values()
        learned[label] = {k: values[k] for k in ("k_s", "C_max", "d_c")}
    scores = evaluate(list(fmus.values()), ds, "test", names=list(fmus))
    print(f"\nfree-run test NRMSE by fmpy co-simulation of each FMU ({ds.test.n_traj} trajectories):")
    print(f"  {'model':32s} {'NRMSE':>8s} {'s':>8s} {'p':>8s} {'train s':>8s}")
    for e in scores:
        s, pr = e.result.output_mean
        print(f"  {e.name:32s} {e.result.mean:8.4f} {s:8.4f} {pr:8.4f} {seconds.get(e.name, 0.0):8.0f}")
    print(f"true k_s = {NOMINAL.k_s:g}, C_max = {NOMINAL.C_max:g}, d_c = {NOMINAL.d_c:g}; learned: {learned}")
    speed = physics_speed()
    print("torch physics, valve ODE, us per call: " + ", ".join(f"{k} {v:.0f}" for k, v in speed.items()))
    results = {"nrmse": {e.name: e.to_json(ds.output_names) for e in scores}, "train_seconds": seconds,
               "learned_parameters": learned, "physics_speed_us": speed, "args": vars(args), "wrong": WRONG}
    (out / "results.json").write_text(json.dumps(results, indent=2, default=str))


if __name__ == "__main__":
    main()
