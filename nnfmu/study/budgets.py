"""The study's budgets: one typed table of data sizes, training lengths and hyperparameters.

``BUDGETS[system][name]`` is a :class:`Budget`; :func:`get_budget` looks one up
with a clear error. The systems are the studies of the registered physics models
(:class:`nnfmu.physics.StudyPreset`: the valve, the arm and the slider on data
their models generate, and the measured industrial robot benchmark); each
study's preset gives its data sizes, noise, linear options and training lengths.
The preset hyperparameters and the measurements that chose them are in
:mod:`nnfmu.study.presets`; a study without a table of its own starts every
architecture at its record's preset (:func:`nnfmu.study.presets.preset_for`).

==========  ===============================================================
budget      what it is for
==========  ===============================================================
``smoke``   the pipeline end to end in a few minutes on 2 cores: small data,
            tiny networks, 2 epochs. The numbers mean nothing.
``quick``   meaningful numbers: full-size data, the preset hyperparameters,
            tens of epochs with early stopping (robot: 2 seeds per network,
            their ensemble scored and their spread reported).
``paper``   the paper's protocol: full-size data, long training with early
            stopping on the validation free-run NRMSE; hyperparameters from
            a grid search (Ray Tune) per architecture and strategy, except
            for the robot, whose researched recipe is kept and trained from
            5 seeds (``--tune`` still searches). Hours.
``demo``    (valve only) ``nnfmu demo``: a parallel and a series-parallel GRU
            at equal budgets (the paper-size data, 20 epochs on windows of
            100 samples), sized so that the paper's finding shows; about
            2 minutes on 2 cores (1 min 55 s measured).
==========  ===============================================================

Every budget is counted in epochs (and early stopping), so that a seed gives
the same table on any machine; the wall-clock limit of a training
(:data:`SAFETY_NET_MINUTES`) is a safety net that normal runs never reach, and
``results.md`` says when it fired.

Generated valve data get white measurement noise (:data:`VALVE_NOISE`, 5 % of
each output's training standard deviation) in every budget: the paper's valve
data were measured on a test bench, and noise-free simulated outputs favour
series-parallel training, which feeds them back. Measured on the demo preset
(GRU-32, 20 epochs, seeds 0, 1, 2; free-run test NRMSE, parallel vs
series-parallel): with 2 % noise 0.080/0.109, 0.092/0.100, 0.092/0.085 (series-
parallel won once); with 5 % noise 0.105/0.153, 0.116/0.143, 0.110/0.154. With
``quick`` (seed 0, whole trajectories) series-parallel won for 4 of 5
architectures without noise and 2 of 5 with 2 % noise; with 5 % noise and
windows of 100 samples parallel wins for all 5 (figures in :mod:`nnfmu.study.presets`).

The preset hyperparameters (:class:`Hyper`, one per architecture) are the
same for both strategies, so that a preset study compares the strategies at
equal settings; ``--tune`` replaces them by a grid search per architecture
and strategy, as the paper did.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

from nnfmu.errors import ConfigError, check_options
from nnfmu.models import architectures
from nnfmu.physics import StudyPreset, study_names, study_preset
from nnfmu.study import presets
from nnfmu.study.hyper import Hyper
from nnfmu.training import KEEP, STRATEGIES

SYSTEMS = study_names(plugins=False)  # a plug-in's study gets its budgets from get_budget (a broken one
#                                     must not break importing the study)


def network_name(arch: str, strategy: str) -> str:
    """File stem of a network's checkpoint, FMU and score: ``gru-parallel``, ``gru-series-parallel``."""
    return f"{arch}-{strategy}"


@dataclass(frozen=True, kw_only=True)
class Budget:
    """Everything a study of one system at one budget needs, except the seed.

    Attributes
    ----------
    name, description : str
    data_size : str or None
        Size passed to :func:`nnfmu.physics.generate_dataset` (valve: 'small' or 'paper';
        arm: 'small' or 'benchmark'); None for loaded data (robot).
    max_train, max_test : int or None
        Keep only the first this many training / test trajectories (None: all).
    valid_fraction : float
        Share of the training trajectories set aside for validation when the data has no 'valid' split.
    noise : float
        White Gaussian measurement noise added to the outputs of generated data, as a fraction of
        each output's training standard deviation, in every split (the paper's data were measured).
    archs, strategies : tuple of str
        The networks trained: every architecture (default: those ``hyper`` covers, in its order; each a registered
        one) with every strategy.
    epochs, patience : int
        Maximum epochs and early-stopping patience of every training: the budget proper, so that
        a seed gives the same table on any machine.
    max_minutes : float or None
        Wall-clock safety net of one training (minutes): set well above what the epochs take, it
        only stops a run that would otherwise hang a study; the best epoch so far is kept and the
        results say when it fired (stop reason ``time-budget``).
    seeds, keep :
        Every network is trained from ``seeds`` seeds (the study's seed, +1, ...); the study
        scores the kept model (``keep``: 'ensemble' of the seeds, or the 'best' on validation)
        and reports the spread of the seeds' own test scores next to it. 1: one seed.
    hyper : mapping arch -> Hyper
        Preset hyperparameters per architecture.
    linear : mapping
        Options of :func:`nnfmu.linear.identify_linear`.
    tune : bool
        Whether the study searches the hyperparameters (Ray Tune) unless told otherwise.
    tune_grid : mapping arch -> mapping field -> tuple of values
        The grid searched around ``hyper[arch]``.
    tune_epochs, tune_patience : int
        Training length of one trial.
    tune_max_minutes : float or None
        Wall-clock cap of one trial (minutes).
    threads : int
        torch threads per training. Recurrent steps of small networks are latency-bound:
        one thread is fastest, and with a second busy process two threads were measured
        up to 30 times slower.
    """

    name: str
    description: str
    data_size: str | None
    max_train: int | None = None
    max_test: int | None = None
    valid_fraction: float = 0.1
    noise: float = 0.0
    archs: tuple[str, ...] = ()
    strategies: tuple[str, ...] = STRATEGIES
    epochs: int
    patience: int
    max_minutes: float | None = None
    seeds: int = 1
    keep: str = "ensemble"
    hyper: Mapping[str, Hyper]
    linear: Mapping = field(default_factory=dict)
    tune: bool = False
    tune_grid: Mapping[str, Mapping[str, tuple]] = field(default_factory=dict)
    tune_epochs: int = 10
    tune_patience: int = 5
    tune_max_minutes: float | None = None
    threads: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "archs", tuple(self.archs or self.hyper))
        unknown = [a for a in self.archs if not architectures.is_architecture(a)]
        unknown += [s for s in self.strategies if s not in STRATEGIES]
        if unknown:
            raise ConfigError(f"budget {self.name!r}: unknown architecture or strategy {unknown}; valid: "
                              f"{', '.join(architectures.names() + STRATEGIES)}")
        if isinstance(self.seeds, bool) or not isinstance(self.seeds, int) or self.seeds < 1:
            raise ConfigError(f"budget {self.name!r}: seeds must be a positive integer, got {self.seeds!r}")
        if self.keep not in KEEP:
            raise ConfigError(f"budget {self.name!r}: unknown keep {self.keep!r}; choose one of {', '.join(KEEP)}")
        if not 0.0 <= self.noise < 1.0:
            raise ConfigError(f"budget {self.name!r}: noise must be a fraction in [0, 1), got {self.noise!r}")
        missing = [a for a in self.archs if a not in self.hyper]
        if missing:
            raise ConfigError(f"budget {self.name!r} has no hyperparameters for {missing}")
        object.__setattr__(self, "hyper", MappingProxyType(dict(self.hyper)))
        object.__setattr__(self, "linear", MappingProxyType(dict(self.linear)))
        object.__setattr__(self, "tune_grid", MappingProxyType(dict(self.tune_grid)))

    def grid(self, arch: str) -> dict[str, tuple]:
        """The tune grid of ``arch`` (field -> values); at least one point (the preset) when none is set."""
        return {k: tuple(v) for k, v in self.tune_grid.get(arch, {}).items()}

    def replace(self, **changes) -> "Budget":
        check_options(changes, {f.name for f in dataclasses.fields(self)}, "Budget")
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict:
        """A JSON-clean description (stored in the study's manifest and results)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["hyper"] = {a: h.to_dict() for a, h in self.hyper.items()}
        d["linear"] = dict(self.linear)
        d["tune_grid"] = {a: {k: list(v) for k, v in g.items()} for a, g in self.tune_grid.items()}
        d["archs"], d["strategies"] = list(self.archs), list(self.strategies)
        return d


def _budgets(study: StudyPreset, hyper: dict, quick_hyper: dict) -> dict[str, Budget]:
    full_size, small_size = study.data_sizes or (None, None)
    quick_epochs, quick_patience, quick_seeds = study.quick_epochs, study.quick_patience, study.quick_seeds
    paper_seeds, paper_tune, noise = study.paper_seeds, study.paper_tune, study.noise
    linear_quick, linear_paper = dict(study.linear_quick), dict(study.linear_paper)
    smoke_data = {"data_size": small_size} if small_size else {"data_size": None, "max_train": 6}
    smoke_data["noise"] = noise
    seeds = f", {quick_seeds} seeds (their ensemble)" if quick_seeds > 1 else ""
    tuned = "grid-searched hyperparameters" if paper_tune else "the preset recipe"
    return {
        "smoke": Budget(name="smoke", description="pipeline check: small data, tiny networks, 2 epochs",
                        **smoke_data, epochs=2, patience=0, hyper=presets.SMOKE, linear=presets.LINEAR_SMOKE,
                        tune_grid=presets.SMOKE_GRID, tune_epochs=1, tune_patience=0),
        "quick": Budget(name="quick", description=f"full-size data, preset hyperparameters, up to {quick_epochs} "
                                                  f"epochs (patience {quick_patience}){seeds}",
                        data_size=full_size, noise=noise, epochs=quick_epochs, patience=quick_patience,
                        max_minutes=SAFETY_NET_MINUTES, seeds=quick_seeds, hyper=quick_hyper,
                        linear=linear_quick, tune_grid=presets.quick_grid(), tune_epochs=10, tune_patience=5,
                        tune_max_minutes=2.0),
        "paper": Budget(name="paper", description=f"the paper's protocol: {tuned}, up to 1000 epochs with early "
                                                  f"stopping (patience 50)" + (f", {paper_seeds} seeds (their "
                                                                               "ensemble)" if paper_seeds > 1 else ""),
                        data_size=full_size, noise=noise, epochs=1000, patience=50, max_minutes=4 * SAFETY_NET_MINUTES,
                        seeds=paper_seeds, hyper=hyper, linear=linear_paper, tune=paper_tune,
                        tune_grid=presets.paper_grid(), tune_epochs=60, tune_patience=15, tune_max_minutes=15.0),
    }


# Generated valve data get 5 % measurement noise (the valve's StudyPreset): the paper's valve data were measured,
# and on noise-free simulated data series-parallel training is far more competitive (figures in the module docstring).
VALVE_NOISE = study_preset("valve")[1].noise
# A training stops on its epochs and early stopping; this wall-clock limit only keeps a hung or absurdly slow
# run from stalling a study, and the results say when it fired (so that the table is known to depend on the machine).
SAFETY_NET_MINUTES = 60.0

# The measured hyperparameters ('paper', 'quick') of the studies that have a table (nnfmu.study.presets): data about
# a pair of a system and an architecture, which neither's folder owns.
_MEASURED = {"valve": (presets.VALVE, presets.VALVE_QUICK), "arm": (presets.ARM, presets.ARM),
             "robot": (presets.ROBOT, presets.ROBOT), "slider": (presets.SLIDER, presets.SLIDER)}

# nnfmu demo (nnfmu.study.demo): a parallel and a series-parallel GRU on the valve at equal budgets.
_DEMO = {"valve": Budget(name="demo", description="nnfmu demo: a parallel and a series-parallel GRU at equal budgets "
                                                  "(20 epochs on windows of 100 samples) on the paper-size valve data",
                         data_size="paper", noise=VALVE_NOISE, epochs=20, patience=10,
                         max_minutes=SAFETY_NET_MINUTES, hyper=presets.DEMO, linear={"refine": False})}


def _study_budgets(name: str) -> Mapping[str, Budget]:
    start = {a: presets.preset_for(a) for a in presets.SMOKE}  # the networks the tables cover
    hyper, quick_hyper = _MEASURED.get(name, (start, start))
    extra = {"demo": _DEMO[name]} if name in _DEMO else {}
    return MappingProxyType({**_budgets(study_preset(name)[1], hyper, quick_hyper), **extra})


BUDGETS: Mapping[str, Mapping[str, Budget]] = MappingProxyType({name: _study_budgets(name) for name in SYSTEMS})


def get_budget(system: str, name: str) -> Budget:
    """``BUDGETS[system][name]`` with an error listing the valid choices; a study registered after this module
    was imported (a plug-in's) gets its budgets built here."""
    budgets = BUDGETS.get(system) or _study_budgets(system)  # ConfigError listing the studies if there is none
    if name not in budgets:
        raise ConfigError(f"unknown budget {name!r} for the {system}; choose one of {', '.join(budgets)}")
    return budgets[name]
