"""One seed of :func:`nnfmu.training.train_seeds`, in a process of its own.

``python -m nnfmu.training.seed_worker DATASET_DIR MODEL_JSON TRAIN_JSON OUT.pt DEVICE THREADS PROGRESS [LINEAR.json]``

Runs in a fresh interpreter so that :func:`nnfmu.training.train_seeds` can train seeds side by side
without ``multiprocessing`` (which would re-run the caller's script). The dataset is a dataset
folder (its validation split already fixed); the configs are JSON dicts; ``PROGRESS`` is 1 for a progress
bar on stderr, else 0.

A Ctrl-C (the parent's SIGINT) while training stops the seed after its epoch, with its checkpoint kept (the
trainer's own handler). One that arrives before training began, while torch is still being imported, ends the
worker at once with status 130 and without a traceback: it had nothing to keep, and the parent says so.
"""

from __future__ import annotations

import signal
import sys


def main(argv: list[str]) -> int:
    import json
    from pathlib import Path

    from nnfmu.data import load_dataset
    from nnfmu.linear import load_linear
    from nnfmu.models import ModelConfig
    from nnfmu.training.config import TrainConfig
    from nnfmu.training.seed_runs import train_member

    data, model_json, train_json, out, device, threads, progress, *linear = argv
    start = load_linear(linear[0]) if linear else None  # the linear path's start (ModelConfig.linear_order > 0)
    train_member(load_dataset(data), ModelConfig.from_dict(json.loads(model_json)),
                 TrainConfig.from_dict(json.loads(train_json)), Path(out), progress == "1", device=device,
                 threads=int(threads), linear=start)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except KeyboardInterrupt:
        sys.exit(128 + signal.SIGINT)  # the status of a process ended by SIGINT, as nnfmu's CLI
