"""One seed of :func:`nnfmu.training.train_seeds`, in a process of its own.

``python -m nnfmu.training.seed_worker DATASET_DIR MODEL_JSON TRAIN_JSON OUT.pt DEVICE THREADS PROGRESS [LINEAR.json]``

Runs in a fresh interpreter so that :func:`nnfmu.training.train_seeds` can train seeds side by side
without ``multiprocessing`` (which would re-run the caller's script). The dataset is a dataset
folder (its validation split already fixed); the configs are JSON dicts; ``PROGRESS`` is 1 for a progress
bar on stderr, else 0.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from nnfmu.data import load_dataset
from nnfmu.linear import load_linear
from nnfmu.models import ModelConfig
from nnfmu.training.config import TrainConfig
from nnfmu.training.ensemble import _train_one


def main(argv: list[str]) -> int:
    data, model_json, train_json, out, device, threads, progress, *linear = argv
    start = load_linear(linear[0]) if linear else None  # the linear path's start (ModelConfig.linear_order > 0)
    _train_one(load_dataset(data), ModelConfig.from_dict(json.loads(model_json)),
               TrainConfig.from_dict(json.loads(train_json)), Path(out), progress == "1", device=device,
               threads=int(threads), linear=start)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
