"""Time the generation of the valve's paper-size dataset (and optionally the arm's benchmark size).

    python benchmarks/generate_speed.py [--arm] [--seed N]

Prints wall-clock seconds. The first valve run may include compiling the RK4
step (cached afterwards under $XDG_CACHE_HOME/nnfmu); both the cold and the
warm figure are printed. Timings on a shared machine are noisy.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time


def _timed(label: str, fn):
    start = time.perf_counter()
    result = fn()
    print(f"{label}: {time.perf_counter() - start:.1f} s")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arm", action="store_true", help="also time the arm's benchmark size (minutes)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    from nnfmu.physics import generate_dataset

    print(f"cores available: {len(os.sched_getaffinity(0))}")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["NNFMU_CACHE_DIR"] = cache  # cold: includes compiling the RK4 step
        _timed("valve paper size, cold cache (compile + simulate)",
               lambda: generate_dataset("valve", size="paper", seed=args.seed))
        ds = _timed("valve paper size, warm cache", lambda: generate_dataset("valve", size="paper", seed=args.seed))
    print(ds.summary())
    if args.arm:
        ds = _timed("arm benchmark size (CVODES, closed loop)",
                    lambda: generate_dataset("arm", size="benchmark", seed=args.seed))
        print(ds.summary())


if __name__ == "__main__":
    main()
