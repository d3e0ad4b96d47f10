"""Whether a training option should be a default: ``nnfmu train`` at its defaults against the same with the option.

For each dataset folder and architecture this runs what a new user types, once as is and once with the option
(``--with``, default ``--lr-schedule plateau``), from the same identified linear model (``nnfmu linear --save``
once a dataset, then ``--linear-path`` for both, so that the start is equal and identified once)::

    nnfmu linear --data D --save W/D/linear.json
    nnfmu train --data D --arch A -o W/D/A-default.pt --linear-path W/D/linear.json
    nnfmu train --data D --arch A -o W/D/A-lr-schedule-plateau.pt --linear-path W/D/linear.json --lr-schedule plateau

and prints, per cell, every seed's validation free-run NRMSE (which decides) and the kept model's, the CPU
seconds, and the test NRMSE that ``nnfmu train`` reports (float64 free run from y0; reported only, never used to
choose). The last line counts the cells where the option is better on validation, and gives the geometric mean of
the kept validation ratios. Each training's output is kept in ``W/D/A-default.log`` and ``W/D/A-SLUG.log`` (SLUG:
the option's words joined by dashes). A cell already measured is read back from its ``W/D/A-NAME.json``, not
trained again. Not part of the tests.

    python benchmarks/lr_schedule.py /tmp/ds/valve /tmp/ds/slider --archs gru tcn --work /tmp/lrs
"""

from __future__ import annotations

import argparse
import json
import math
import re
import resource
import subprocess
import sys
from pathlib import Path

SEED = re.compile(r"^seed (\d+): validation NRMSE ([0-9.]+), test ([0-9.]+)", re.M)
KEPT = re.compile(r"validation free-run NRMSE ([0-9.]+)[;,:]? ?(?:checkpoint|$)", re.M)
TEST = re.compile(r"^test free-run NRMSE: ([0-9.]+)", re.M)


def _cpu() -> float:
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return kids.ru_utime + kids.ru_stime


def _nnfmu(args: list[str], log: Path) -> tuple[str, float]:
    before = _cpu()
    done = subprocess.run([sys.executable, "-m", "nnfmu", *args], capture_output=True, text=True)
    log.write_text(done.stdout + done.stderr)
    if done.returncode != 0:
        raise SystemExit(f"nnfmu {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return done.stdout, _cpu() - before


def cell(data: Path, arch: str, variant: str, extra: list[str], work: Path, linear: Path) -> dict:
    """One training: its seeds' (validation, test), the kept validation and test, CPU seconds (kept in
    ``W/D/A-NAME.json``, and read from there when the cell ran before)."""
    done = work / f"{arch}-{variant}.json"
    if done.is_file():
        return json.loads(done.read_text())
    out, cpu = _nnfmu(["train", "--data", str(data), "--arch", arch, "-o", str(work / f"{arch}-{variant}.pt"),
                       "--linear-path", str(linear), *extra], work / f"{arch}-{variant}.log")
    seeds = [(float(v), float(t)) for _, v, t in SEED.findall(out)]
    kept = [float(v) for v in KEPT.findall(out)]
    test = TEST.findall(out)
    row = {"seeds": seeds, "valid": kept[-1] if kept else math.nan,
           "test": float(test[-1]) if test else math.nan, "cpu": cpu}
    done.write_text(json.dumps(row))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--archs", nargs="+", default=["gru", "tcn"])
    ap.add_argument("--with", dest="option", default="--lr-schedule plateau",
                    help="the option measured, as typed (default: '--lr-schedule plateau')")
    ap.add_argument("--work", type=Path, required=True)
    args = ap.parse_args()
    option = args.option.split()
    slug = "-".join(word.lstrip("-") for word in option)  # the option's files: W/D/A-SLUG.pt
    print("| dataset | arch | variant | seeds: validation / test | kept validation | test (reported) | CPU s |")
    print("|---|---|---|---|---:|---:|---:|")
    ratios, better = [], 0
    for data in args.datasets:
        work = args.work / data.name
        work.mkdir(parents=True, exist_ok=True)
        linear = work / "linear.json"
        if not linear.is_file():
            _nnfmu(["linear", "--data", str(data), "--save", str(linear), "--quiet"], work / "linear.log")
        for arch in args.archs:
            rows = {v: cell(data, arch, name, extra, work, linear)
                    for v, name, extra in (("default", "default", []), ("option", slug, option))}
            for variant, r in rows.items():
                seeds = ", ".join(f"{v:.4f} / {t:.4f}" for v, t in r["seeds"])
                name = "defaults" if variant == "default" else " ".join(option)
                print(f"| {data.name} | {arch} | {name} | {seeds} | {r['valid']:.4f} | {r['test']:.4f} | "
                      f"{r['cpu']:.0f} |", flush=True)
            ratio = rows["option"]["valid"] / rows["default"]["valid"]
            ratios.append(ratio)
            better += ratio < 1.0
    mean = math.exp(sum(map(math.log, ratios)) / len(ratios))
    print(f"\n{' '.join(option)}: better on validation in {better} of {len(ratios)} cells; kept validation ratio "
          f"(option / defaults), geometric mean {mean:.4f}")


if __name__ == "__main__":
    main()
