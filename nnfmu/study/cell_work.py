"""The work of each cell of a study: data, training, FMUs, the baselines and the fmpy scores.

Every function reads its inputs from files and writes its result atomically
to a file, so that a study can be stopped at any point and resumed.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable

import numpy as np

from nnfmu.data import Dataset, load_dataset, load_robot_benchmark, save_dataset
from nnfmu.errors import (
    CheckpointError,
    ConfigError,
    DataError,
    DataFileError,
    MetricError,
    SimulationError,
    TrainingError,
)
from nnfmu.physics import study_preset
from nnfmu.study.budgets import Budget, Hyper
from nnfmu.study.data_check import check_study_data
from nnfmu.atomic import write_atomic, write_text_atomic


# ---- data ----------------------------------------------------------------------------------------
def load_source(path: Path) -> Dataset:
    """A dataset folder, or the robot benchmark's ``.mat`` file."""
    path = Path(path)
    if path.is_dir():
        return load_dataset(path)
    if path.suffix.lower() == ".mat":
        return load_robot_benchmark(path)
    if not path.exists():
        raise DataFileError(f"--data {path} not found; give a dataset folder or the robot benchmark's .mat file")
    raise DataFileError(f"--data {path} is neither a dataset folder nor a .mat file; give a folder written by "
                        "'nnfmu generate' / 'nnfmu import', or the robot benchmark's .mat file")


def trim(ds: Dataset, budget: Budget, seed: int) -> Dataset:
    """Cut the dataset to the budget's sizes and fix its validation split (the same for every model)."""
    splits = dict(ds.splits)
    for split, keep in (("train", budget.max_train), ("test", budget.max_test)):
        if keep is not None and splits[split].n_traj > keep:
            splits[split] = splits[split].subset(range(keep))
    trimmed = ds.replace(splits=splits)
    if budget.max_train is not None and trimmed.valid is not None and trimmed.valid.n_traj > budget.max_train:
        trimmed = trimmed.replace(splits={**splits, "valid": trimmed.valid.subset(range(budget.max_train))})
    return trimmed.with_validation(budget.valid_fraction, seed=seed)


def check_source(system: str, source: Path | None, data_dir: Path) -> None:
    """Before a study touches its folder: a study of measured data (the robot) needs them, and given data must
    load and be of ``system``.

    Data already prepared in ``data_dir`` are not read again (the source may have moved since).
    """
    if source is None:
        if study_preset(system)[1].data_sizes is None:
            raise ConfigError(f"the {system} study needs measured data: pass --data with the benchmark's .mat file "
                              "or a dataset folder")
        return
    if not (data_dir / "meta.json").exists():
        check_study_data(system, load_source(source), str(source))


def prepare_data(system: str, budget: Budget, seed: int, source: Path | None, out: Path,
                 progress: bool) -> str:
    """Generate (with the study's physics model) or load (``source``) the data, trim it to the budget and save it
    at ``out``."""
    if source is not None:
        ds = load_source(source)
        check_study_data(system, ds, str(source))
    else:
        from nnfmu.physics import generate_dataset

        ds = generate_dataset(study_preset(system)[0].name, size=budget.data_size, seed=seed, progress=progress)
        if budget.noise:
            ds = ds.with_measurement_noise(budget.noise, seed)
    ds = trim(ds, budget, seed)
    save_dataset(ds, out, overwrite=True)
    tr, va, te = ds.train, ds.valid, ds.test
    return f"{tr.n_traj} train, {va.n_traj} valid, {te.n_traj} test trajectories, Ts = {ds.Ts:g} s"


# ---- training ------------------------------------------------------------------------------------
def training_finished(ckpt: Path) -> bool:
    """Whether the checkpoint holds a finished run (a run cut short by Ctrl-C or a crash has no stop reason)."""
    from nnfmu.models import load_checkpoint

    try:
        summary = load_checkpoint(ckpt).get("summary") or {}
    except CheckpointError:  # an unreadable file is simply not done; the cell redoes it
        return False
    return "stop_reason" in summary or error_file(ckpt).exists()


def error_file(ckpt: Path) -> Path:
    """Where a training that failed (e.g. a NaN loss) records why, beside its checkpoint."""
    return ckpt.with_suffix(".error.txt")


def _resumable(ckpt: Path, inputs: tuple[Path, ...], model_config, train_config) -> bool:
    from nnfmu.models import load_checkpoint
    from nnfmu.training.seed_runs import same_train_config

    if not ckpt.exists() or any(p.exists() and p.stat().st_mtime > ckpt.stat().st_mtime for p in inputs):
        return False
    try:
        stored = load_checkpoint(ckpt)
    except CheckpointError:
        return False
    return (stored.get("resume") is not None and stored.get("model_config") == model_config.to_dict()
            and same_train_config(stored.get("train_config"), train_config))


def train_network(data_dir: Path, arch: str, strategy: str, hyper: Hyper, budget: Budget, seed: int,
                  ckpt: Path, inputs: tuple[Path, ...], progress: bool,
                  callback: Callable[[int, dict], None] | None, device: str = "auto",
                  threads: int | None = None) -> str:
    """Train one network into ``ckpt``; resume it if an unfinished run of the same settings is there."""
    from nnfmu.training import train

    ds = load_dataset(data_dir)
    model_config = hyper.model_config(arch, ds.n_u, ds.n_y)
    train_config = hyper.train_config(strategy=strategy, epochs=budget.epochs, patience=budget.patience,
                                      seed=seed, max_minutes=budget.max_minutes)
    if budget.seeds > 1:
        return _train_seeds(ds, model_config, train_config, budget, ckpt, inputs, progress, device, threads)
    resume = _resumable(ckpt, inputs, model_config, train_config)
    error_file(ckpt).unlink(missing_ok=True)
    if not resume:
        ckpt.unlink(missing_ok=True)
    try:
        result = train(ds, model_config, train_config, out=ckpt, resume=resume, progress=progress,
                       callback=callback, device=device, threads=threads)
    except TrainingError as exc:  # the checkpoint keeps the best weights before the failure
        write_text_atomic(error_file(ckpt), f"{exc}\n")
        return f"FAILED, best weights so far kept: {exc}"
    if result.stop_reason in ("SIGINT", "SIGTERM"):
        raise KeyboardInterrupt(f"training of {arch} {strategy} stopped by {result.stop_reason}; "
                                "run the same command again to resume it")
    how = "resumed, " if resume else ""
    return (f"{how}best valid NRMSE {result.best_valid_nrmse:.4f} at epoch {result.best_epoch} of "
            f"{len(result.history) - 1}, stop: {result.stop_reason}")


def _train_seeds(ds: Dataset, model_config, train_config, budget: Budget, ckpt: Path, inputs: tuple[Path, ...],
                 progress: bool, device: str, threads: int | None) -> str:
    """``budget.seeds`` seeds of one network (:func:`nnfmu.training.train_seeds`); the kept model goes to ``ckpt``."""
    import shutil

    from nnfmu.training import train_seeds
    from nnfmu.training.ensemble import seed_paths

    members = seed_paths(ckpt, [0])[0].parent
    if members.exists() and any(p.exists() and p.stat().st_mtime > members.stat().st_mtime for p in inputs):
        shutil.rmtree(members)  # the data changed: the seeds start over
    ckpt.unlink(missing_ok=True)
    try:
        result = train_seeds(ds, model_config, train_config, seeds=budget.seeds, keep=budget.keep, out=ckpt,
                             jobs=1, progress=progress, device=device, threads=threads)
    except TrainingError as exc:
        write_text_atomic(error_file(ckpt), f"{exc}\n")
        return f"FAILED: {exc}"
    spread = result.spread()
    return (f"{budget.keep} of {budget.seeds} seeds: valid NRMSE {result.valid_nrmse:.4f}, test "
            f"{result.test_nrmse:.4f}; seeds' test {spread['mean']:.4f} ({spread['min']:.4f}-{spread['max']:.4f})")


# ---- FMUs ----------------------------------------------------------------------------------------
def export_network(ckpt: Path, fmu: Path, name: str) -> str:
    from nnfmu.export import build_fmu, casadi_model
    from nnfmu.models import load_model

    fmu.parent.mkdir(parents=True, exist_ok=True)
    build_fmu(casadi_model(load_model(ckpt), name=name), fmu)
    return f"wrote {fmu.name}"


def identify_baseline(data_dir: Path, options: dict, out: Path, progress: bool = False) -> str:
    from nnfmu.linear import identify_linear

    model = identify_linear(load_dataset(data_dir), progress=progress, **options)
    model.save(out)
    return f"order {model.n_x}, init '{model.init}'"


def export_linear(model_file: Path, fmu: Path, name: str) -> str:
    from nnfmu.export import build_fmu
    from nnfmu.linear import load_linear

    fmu.parent.mkdir(parents=True, exist_ok=True)
    build_fmu(load_linear(model_file).casadi_model(name=name), fmu)
    return f"wrote {fmu.name}"


def physics_model(system: str):
    """The physics reference model of the study ``system`` (the robot is scored against the arm model)."""
    return study_preset(system)[0].build().model()


def export_physics(system: str, fmu: Path) -> str:
    from nnfmu.export import build_fmu

    fmu.parent.mkdir(parents=True, exist_ok=True)
    build_fmu(physics_model(system), fmu)
    return f"wrote {fmu.name}"


# ---- scores --------------------------------------------------------------------------------------
def score_fmu(fmu: Path, data_dir: Path, out: Path, split: str = "test") -> str:
    """Co-simulate ``fmu`` on the split in fmpy (:func:`nnfmu.cosim.simulate_split`) and store the predictions.

    A model whose free run diverges, or that does not fit the data, is a result too: its
    error is stored instead of predictions and the table shows it.
    """
    from nnfmu.cosim import simulate_split
    from nnfmu.metrics import nrmse

    ds = load_dataset(data_dir)
    try:
        predictions = simulate_split(fmu, ds, split)
        score = nrmse(list(ds.split(split).y), predictions).mean
        error = ""
    except (SimulationError, MetricError, DataError) as exc:
        predictions, score, error = [], float("nan"), str(exc)
    arrays = {f"pred_{i}": p for i, p in enumerate(predictions)}
    write_atomic(out, lambda tmp: _save_npz(tmp, arrays, error, split), suffix=".npz")
    return f"NRMSE {score:.4f}" if not error else f"not scored: {error}"


def _save_npz(tmp: Path, arrays: dict, error: str, split: str) -> None:
    with open(tmp, "wb") as f:
        np.savez_compressed(f, n=np.array(len(arrays)), error=np.array(error), split=np.array(split), **arrays)


def load_scores(path: Path) -> tuple[list[np.ndarray], str]:
    """Predictions (one (N_i, n_y) array per trajectory) and the error text ('' if scored) of a score file."""
    with np.load(path) as z:
        return [z[f"pred_{i}"] for i in range(int(z["n"]))], str(z["error"])


def write_json(path: Path, doc: dict) -> Path:
    return write_text_atomic(path, json.dumps(doc, indent=2, default=_jsonable) + "\n")


def _jsonable(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, os.PathLike):
        return str(v)
    return str(v)
