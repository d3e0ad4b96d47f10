"""The refit: the kept seeds trained once more on the training and validation data together.

``nnfmu train`` chooses on validation: the epoch of each seed (early stopping) and the seeds it keeps
(:mod:`nnfmu.training.ensemble`). The validation data never train the network. After choosing, each kept seed
trains once more from the same seed on the training and the validation data together, for the epochs its first run
kept, and its final weights are kept (``TrainConfig.keep_weights = 'last'``): validation chooses how much training,
all the data estimate the weights, as the linear baseline is refitted after choosing its order
(:mod:`nnfmu.linear.identify`).

Decided one level down, without the test split: ``benchmarks/network_refit.py`` carves an inner validation from the
training split, chooses there, refits or not, and scores on the dataset's own validation (docs/accuracy.md, "A
network refitted on training and validation data").

Each refit is a normal resumable training into ``<out stem>.seeds/refit-<s>.pt``, beside its seed. The kept
model's validation score is then in-sample: the score it was chosen by (before the refit) is the one reported
and compared. A learning-rate schedule that follows validation (plateau, anneal) has nothing to follow in a refit,
so such a run is not refitted.
"""

from __future__ import annotations

from pathlib import Path

from nnfmu.data import Dataset, Trajectories
from nnfmu.training.config import TrainConfig

#: Learning-rate schedules a refit can replay: the ones that do not read the validation score.
REPLAYABLE_SCHEDULES = ("constant", "cosine")
#: How a refit lands where its run averages no weights: on an exponential moving average of the weights
#: (``TrainConfig.average = 'ema'``), not on the last epoch's weights alone, whose free run at a constant learning
#: rate moves from epoch to epoch. Chosen one level down (docs/accuracy.md): lower than the last weights in 12 of 16
#: refits of the TCN and the ss network on four datasets (geometric means 0.852 and 0.878 of the run without refit).
LANDING_AVERAGE = "ema"


def training_and_validation(dataset: Dataset) -> Trajectories:
    """The data a refit trains on: the training split, and the validation split after it where there is one.

    Pass the dataset as loaded, before a validation split was carved from it: a carved record is then whole again,
    and carved trajectories are back in their order (``TrainConfig.join`` joins them as recorded).
    """
    if dataset.valid is None:
        return dataset.train
    train, valid = dataset.train, dataset.valid
    return Trajectories(tuple(train.u) + tuple(valid.u), tuple(train.y) + tuple(valid.y))


def refit_dataset(chosen_on: Dataset, whole: Trajectories) -> Dataset:
    """The dataset of a refit: ``whole`` trains, and the validation split the seeds were chosen on stays as the
    ``valid`` split (in-sample now: the progress bar shows it, it chooses nothing); the test split is unchanged."""
    return chosen_on.replace(splits={**chosen_on.splits, "train": whole})


def refit_config(cfg: TrainConfig, seed: int, epochs: int, stretch: float = 1.0) -> TrainConfig:
    """The refit of seed ``seed``: ``epochs`` epochs (its first run's best), no early stopping, the last weights,
    averaged (:data:`LANDING_AVERAGE`, or the run's own averaging).

    ``stretch``: the refit's samples over the first run's (>= 1). Its epochs are that much longer, so a time budget
    (``max_minutes``) grows by as much: the epochs bind, as in the first run that reached them within its budget.
    """
    budget = None if cfg.max_minutes is None else cfg.max_minutes * max(float(stretch), 1.0)
    average = LANDING_AVERAGE if cfg.average == "none" else cfg.average
    return cfg.replace(seed=seed, epochs=max(int(epochs), 1), patience=0, keep_weights="last", max_minutes=budget,
                       average=average)


def refit_path(folder: Path, seed: int) -> Path:
    """Where seed ``seed``'s refit lives: ``<out stem>.seeds/refit-<s>.pt``."""
    return folder / f"refit-{seed}.pt"


def can_refit(cfg: TrainConfig) -> bool:
    """Whether the run's learning-rate schedule can be replayed without validation (constant, cosine)."""
    return cfg.lr_schedule in REPLAYABLE_SCHEDULES


def refit_kept(chosen, kept: list, rows: list, *, chosen_on: Dataset, whole: Trajectories, model_config, cfg,
               folder: Path, jobs, progress: bool, device, threads, linear, overwrite: bool):
    """Refit the kept seeds and rebuild the kept model from them: ``(model, summary or None, notes)``.

    ``chosen``: the model chosen on validation; ``kept``: the indices into ``rows`` (one dict per seed,
    :func:`nnfmu.training.ensemble.train_seeds`) of the seeds it holds. A seed that never improved on its start
    (best epoch 0) is kept as it is: its start is what validation chose. Without a replayable schedule, or when no
    kept seed trained, ``chosen`` is returned with a note saying why.
    """
    from nnfmu.models import EnsembleStepModel, load_checkpoint, load_model
    from nnfmu.training.seed_runs import history_seconds, planned_jobs, train_members

    if not can_refit(cfg):
        return chosen, None, [f"no refit: the learning-rate schedule {cfg.lr_schedule!r} follows the validation "
                              "score, which a refit on the validation data has not"]
    todo = [i for i in kept if rows[i]["best_epoch"]]
    if not todo:
        return chosen, None, ["no refit: the kept seed never improved on its start (best epoch 0)"]
    data = refit_dataset(chosen_on, whole)
    stretch = whole.n_samples / chosen_on.train.n_samples
    paths = {i: refit_path(folder, rows[i]["seed"]) for i in todo}
    work = [(data, model_config, refit_config(cfg, rows[i]["seed"], rows[i]["best_epoch"], stretch), paths[i],
             progress and k == 0) for k, i in enumerate(todo)]
    train_members(work, planned_jobs(jobs, len(work)), device=device, threads=threads, linear=linear,
                  overwrite=overwrite, what="refits")
    members = [load_model(paths.get(i, rows[i]["checkpoint"])) for i in kept]  # an untrained seed: as chosen
    model = members[0] if len(members) == 1 else EnsembleStepModel.from_members(members).eval()
    runs = [load_checkpoint(paths[i]) for i in todo]
    summary = {"seeds": [rows[i]["seed"] for i in todo], "epochs": [rows[i]["best_epoch"] for i in todo],
               "stop_reasons": [(r.get("summary") or {}).get("stop_reason") for r in runs],
               "seconds": [history_seconds(r) for r in runs],
               "train_samples": int(whole.n_samples), "chosen_train_samples": int(chosen_on.train.n_samples)}
    short = [f"seed {s}: {e} epochs, {t:.0f} s" for s, e, t in zip(summary["seeds"], summary["epochs"],
                                                                     summary["seconds"])]
    note = (f"refitted on the training and validation data together ({whole.n_samples} samples, "
            f"{chosen_on.train.n_samples} before) for the epochs each seed kept ({'; '.join(short)}); the validation "
            "score above is the one the model was chosen by: the validation data train the refitted weights")
    return model, summary, [note]
