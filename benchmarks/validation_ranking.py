"""Issue 38: which validation predicts the test? The rank correlation between validation and test over trials.

Every choice nnfmu makes (the epoch kept, the seed kept, the search's trial) ranks models by their validation
free-run NRMSE. A validation scheme is as good as that ranking agrees with the test's. For each dataset and
scheme this trains ``--trials`` networks that differ in seed, width and learning rate (``nnfmu train`` at its
defaults otherwise, one seed each, ``--epochs`` each (a step budget, so that a busy machine changes the
wall time, not the result; ``--max-minutes`` caps each as well), ``--jobs`` at once), reads each one's
best validation NRMSE and its test NRMSE from its checkpoint, and prints Spearman's rho and Kendall's tau
between the two, and what picking the trial best on validation would have given on test against the best test.

The schemes (``--schemes``): ``tail`` holds out the record's last part (``--valid-blocks 1``, the default of
``nnfmu train``), ``blocksK`` the same share as K blocks spread over it. They differ only for a dataset of one
training record without a valid split (the F-16); ``--one-record`` joins a dataset's training records (and
its valid split, dropped as a split) end to end first, for data cut from one recording (the robot's pieces).
Not part of the tests. Name the CPU beside the figures.

    python benchmarks/validation_ranking.py data/f16 --schemes tail blocks4 --trials 8 --epochs 40
"""

from __future__ import annotations

import argparse
import itertools
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from scipy.stats import kendalltau, spearmanr

WIDTHS = (16, 32, 64)
RATES = (1e-3, 3e-3, 1e-2)


def one_record(data: Path, work: Path) -> Path:
    """``data`` with its training (and valid) records joined into one record, saved under ``work``."""
    from nnfmu.data import Trajectories, load_dataset, save_dataset

    ds = load_dataset(data)
    parts = [ds.train] + ([ds.valid] if ds.valid is not None else [])
    joined = Trajectories((np.concatenate([u for p in parts for u in p.u]),),
                          (np.concatenate([y for p in parts for y in p.y]),))
    splits = {"train": joined, "test": ds.test}
    out = work / f"{data.name}-one-record"
    shutil.rmtree(out, ignore_errors=True)
    save_dataset(ds.replace(splits=splits), out)
    return out


def trial(data: Path, arch: str, scheme: str, i: int, epochs: int, minutes: float, work: Path) -> tuple[float, float]:
    """Train trial ``i`` of ``scheme``; ``(best validation NRMSE, test NRMSE)`` from its checkpoint."""
    from nnfmu.models import load_checkpoint

    blocks = 1 if scheme == "tail" else int(scheme.removeprefix("blocks"))
    width, rate = list(itertools.product(WIDTHS, RATES))[(5 * i) % (len(WIDTHS) * len(RATES))]
    out = work / f"{scheme}-{i}.pt"
    out.unlink(missing_ok=True)
    cmd = [sys.executable, "-m", "nnfmu", "train", "--data", str(data), "--arch", arch, "--seeds", "1",
           "--seed", str(i), "--hidden", str(width), "--lr", str(rate), "--epochs", str(epochs),
           "--max-minutes", str(minutes), "--valid-blocks", str(blocks), "--threads", "1", "--quiet", "-o", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    (work / f"{scheme}-{i}.log").write_text(done.stdout + done.stderr)
    # a training that diverged exits 1 but keeps its best weights, scored: a trial of the search ends so too
    if done.returncode != 0 and not (out.is_file() and "the best weights so far are kept" in done.stderr):
        raise SystemExit(f"{' '.join(cmd)} failed: {done.stderr.strip()[-1000:]}")
    ckpt = load_checkpoint(out)
    summary = ckpt["summary"]
    if summary.get("test_nrmse") is None:  # the diverged training's best weights: score them as training would
        from nnfmu.data import load_dataset
        from nnfmu.models import model_from_checkpoint
        from nnfmu.training.evaluate import free_run_nrmse

        test = free_run_nrmse(model_from_checkpoint(ckpt), load_dataset(data).test, float64=True).mean
        return float(summary["best_valid_nrmse"]), float(test)
    return float(summary["best_valid_nrmse"]), float(summary["test_nrmse"])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("datasets", nargs="+", type=Path)
    p.add_argument("--schemes", nargs="+", default=["tail", "blocks4"])
    p.add_argument("--arch", default="gru")
    p.add_argument("--trials", type=int, default=8)
    p.add_argument("--epochs", type=int, default=40)
    p.add_argument("--max-minutes", type=float, default=10.0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--one-record", action="store_true", help="join each dataset's records into one first")
    p.add_argument("--work", type=Path, default=Path("validation-ranking"))
    args = p.parse_args()
    print("| dataset | scheme | trials | Spearman rho | Kendall tau | test of the trial best on validation | best test |")
    print("|---|---|---:|---:|---:|---:|---:|", flush=True)
    for data in args.datasets:
        work = args.work / data.name
        work.mkdir(parents=True, exist_ok=True)
        source = one_record(data, work) if args.one_record else data
        for scheme in args.schemes:
            with ThreadPoolExecutor(args.jobs) as pool:
                rows = list(pool.map(lambda i: trial(source, args.arch, scheme, i, args.epochs, args.max_minutes, work),
                                     range(args.trials)))
            valid, test = np.array(rows).T
            rho, tau = spearmanr(valid, test).statistic, kendalltau(valid, test).statistic
            print(f"| {data.name} | {scheme} | {len(rows)} | {rho:.3f} | {tau:.3f} | {test[np.argmin(valid)]:.4f} | "
                  f"{test.min():.4f} |", flush=True)
            (work / f"{scheme}.tsv").write_text("valid\ttest\n" + "".join(f"{v}\t{t}\n" for v, t in rows))


if __name__ == "__main__":
    main()
