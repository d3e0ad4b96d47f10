"""Export time per platform: each platform's binary built alone, for a small GRU and for the valve physics.

Prints, per model and platform, the CPU seconds of the compiler processes (the system C compiler for
the host, ``zig cc`` for the others; CasADi's code generation, the same for every platform, is
counted apart) and the wall time of the whole export, then one export with every platform together.
Run pinned to one core on a shared machine, with Zig's cache prepared (python -m nnfmu.export.prepare_zig):

    taskset -c 0 python benchmarks/export_platforms.py

Not part of the test run.
"""

from __future__ import annotations

import resource
import tempfile
import time
from pathlib import Path

import torch

from nnfmu.export import build_fmu, casadi_model
from nnfmu.export.platforms import PLATFORMS
from nnfmu.models import ModelConfig, build_model
from nnfmu.physics import valve_system


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def small_gru():
    meta = {"name": "valve_gru", "Ts": 4e-5, "inputs": [{"name": "u1", "unit": "V"}, {"name": "u2", "unit": "V"}],
            "outputs": [{"name": "s", "unit": "m"}, {"name": "p", "unit": "Pa"}]}
    torch.manual_seed(0)
    return casadi_model(build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=8), meta).double().eval())


def export(model, folder: Path, platforms) -> tuple[float, float]:
    """(compiler CPU seconds, wall seconds) of one export."""
    cpu, wall = children_cpu(), time.perf_counter()
    build_fmu(model, folder / "m.fmu", platforms=platforms)
    return children_cpu() - cpu, time.perf_counter() - wall


def main() -> None:
    models = {"GRU (8 hidden)": small_gru(), "valve physics (RK4 + Model Exchange)": valve_system().model()}
    names = [p.fmi2 for p in PLATFORMS.values()]
    with tempfile.TemporaryDirectory() as tmp:
        for label, model in models.items():
            export(model, Path(tmp), ["host"])  # warm-up: imports, first code generation
            print(f"{label}: compiler CPU s / export wall s")
            for name in names:
                cpu, wall = export(model, Path(tmp), [name])
                print(f"  {name:15s} {cpu:6.2f} / {wall:6.2f}")
            cpu, wall = export(model, Path(tmp), names)
            print(f"  {'all five':15s} {cpu:6.2f} / {wall:6.2f}")


if __name__ == "__main__":
    main()
