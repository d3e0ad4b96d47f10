"""The study of the paper as resumable cells: ``nnfmu reproduce`` (and, as a small preset, ``nnfmu demo``).

A study folder holds::

    study.json              what was asked (system, budget, seed, tune, data); a re-run must ask the same
    data/                   the dataset (generated or loaded, trimmed to the budget, validation split fixed)
    tune/A-S.json           grid-search result per architecture A and strategy S (with --tune)
    models/A-S.pt           training checkpoints (rewritten every epoch; an unfinished one is resumed)
    models/linear.json      the linear baseline
    fmus/A-S.fmu, fmus/linear.fmu, fmus/physics.fmu
    scores/NAME.npz         fmpy free-run predictions on the test split (or why there are none)
    results.md, results.json, figures/*.png

Every file is one cell's output; see :mod:`nnfmu.study.cells` for when a cell is skipped.
"""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from nnfmu.atomic import write_text_atomic
from nnfmu.errors import ConfigError, DataFileError
from nnfmu.study import cell_work
from nnfmu.study import parallel
from nnfmu.physics import study_preset
from nnfmu.study.budgets import Budget, Hyper, get_budget, network_name
from nnfmu.study.cells import Cell, CellLog, run_cells

TrainCallback = Callable[[str, int, dict], None]


@dataclass(frozen=True)
class StudyResult:
    """What :func:`reproduce` returns: the folder, the cells run or skipped, and the results document."""

    out: Path
    log: CellLog
    results: dict

    @property
    def results_md(self) -> Path:
        return self.out / "results.md"


class Study:
    """The cells of one study folder; see the module docstring for the layout."""

    def __init__(self, system: str, out: str | Path, budget: Budget, *, data: str | Path | None = None,
                 tune: bool | None = None, seed: int = 0, address: str | None = None, progress: bool = True,
                 callback: TrainCallback | None = None, echo: Callable[[str], None] | None = print,
                 jobs: int = 1, device: str = "auto", threads: int | None = None):
        study_preset(system)  # ConfigError listing the registered studies when there is none
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
        self.system, self.out, self.budget, self.seed = system, Path(out), budget, seed
        self.source = None if data is None else Path(data).resolve()
        self.tune = budget.tune if tune is None else bool(tune)
        self.address, self.progress, self.callback, self.echo = address, progress, callback, echo
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise ConfigError(f"jobs must be a positive integer (cells run at once), got {jobs!r}")
        self.jobs, self.device = jobs, device
        self.threads = budget.threads if threads is None else threads
        self.data_dir = self.out / "data"
        self._ray = contextlib.ExitStack()
        self._ray_started = False

    # ---- paths ---------------------------------------------------------------------------------
    def path(self, kind: str, name: str) -> Path:
        """``models/NAME.pt``, ``fmus/NAME.fmu``, ``scores/NAME.npz``, ``tune/NAME.json`` ..."""
        suffix = {"models": ".pt", "fmus": ".fmu", "scores": ".npz", "tune": ".json"}[kind]
        return self.out / kind / f"{name}{suffix}"

    @property
    def networks(self) -> list[tuple[str, str]]:
        return [(a, s) for a in self.budget.archs for s in self.budget.strategies]

    @property
    def baselines(self) -> list[str]:
        """The baselines' file stems: the linear model, and the physics model (the arm model for the robot)."""
        return ["linear", "physics"]

    def fmu_name(self, name: str) -> str:
        """The FMU's model name (a C identifier), e.g. ``valve_gru_series_parallel``."""
        return f"{self.system}_{name}".replace("-", "_")

    # ---- the manifest ----------------------------------------------------------------------------
    def manifest(self) -> dict:
        return {"format": "nnfmu-study", "system": self.system, "budget": self.budget.to_json(), "seed": self.seed,
                "tune": self.tune, "data": None if self.source is None else str(self.source)}

    def check_manifest(self) -> None:
        """Refuse to mix two different studies in one folder; write the manifest of a new one."""
        file = self.out / "study.json"
        wanted = json.loads(json.dumps(self.manifest()))
        if file.exists():
            try:
                stored = json.loads(file.read_text())
            except ValueError as exc:
                raise DataFileError(f"{file} is damaged ({exc}); delete it, or use a new --out folder") from exc
            if stored != wanted:
                diff = sorted(k for k in wanted if stored.get(k) != wanted[k])
                raise ConfigError(f"{self.out} holds a study with other settings ({', '.join(diff)} differ); "
                                  "run it with the same options to resume it, or choose a new --out folder")
            return
        self.out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(file, json.dumps(wanted, indent=2) + "\n")

    # ---- cells -----------------------------------------------------------------------------------
    def cells(self) -> list[Cell]:
        data = self.data_dir
        src = () if self.source is None or self.source.is_dir() else (self.source,)
        cells = [Cell("data", (data,), src, lambda: cell_work.prepare_data(
            self.system, self.budget, self.seed, self.source, data, self.progress), where="driver")]
        for arch, strategy in self.networks:
            cells += self._network_cells(arch, strategy)
        lin_json, lin_fmu, phys_fmu = self.out / "models" / "linear.json", self.path("fmus", "linear"), \
            self.path("fmus", "physics")
        cells += [
            Cell("identify linear baseline", (lin_json,), (data,),
                 lambda: cell_work.identify_baseline(data, dict(self.budget.linear), lin_json, self.progress)),
            Cell("export linear baseline", (lin_fmu,), (lin_json,),
                 lambda: cell_work.export_linear(lin_json, lin_fmu, self.fmu_name("linear"))),
            Cell("export physics model", (phys_fmu,), (), lambda: cell_work.export_physics(self.system, phys_fmu)),
        ]
        for name in [network_name(a, s) for a, s in self.networks] + self.baselines:
            fmu, scores = self.path("fmus", name), self.path("scores", name)
            cells.append(Cell(f"score {name}", (scores,), (fmu, data),
                              lambda fmu=fmu, scores=scores: cell_work.score_fmu(fmu, data, scores)))
        return cells + [self._report_cell()]

    def _network_cells(self, arch: str, strategy: str) -> list[Cell]:
        name = network_name(arch, strategy)
        ckpt, fmu, tuned = self.path("models", name), self.path("fmus", name), self.path("tune", name)
        inputs = (self.data_dir, tuned) if self.tune else (self.data_dir,)
        cells = []
        if self.tune:
            cells.append(Cell(f"tune {arch} {strategy}", (tuned,), (self.data_dir,),
                              lambda: self._tune(arch, strategy, tuned), where="driver"))
        cells += [
            Cell(f"train {arch} {strategy}", (ckpt,), inputs,
                 lambda: cell_work.train_network(self.data_dir, arch, strategy, self.hyper(arch, strategy),
                                             self.budget, self.seed, ckpt, inputs, self.progress,
                                             self._epoch_callback(name), self.device, self.threads),
                 done=lambda: cell_work.training_finished(ckpt)),
            Cell(f"export {arch} {strategy}", (fmu,), (ckpt,),
                 lambda: cell_work.export_network(ckpt, fmu, self.fmu_name(name))),
        ]
        return cells

    def hyper(self, arch: str, strategy: str) -> Hyper:
        """The preset hyperparameters, or the tuned ones with ``--tune``."""
        if not self.tune:
            return self.budget.hyper[arch]
        from nnfmu.study.tune import TuneResult

        return TuneResult.load(self.path("tune", network_name(arch, strategy))).best

    def _epoch_callback(self, name: str):
        if self.callback is None:
            return None
        return lambda epoch, metrics: self.callback(name, epoch, metrics)

    def _tune(self, arch: str, strategy: str, out: Path) -> str:
        from nnfmu.data import load_dataset
        from nnfmu.study.tune import TuneSettings, ray_session, tune_architecture

        if not self._ray_started:  # one Ray instance for all the searches of this run
            self._ray.enter_context(ray_session(self.address))
            self._ray_started = True
        b = self.budget
        settings = TuneSettings(epochs=b.tune_epochs, patience=b.tune_patience, max_minutes=b.tune_max_minutes,
                                seed=self.seed, device=self.device)
        result = tune_architecture(load_dataset(self.data_dir), arch, strategy=strategy, base=b.hyper[arch],
                                   grid=b.grid(arch), settings=settings, address=self.address,
                                   storage=self.out / "tune" / "ray", progress=self.progress)
        result.save(out)
        return f"best {result.best_valid_nrmse:.4f} of {len(result.trials)} trials: {result.best.to_dict()}"

    def _report_cell(self) -> Cell:
        from nnfmu.study.results import write_results

        names = [network_name(a, s) for a, s in self.networks] + self.baselines
        inputs = tuple(self.path("scores", n) for n in names) + tuple(self.path("models", network_name(a, s))
                                                                      for a, s in self.networks)
        outputs = (self.out / "results.md", self.out / "results.json")
        # on the driver: the report reads the whole study folder, not only the files named as inputs
        return Cell("write results.md, results.json and figures", outputs, inputs, lambda: write_results(self),
                    where="driver")

    # ---- running ---------------------------------------------------------------------------------
    def _run_parallel(self) -> CellLog:
        """Up to ``jobs`` cells at once, in local processes or as Ray tasks (:mod:`nnfmu.study.parallel`)."""
        if self.address:
            from nnfmu.study.ray_connect import ray_session

            ray = self._ray.enter_context(ray_session(self.address))
            self._ray_started = True
            from nnfmu.training.resources import gpus_per_training

            gpus = gpus_per_training(self.device, ray.cluster_resources().get("GPU", 0))  # auto: one where there is
            pool = parallel.RayPool(ray, study_from_spec, cpus=self.threads, gpus=gpus)
            jobs = self.jobs if self.jobs > 1 else max(1, int(ray.cluster_resources().get("CPU", 1) // self.threads))
        else:
            pool, jobs = parallel.LocalPool(self.jobs, study_from_spec), self.jobs
        try:
            return parallel.run_cells_parallel(self.cells(), pool, parallel.study_spec(self), self.out, jobs,
                                               echo=self.echo)
        finally:
            pool.close()

    def run(self) -> StudyResult:
        if self.tune:
            from nnfmu.study.tune import require_ray

            require_ray()  # a missing extra is said before any work, not after the data are made
        cell_work.check_source(self.system, self.source, self.data_dir)  # bad --data: say so and leave the folder alone
        from nnfmu.training.resources import check_threads, device_name, resolve_device

        check_threads(self.threads)
        if self.address:  # the cluster's workers have the GPUs, not necessarily this driver
            device_name(self.device)
        else:
            resolve_device(self.device)  # a missing GPU is said before any work
        self.check_manifest()
        from nnfmu.models.base import torch_threads

        try:
            with torch_threads(self.threads):
                if self.address or self.jobs > 1:
                    log = self._run_parallel()
                else:
                    log = run_cells(self.cells(), echo=self.echo)
        finally:
            self._ray.close()
            self._ray_started = False
        results = json.loads((self.out / "results.json").read_text())
        return StudyResult(self.out, log, results)


def study_from_spec(spec: dict, out: str | Path) -> Study:
    """The :class:`Study` a worker rebuilds from :func:`nnfmu.study.parallel.study_spec` in the folder ``out``."""
    return Study(spec["system"], out, parallel.budget_from_json(spec["budget"]), data=spec["data"], tune=spec["tune"],
                 seed=spec["seed"], progress=False, echo=None, device=spec["device"], threads=spec["threads"])


def reproduce(system: str, out: str | Path, *, budget: str | Budget = "quick", data: str | Path | None = None,
              tune: bool | None = None, seed: int = 0, address: str | None = None, progress: bool = True,
              callback: TrainCallback | None = None, echo: Callable[[str], None] | None = print,
              jobs: int = 1, device: str = "auto", threads: int | None = None) -> StudyResult:
    """Run (or resume) the paper's study of ``system`` into the folder ``out``.

    Parameters
    ----------
    system : str
        A study of a registered physics model (:func:`nnfmu.physics.study_names`: valve, arm, robot, slider).
    out : path
        The study folder; cells already done there are skipped, an unfinished training is resumed.
    budget : str or Budget
        'smoke', 'quick' or 'paper' (see :mod:`nnfmu.study.budgets`), or a custom :class:`Budget`.
    data : path, optional
        A dataset folder, or the robot benchmark's ``.mat`` file (required for 'robot').
    tune : bool, optional
        Grid-search the hyperparameters on Ray Tune per architecture and strategy
        (default: the budget's choice, on for 'paper').
    seed : int
        Seeds the generated data, the validation split and every training.
    address : str, optional
        A running Ray cluster: the study's cells run there as Ray tasks (files travel with them, so
        the nodes need no shared folder), and so does the search; default: this machine.
    progress : bool
        Progress bars for data generation and training.
    callback : callable, optional
        ``callback(network_name, epoch, metrics)`` after every training epoch.
    echo : callable or None
        Prints one line per cell (default ``print``).
    jobs : int
        Cells run at once in local processes (default 1: in this process, in order); with
        ``address``, tasks at once (default: the cluster's CPUs / threads).
    device : {'auto', 'cpu', 'cuda'}
        Where the networks train (:mod:`nnfmu.training.resources`).
    threads : int, optional
        Torch threads of each training (default: the budget's, one).
    """
    if isinstance(budget, str):
        budget = get_budget(system, budget)
    return Study(system, out, budget, data=data, tune=tune, seed=seed, address=address, progress=progress,
                 callback=callback, echo=echo, jobs=jobs, device=device, threads=threads).run()
