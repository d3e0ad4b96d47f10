"""The small search space of ``nnfmu train --max-minutes N`` (:mod:`nnfmu.study.time_search`) and its trials.

The knobs that matter on data nobody tuned for (issue 21): the architecture, the width, the training window
(``--truncate``), the learning rate and the feedback noise. Every knob the user gave stays as given; the others
take these values:

- ``arch``: the architectures whose record has a ``search_rank``, in its order (gru, lstm, tcn, mlp, rnn, then
  plugins that ask for it; :func:`arch_order`), the given ``model_config.arch`` first;
- ``hidden``: 16, 32, 64; ``lr``: 1e-3, 3e-3, 1e-2; ``feedback_noise``: 0, 0.1 (output standard deviations);
- ``truncate``: the planned window times 0.5, 1 and 2, when the plan trains on windows (else whole trajectories).

Trial 0 is the plain training at the defaults (the given architecture, hidden 32, lr 3e-3, no noise, the
planned window), so the search keeps it unless something beats it on validation. The next trials take the
architectures in turn, with the other knobs drawn at random (seeded) and no point twice. Once every point has
started, the best points train again with further seeds (:func:`again`).
"""

from __future__ import annotations

import math

import numpy as np

from nnfmu.errors import NnfmuError
from nnfmu.models import ModelConfig, architectures
from nnfmu.training import TrainConfig
HIDDEN = (16, 32, 64)
LRS = (1e-3, 3e-3, 1e-2)
NOISES = (0.0, 0.1)
TRUNCATE_FACTORS = (0.5, 1.0, 2.0)
KNOBS = ("arch", "hidden", "lr", "feedback_noise", "truncate")
# The model options a user may give (``nnfmu train``); they are kept in every trial.
MODEL_OPTIONS = ("hidden", "layers", "window", "dropout", "init_window")


def arch_order() -> tuple[str, ...]:
    """The searched architectures: those whose record has a ``search_rank``, lowest first."""
    return architectures.search_order()


def axes(model_config: ModelConfig, train_config: TrainConfig, given, longest: int) -> dict:
    """Knob -> the values it takes (one value: fixed). ``longest``: samples of the longest training record."""
    arch = model_config.arch
    truncate = train_config.truncate
    windows = (truncate,)
    if truncate is not None and "truncate" not in given:
        windows = tuple(sorted({w for f in TRUNCATE_FACTORS if 2 <= (w := int(round(f * truncate))) <= longest}))
    # a model that feeds back no output (a neural ODE's state is its own) refuses feedback noise: search none
    noises = NOISES if architectures.model_class(arch).takes_feedback_noise else (0.0,)
    return {"arch": (arch,) if "arch" in given else (arch,) + tuple(a for a in arch_order() if a != arch),
            "hidden": (model_config.hidden,) if "hidden" in given else HIDDEN,
            "lr": (train_config.lr,) if "lr" in given else LRS,
            "feedback_noise": (train_config.feedback_noise,) if "feedback_noise" in given else noises,
            "truncate": windows}


def trial_points(model_config: ModelConfig, train_config: TrainConfig, given, n: int, seed: int,
                 longest: int) -> list[dict]:
    """Up to ``n`` distinct points of the space (knob -> value), trial 0 the defaults (module docstring)."""
    space = axes(model_config, train_config, given, longest)
    space["arch"] = tuple(a for a in space["arch"] if _builds(model_config, a, given))
    default = {"arch": space["arch"][0],
               "hidden": model_config.hidden if "hidden" in given else ModelConfig.hidden,
               "lr": train_config.lr if "lr" in given else TrainConfig.lr,
               "feedback_noise": train_config.feedback_noise if "feedback_noise" in given else 0.0,
               "truncate": train_config.truncate}
    points, seen = [default], {point_key(default)}
    size = math.prod(len(v) for v in space.values())
    rng = np.random.default_rng(seed)
    k = 1
    while len(points) < min(n, size):
        arch = space["arch"][k % len(space["arch"])]
        for _ in range(50):  # a fresh point of this architecture, if it has one left
            point = {"arch": arch, **{name: space[name][rng.integers(len(space[name]))] for name in KNOBS[1:]}}
            if "feedback_noise" not in given and not architectures.model_class(arch).takes_feedback_noise:
                point["feedback_noise"] = 0.0  # searched for the base architecture; this one refuses any
            if point_key(point) not in seen:
                points.append(point)
                seen.add(point_key(point))
                break
        k += 1
        if k > 50 * n:
            break
    return [{name: _plain(v) for name, v in p.items()} for p in points]


def trial_configs(point: dict, model_config: ModelConfig, train_config: TrainConfig,
                  given) -> tuple[ModelConfig, TrainConfig]:
    """The ModelConfig and TrainConfig of one point: the given options kept, the point's knobs set."""
    model = _model(model_config, point["arch"], given).replace(hidden=point["hidden"])
    train = train_config.replace(lr=point["lr"], feedback_noise=point["feedback_noise"], truncate=point["truncate"])
    return model, train


def _model(model_config: ModelConfig, arch: str, given) -> ModelConfig:
    """``model_config`` as ``arch``: the options the user gave kept, the architecture's own defaults otherwise."""
    if arch == model_config.arch:
        return model_config
    kept = {k: getattr(model_config, k) for k in MODEL_OPTIONS if k in given}
    config_class = architectures.architecture(arch).get("config_class")
    return config_class(arch=arch, n_u=model_config.n_u, n_y=model_config.n_y, increment=model_config.increment,
                        linear_order=model_config.linear_order, **kept)


def _builds(model_config: ModelConfig, arch: str, given) -> bool:
    try:
        _model(model_config, arch, given)
        return True
    except NnfmuError:  # e.g. a given --window that a recurrent network cannot take
        return False


def point_key(point: dict) -> tuple:
    """A point's knobs (:data:`KNOBS`) as a tuple: the same for every seed of the point (a trial's row or point)."""
    return tuple(point[k] for k in KNOBS)


def _plain(v):
    return v.item() if isinstance(v, np.generic) else v


def again(run: list, scores: dict, halved: set, keep: int) -> dict | None:
    """The point to train once more, with the next seed, once every point of the space has started.

    ``run``: the points of the trials so far (with their ``seed``), ``scores``: trial -> its best validation NRMSE,
    ``halved``: the trials successive halving stopped. Among the ``keep`` points best on validation (a point's
    score: its best trial's) that trained to their own stop, the one with the fewest seeds so far (the better first)
    gets the next seed: further seeds of the best points give the ensemble selection members that differ by their
    seed alone (the search trains them to their own stop, as it does trial 0). None while no point qualifies.
    """
    best, seeds = {}, {}
    for i, point in enumerate(run):
        key = point_key(point)
        seeds[key] = max(seeds.get(key, point["seed"]), point["seed"])
        if i in scores and i not in halved:
            best[key] = min(best.get(key, math.inf), scores[i])
    top = sorted(best, key=best.get)[:keep]
    if not top:
        return None
    counts = {key: sum(point_key(p) == key for p in run) for key in top}
    key = min(top, key=lambda k: (counts[k], best[k]))
    return {**dict(zip(KNOBS, key)), "seed": seeds[key] + 1}


def label(point: dict) -> str:
    """A short text of a point, e.g. ``gru h32 lr 0.003 noise 0 T 400`` (`` seed 2`` where it has one)."""
    window = "whole" if point["truncate"] is None else point["truncate"]
    seed = f" seed {point['seed']}" if "seed" in point else ""
    return (f"{point['arch']} h{point['hidden']} lr {point['lr']:g} noise {point['feedback_noise']:g} "
            f"T {window}{seed}")
