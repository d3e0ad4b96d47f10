"""Grey-box fit (nnfmu fit) on data of the model's own structure: recovered parameters, standard errors, solvers.

Slider: the small slider dataset (16 records of 400 samples to fit, 2 of 1600 to score) from the full model
(m = 1 kg, d = 2 N.s/m), 1 % of each output's std as white noise; m and d free, started at 1.6 and 1.3.
Valve: the first 8 records of the small valve dataset; d_p and k_s free, started at 6.5 and 20000
(true 5 and 25000). Each is fitted by SciPy's trf and by IPOPT (both with a Gauss-Newton Hessian), and
the time, the final cost, the estimates with their standard errors and the test NRMSE are printed.

    .venv/bin/python benchmarks/greybox_slider.py [--no-valve]
"""

from __future__ import annotations

import argparse
import time

from nnfmu.greybox import FitConfig, fit_greybox
from nnfmu.physics import generate_dataset, resolve_physics
from nnfmu.physics.generate_slider import generate_slider

CASES = {
    "slider": dict(truth={"m": 1.0, "d": 2.0}, start={"m": 1.6, "d": 1.3}, window=100),
    "valve": dict(truth={"d_p": 5.0, "k_s": 25e3}, start={"d_p": 6.5, "k_s": 20e3}, window=300),
}


def _data(name: str):
    if name == "slider":
        return generate_slider(size="small", seed=0).with_measurement_noise(0.01, seed=1)
    ds = generate_dataset("valve", size="small", seed=0)
    return ds.replace(splits={**ds.splits, "train": ds.train.subset(range(8))})


def _row(name: str, solver: str, dataset, case: dict) -> list[str]:
    t0 = time.perf_counter()
    config = FitConfig(free=tuple(case["truth"]), start=case["start"], window=case["window"], solver=solver,
                       max_evaluations=100)
    report = fit_greybox(resolve_physics(name), dataset, config).report
    seconds = time.perf_counter() - t0
    run = report["starts"][0]
    cells = [f"{p} = {r['value']:.5g} +- {r['std_error']:.2g} ({(r['value'] - case['truth'][p]) / r['std_error']:+.1f} "
             "SE)" for p, r in report["parameters"].items()]
    return [f"{name:<6} {solver:<6} {seconds:7.1f} s  cost {report['cost']:.6g}  {run['evaluations']:>3} "
            f"evaluations  test NRMSE {report['scores']['test']['nrmse']:.4f}  " + "; ".join(cells),
            f"{'':14}{run['status']}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-valve", action="store_true", help="the slider only (the valve takes minutes)")
    args = parser.parse_args()
    names = ["slider"] if args.no_valve else ["slider", "valve"]
    print("system solver   time    final cost (0.5 |r|^2, normalised)   estimates +- standard error (bias in SE)")
    for name in names:
        dataset = _data(name)
        for solver in ("trf", "ipopt"):
            print("\n".join(_row(name, solver, dataset, CASES[name])), flush=True)


if __name__ == "__main__":
    main()
