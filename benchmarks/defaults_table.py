"""Issue 21's proof: every network at its defaults against the linear baseline, scored in fmpy.

For each dataset folder and architecture this runs exactly what a new user types, with no flag beyond
``--data`` and ``-o`` (plus ``--quiet``)::

    nnfmu linear --data D -o linear.fmu
    nnfmu train  --data D --arch A -o A.pt         # then: nnfmu export A.pt -o A.fmu
    nnfmu evaluate --data D linear.fmu A.fmu ... --json scores.json

and prints one table: the test NRMSE (free run in fmpy) of the linear model and of each network, its
ratio to the linear model, and the CPU seconds (user + system, of the command and its children) of each
cell (each training's output is kept in ``WORK/DATASET/ARCH.log``). After each dataset's rows, a line gives
the rank correlation (Spearman's rho, Kendall's tau) between the validation and the test NRMSE over every
seed of every cell (issue 38: how well the validation that makes every choice predicts the test). ``--max-minutes N`` adds that flag to
every training (the time-budget search over the knobs left out); the architecture ``search`` names the cell
that gives no ``--arch``, so that the search also chooses it. Pin it to one core on a shared machine
(``taskset -c 1``) and name the CPU next to the figures. Not part of the tests.

    python benchmarks/defaults_table.py data/slider data/valve --archs gru mlp --work /tmp/defaults
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
from pathlib import Path


def _cpu() -> float:
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return kids.ru_utime + kids.ru_stime


def _nnfmu(*args: str, log: Path | None = None) -> float:
    """Run one nnfmu command (its output kept in ``log``, if given); its CPU seconds."""
    before = _cpu()
    done = subprocess.run([sys.executable, "-m", "nnfmu", *args], capture_output=True, text=True)
    if log is not None:
        log.write_text(done.stdout + done.stderr)
    if done.returncode != 0:
        raise SystemExit(f"nnfmu {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return _cpu() - before


def run_dataset(data: Path, archs: list[str], work: Path, extra: list[str], reuse_linear: bool = False,
                reuse_seeds: bool = False) -> dict:
    """Train, export and score every cell of one dataset; returns {name: (test NRMSE, CPU s)}.

    ``reuse_linear``: keep a ``linear.fmu`` already in ``work`` (its CPU seconds then read NaN). ``reuse_seeds``:
    keep each cell's ``ARCH.seeds/seed-*.pt`` (the training finds them finished and only chooses, and refits where
    the defaults refit; the CPU seconds are then those of that step alone).
    """
    work.mkdir(parents=True, exist_ok=True)
    fmus, cpu = {}, {}
    fmus["linear"] = work / "linear.fmu"
    if reuse_linear and fmus["linear"].is_file():
        cpu["linear"] = float("nan")
    else:
        fmus["linear"].unlink(missing_ok=True)
        cpu["linear"] = _nnfmu("linear", "--data", str(data), "-o", str(fmus["linear"]), "--quiet")
    for arch in archs:
        ckpt = work / f"{arch}.pt"
        ckpt.unlink(missing_ok=True)
        if reuse_seeds:  # the refits go: they are made from the seeds by today's rule
            for old in (work / f"{arch}.seeds").glob("refit-*"):
                old.unlink()
        else:
            shutil.rmtree(work / f"{arch}.seeds", ignore_errors=True)  # the plan's seeds train anew, not resumed
        chosen = [] if arch == "search" else ["--arch", arch]
        cpu[arch] = _nnfmu("train", "--data", str(data), *chosen, "-o", str(ckpt), "--quiet", *extra,
                           log=work / f"{arch}.log")
        fmus[arch] = work / f"{arch}.fmu"
        fmus[arch].unlink(missing_ok=True)
        _nnfmu("export", str(ckpt), "-o", str(fmus[arch]))
    scores = work / "scores.json"
    _nnfmu("evaluate", "--data", str(data), *map(str, fmus.values()), "--json", str(scores))
    models = {Path(m["fmu"]).stem: m for m in json.loads(scores.read_text())["models"]}
    out = {name: (float(models[path.stem]["nrmse"]), cpu[name]) for name, path in fmus.items()}
    return out


def seed_scores(work: Path, archs: list[str]) -> list[tuple[float, float]]:
    """``(validation NRMSE, test NRMSE)`` of every seed of every cell (one pair for a cell of one training), as
    the checkpoints' summaries hold them (float64 free runs from y0)."""
    from nnfmu.models import load_checkpoint

    pairs = []
    for arch in archs:
        summary = load_checkpoint(work / f"{arch}.pt")["summary"]
        for row in summary.get("seeds") or [summary]:
            if row.get("best_valid_nrmse") is not None and row.get("test_nrmse") is not None:
                pairs.append((float(row["best_valid_nrmse"]), float(row["test_nrmse"])))
    return pairs


def rank_line(name: str, pairs: list[tuple[float, float]]) -> str:
    """The line after a dataset's rows: Spearman's rho and Kendall's tau of validation against test."""
    from scipy.stats import kendalltau, spearmanr

    if len(pairs) < 3:
        return f"{name}: {len(pairs)} seeds, too few for a rank correlation"
    valid, test = zip(*pairs)
    return (f"{name}: validation-test rank correlation over {len(pairs)} seeds: Spearman "
            f"{spearmanr(valid, test).statistic:.3f}, Kendall {kendalltau(valid, test).statistic:.3f}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--archs", nargs="+", help="default: every architecture the search takes part in "
                   "(nnfmu.models.architectures.search_order(): the five networks and ss)")
    p.add_argument("--work", type=Path, default=Path("defaults-table"))
    p.add_argument("--max-minutes", type=float, help="the time budget of every training (default: none)")
    p.add_argument("--reuse-linear", action="store_true",
                   help="keep the linear.fmu of an earlier run in the work folder instead of identifying it again")
    p.add_argument("--refit", action="store_true", help="add --refit to every training (nnfmu.training.refit)")
    p.add_argument("--reuse-seeds", action="store_true",
                   help="keep every cell's seeds of an earlier run in the work folder: only what follows them (the "
                        "choice, the refit) runs again")
    args = p.parse_args(argv)
    if args.archs is None:
        from nnfmu.models.architectures import search_order

        args.archs = list(search_order())
    if "search" in args.archs and args.max_minutes is None:
        p.error("the 'search' cell needs --max-minutes (the search's time budget)")
    extra = [] if args.max_minutes is None else ["--max-minutes", str(args.max_minutes)]
    extra += ["--refit"] if args.refit else []
    print("| dataset | model | test NRMSE (fmpy) | / linear | CPU s |\n|---|---|---|---|---|", flush=True)
    for data in args.datasets:
        rows = run_dataset(data, args.archs, args.work / data.name, extra, args.reuse_linear, args.reuse_seeds)
        base = rows["linear"][0]
        for name, (score, seconds) in rows.items():
            print(f"| {data.name} | {name} | {score:.4f} | {score / base:.3f} | {seconds:.0f} |", flush=True)
        print(rank_line(data.name, seed_scores(args.work / data.name, args.archs)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
