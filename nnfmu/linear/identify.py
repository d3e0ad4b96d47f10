"""Identify a linear baseline from a dataset: subspace fit, order selection, stabilisation, refinement.

Steps of :func:`identify_linear`:

1. Normalise. Inputs and outputs are divided by their training std. With
   ``init="estimate"`` the training means are removed and the model is affine
   (offsets ``b``, ``d`` estimated with ``A, B, C``); with ``init="zero-offset"``
   each trajectory is taken relative to its first sample and ``b = d = 0``.
2. Subspace fit (N4SID, :mod:`nnfmu.linear.subspace`) on the training split,
   with horizon ``s = max(2, ceil((n_max + 1) / n_y))`` unless given.
3. Order. ``order=N`` forces it. Otherwise every order from 1 to ``max_order``
   that the singular values support is realised and scored by its free-run NRMSE on
   the validation split (the training split if there is none). Up to
   ``order_candidates`` orders (the best of those, and the orders at the largest
   singular-value gaps) are then refined for a tenth of the refinement's evaluations
   and scored again, and the order chosen is the smallest candidate within
   ``order_tolerance`` (relative, at least 1e-6) of the best refined one
   (:mod:`nnfmu.linear.order`: the subspace models alone can rank orders wrongly,
   on the robot every one ran worse than the mean). The subspace scores decide
   with ``order_candidates=1``, ``refine=False``, or without a validation split:
   on the training data the refined candidates were fitted to, more states
   always look better.
4. Stability. Eigenvalues of ``A`` beyond ``0.999 * max_spectral_radius`` are
   pulled onto that circle and ``B, b`` refitted.
5. Refinement (optional, :mod:`nnfmu.linear.refine`): output-error least squares on
   the free runs of the training split, stopped early when the validation NRMSE stops
   improving: it is checked every ``max_evaluations // 100`` evaluations (at least 1), and
   after ``refine_patience`` checks in a row without a better one the refinement ends and
   the best model seen is kept (the subspace model if none was better), so refinement
   never makes the validation error worse. ``refine_patience=None``: run to the limit, and
   keep the end point only if its validation NRMSE is no worse than the subspace model's.
6. Refit (``refit=True``, the default, where a validation split chose the order or stopped the
   refinement): the model is estimated again on all the data, the training and validation records
   together (or the records ``refit_on`` names: ``nnfmu train`` and ``nnfmu linear`` pass the one
   record their validation tail was cut from), at the order chosen and for the refinement evaluations
   that validation chose, without looking at validation again. Validation chose *how much* model; the
   data it held out then helps estimate it: on one record, a 25 % tail held out and never refitted cost
   the two-tank record 0.592 -> 0.691 V and the positioning axis 5.95 -> 8.94 mm on test (issue 38).
   ``info["refit"]`` says what the refit used and the chosen model's validation score before it
   (``nrmse_valid_before``, the fair one: the refitted model has seen the validation data, and its
   ``info["nrmse_valid"]`` is what a network starting from it scores at epoch 0).
7. The scaling is folded back: :class:`~nnfmu.linear.LinearModel` works in physical units.

Records that are consecutive pieces of one recording (the dataset's ``source["contiguous"]``, as the robot
benchmark's 605-sample pieces, with a valid split of its own and several training records) are joined end to
end first, each split into one record (``join=True``, the default; ``info["joined"]`` says so), as
``nnfmu train`` joins them for its networks: the output-error fit and the order's validation then run over
the recording's horizon, not 605 samples from each piece's init rule. On the robot, before the refit (so
that validation is unseen), this took the validation free-run NRMSE over the joined validation record from
0.8624 to 0.7545, and over its separate pieces from 0.7882 to 0.7619, at 62 CPU-s against 9 (docs/accuracy.md).

Every step runs with ``threads`` BLAS threads (default 1, through threadpoolctl). The
threaded BLAS rounds its sums differently, and 1000 quasi-Newton steps carry that
difference to another end point: on the robot one thread gave a test NRMSE of 0.8514 in
54 CPU-s, the machine's default of two threads 0.8528 in 204 CPU-s. With one thread the
baseline no longer depends on how many cores the machine has.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits
from nnfmu.progress import tqdm  # a line every few seconds in a log file, not one per evaluation

from nnfmu.data import Dataset, Trajectories
from nnfmu.errors import ConfigError, ShapeError, check_options
from nnfmu.linear.model import LinearModel
from nnfmu.linear.order import OrderChoice, choose_order
from nnfmu.linear.refine import METHODS, X0_OPTIONS, EarlyStop, refine
from nnfmu.linear.statespace import (
    INIT_OPTIONS,
    StateSpace,
    free_run,
    initial_states,
    padded,
    stabilise,
)
from nnfmu.linear.subspace import fit_subspace, realise, refit_inputs, usable_columns
from nnfmu.metrics import nrmse
from nnfmu.valid_range import training_range


@dataclass(frozen=True, kw_only=True)
class LinearConfig:
    """Options of :func:`identify_linear` (see the module docstring for what each step does).

    Attributes
    ----------
    order : int or None
        Number of states; ``None`` chooses it (step 3).
    max_order : int
        Largest order tried when choosing.
    horizon : int or None
        Past and future block rows of the subspace fit; ``None`` for the rule in step 2.
    init : {"estimate", "zero-offset"}
        Initial-state rule of the model (:mod:`nnfmu.linear.model`).
    refine : bool
        Run the output-error refinement.
    refine_x0 : {"rule", "fit"}
        Training runs start by the init rule, or from a fitted state per trajectory.
    refine_method : {"quasi-newton", "gauss-newton"}
        The refinement's minimiser (:mod:`nnfmu.linear.refine`): adjoint gradients and BFGS
        (cheap evaluations, the default), or trust-region Gauss-Newton (``J^T J`` per evaluation).
    max_evaluations : int or None
        Cost evaluations allowed to the refinement; ``None``: 1000 for ``quasi-newton``, 100 for
        ``gauss-newton`` (about the same CPU time on the robot, where an evaluation costs 0.04 s
        or 3 s).
    refine_patience : int or None
        Validation checks in a row without improvement after which the refinement stops (step 5);
        None: no early stop.
    max_spectral_radius : float
        No refined ``A`` reaches this spectral radius (in (0, 1]).
    order_tolerance : float
        Relative NRMSE tolerance of the order choice.
    order_candidates : int
        Most orders refined shortly to choose the order (step 3); 1: the subspace scores decide.
    threads : int
        BLAS threads of the identification (default 1: faster on this project's small
        matrices, and a result that does not depend on the machine's core count).
    refit : bool
        After choosing on validation, estimate the model again on the training and validation data
        together (step 6).
    join : bool
        Join each split's records end to end where the dataset says they are consecutive pieces of one
        recording (above).
    """

    order: int | None = None
    max_order: int = 20
    horizon: int | None = None
    init: str = "estimate"
    refine: bool = True
    refine_x0: str = "rule"
    refine_method: str = "quasi-newton"
    max_evaluations: int | None = None
    refine_patience: int | None = 10
    max_spectral_radius: float = 0.9999
    order_tolerance: float = 0.02
    order_candidates: int = 4
    threads: int = 1
    refit: bool = True
    join: bool = True

    def __post_init__(self) -> None:
        for name, allowed in (("init", INIT_OPTIONS), ("refine_x0", X0_OPTIONS), ("refine_method", METHODS)):
            if getattr(self, name) not in allowed:
                raise ConfigError(f"{name} must be one of {', '.join(allowed)}, got {getattr(self, name)!r}")
        for name in ("order", "max_order", "horizon", "max_evaluations", "refine_patience", "order_candidates",
                     "threads"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, (int, np.integer)) or value < 1):
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if not 0.0 < self.max_spectral_radius <= 1.0:
            raise ConfigError(f"max_spectral_radius must be in (0, 1], got {self.max_spectral_radius}")
        if not self.order_tolerance >= 0.0:
            raise ConfigError(f"order_tolerance must be >= 0, got {self.order_tolerance}")

    @property
    def evaluations(self) -> int:
        """``max_evaluations``, or its default for ``refine_method``."""
        if self.max_evaluations is not None:
            return self.max_evaluations
        return 1000 if self.refine_method == "quasi-newton" else 100

    @classmethod
    def from_dict(cls, options: dict) -> LinearConfig:
        """Build from a dictionary (JSON, CLI); unknown keys raise UnknownOptionError listing the valid ones."""
        check_options(options, [f.name for f in dataclasses.fields(cls)], "linear")
        return cls(**options)


@dataclass(frozen=True)
class _Scaling:
    """Normalisation: ``(u - u_ref) / u_std``; ``u_ref`` is the training mean or each trajectory's u0."""

    init: str
    u_mean: np.ndarray
    u_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray

    def apply(self, tr: Trajectories) -> tuple[list[np.ndarray], list[np.ndarray]]:
        if self.init == "zero-offset":
            return ([(u - u[0]) / self.u_std for u in tr.u], [(y - y[0]) / self.y_std for y in tr.y])
        return ([(u - self.u_mean) / self.u_std for u in tr.u], [(y - self.y_mean) / self.y_std for y in tr.y])

    def physical(self, sys: StateSpace) -> StateSpace:
        """Fold the scaling into the arrays: the same model, in physical units."""
        B = sys.B / self.u_std[None, :]
        C = sys.C * self.y_std[:, None]
        if self.init == "zero-offset":
            return StateSpace(sys.A, B, np.zeros(sys.n_x), C, np.zeros(len(self.y_std)))
        return StateSpace(sys.A, B, sys.b - B @ self.u_mean, C, self.y_std * sys.d + self.y_mean)


def free_run_nrmse(sys: StateSpace, init: str, us, ys) -> float:
    """Free-run NRMSE (mean over trajectories and outputs) of a normalised system on normalised data."""
    u, _ = padded(list(us))
    y0s = np.array([y[0] for y in ys])
    _, yhat = free_run(sys, initial_states(sys, init, y0s, u[:, 0]), u)
    preds = [np.vstack([y[:1], yhat[i, 1:len(y)]]) for i, y in enumerate(ys)]
    if not all(np.isfinite(p).all() for p in preds):
        return float("inf")
    return nrmse(list(ys), preds).mean


def _horizon(config: LinearConfig, n_y: int) -> int:
    if config.horizon is not None:
        return config.horizon
    n_max = config.order or config.max_order
    return max(2, math.ceil((n_max + 1) / n_y))


def _check_data(train: Trajectories, s: int, n_u: int, n_y: int, config: LinearConfig) -> None:
    needed = s * (2 * n_u + 2 * n_y) + (config.init == "estimate")
    have = usable_columns(train.lengths, s)
    what = f"order {config.order}" if config.order else f"orders up to {config.max_order}"
    if have < needed:
        raise ShapeError(
            f"{what} need a subspace horizon of {s} samples, which needs at least {needed} block-Hankel "
            f"columns (trajectories of at least {2 * s} samples); the training split gives {have} "
            f"(longest trajectory {int(train.lengths.max())} samples); choose a smaller order or horizon, "
            "or add data"
        )
    if config.order is not None and config.order > s * n_y:
        raise ShapeError(f"order {config.order} exceeds horizon {s} x {n_y} outputs = {s * n_y}; "
                         f"choose a horizon of at least {math.ceil(config.order / n_y)}")


def _subspace_model(fit, order: int, us, ys, radius: float) -> tuple[StateSpace, bool]:
    A, B, b, C, d = realise(fit, order, us, ys)
    stable_A = stabilise(A, radius)
    if stable_A is not A:
        B, b = refit_inputs(fit, stable_A, us, ys)
    return StateSpace(stable_A, B, b, C, d), stable_A is not A


def _refine(sys: StateSpace, config: LinearConfig, train, check, before: float,
            progress: bool, evaluations: int | None = None) -> tuple[StateSpace, dict]:
    """Refine ``sys`` with ``evaluations`` (default ``config.evaluations``); the system kept and a report."""
    if evaluations is not None:
        config = dataclasses.replace(config, max_evaluations=evaluations)
    bar = tqdm(total=config.evaluations, disable=not progress, unit="evaluation", dynamic_ncols=True,
               desc=f"linear: refine order {sys.n_x} (output error)")

    def show(evaluations: int, cost: float, best: float) -> None:
        bar.update(evaluations - bar.n)
        bar.set_postfix(cost=f"{cost:.6g}", best=f"{best:.6g}")

    early_stop = None if config.refine_patience is None else EarlyStop(
        lambda candidate: free_run_nrmse(candidate, config.init, *check),
        every=max(1, config.evaluations // 100), patience=config.refine_patience)
    with bar:
        result = refine(sys, *train, init=config.init, x0=config.refine_x0, max_radius=config.max_spectral_radius,
                        max_evaluations=config.evaluations, method=config.refine_method, report=show,
                        early_stop=early_stop)
        bar.total = bar.n  # stopped or converged before the limit: the bar ends full
    report = {"x0": config.refine_x0, "method": config.refine_method, "evaluations": result.evaluations,
              "message": result.message, "cost_before": result.cost_before, "cost_after": result.cost_after}
    if early_stop is None:
        after = free_run_nrmse(result.system, config.init, *check)
        accepted = after <= before
    else:  # the best model seen; when that is the start, the last one checked says how far refining got
        accepted = bool(result.best_evaluation)
        after = result.score_after
        if not accepted and result.score_last is not None:
            after, report["cost_after"] = result.score_last, result.cost_last
        report["best_evaluation"] = result.best_evaluation
    report.update(nrmse_after=after, accepted=bool(accepted))
    return (result.system if accepted else sys), report


def identify_linear(dataset: Dataset, config: LinearConfig | None = None, *, progress: bool = False,
                    refit_on: Trajectories | None = None, **options) -> LinearModel:
    """Identify a linear state-space baseline from ``dataset``'s training split.

    Parameters
    ----------
    dataset : Dataset
        Its ``train`` split is fitted; its ``valid`` split (or, without one, ``train``) chooses
        the order and guards the refinement.
    config : LinearConfig, optional
        All options; or give them as keywords (``order=12, init="zero-offset"``), not both.
    progress : bool
        Progress bars: the orders tried (with their validation NRMSE), the candidates refined
        shortly (step 3), then the refinement's residual evaluations (with the cost, half the sum
        of squared normalised errors).
    refit_on : Trajectories, optional
        The records of the refit (step 6); default: the ``train`` and ``valid`` splits' records. Give the
        one record a validation tail was cut from (``Dataset.with_validation``), so that the refit sees it
        whole rather than as two pieces.

    Returns
    -------
    LinearModel
        In the dataset's units; ``info`` records the order, singular values and NRMSEs.
    """
    if config is not None and options:
        raise ConfigError("give a LinearConfig or keyword options, not both")
    config = config or LinearConfig.from_dict(options)
    with threadpool_limits(limits=config.threads):
        return _identify(dataset, config, progress, refit_on)


def _refit(data: Trajectories, scaling: _Scaling, order: int, evaluations: int, config: LinearConfig,
           s: int, radius: float) -> StateSpace:
    """Step 6: the subspace model of ``order`` on ``data``, refined for ``evaluations`` without early stopping."""
    us, ys = scaling.apply(data)
    sys = _subspace_model(fit_subspace(us, ys, s, constant=config.init == "estimate"), order, us, ys, radius)[0]
    if evaluations < 1:
        return sys
    result = refine(sys, us, ys, init=config.init, x0=config.refine_x0, max_radius=config.max_spectral_radius,
                    max_evaluations=evaluations, method=config.refine_method)
    return result.system


def _joined(dataset: Dataset) -> Dataset:
    """``dataset`` with its training and validation splits each joined end to end into one record."""
    return dataset.replace(splits={**dataset.splits, "train": dataset.train.concatenated(),
                                   "valid": dataset.valid.concatenated()})


def _identify(dataset: Dataset, config: LinearConfig, progress: bool, refit_on: Trajectories | None) -> LinearModel:
    joined = None
    if config.join and dataset.consecutive_pieces:
        joined = {"train": int(dataset.train.n_traj), "valid": int(dataset.valid.n_traj)}
        dataset = _joined(dataset)
    st = dataset.norm_stats("train")
    scaling = _Scaling(config.init, st.u_mean, st.u_std, st.y_mean, st.y_std)
    s = _horizon(config, dataset.n_y)
    _check_data(dataset.train, s, dataset.n_u, dataset.n_y, config)
    train = scaling.apply(dataset.train)
    check_split = "valid" if dataset.valid is not None else "train"
    check = scaling.apply(dataset.split(check_split))
    fit = fit_subspace(*train, s, constant=config.init == "estimate")
    radius = 0.999 * config.max_spectral_radius
    if config.order is not None:
        choice = OrderChoice(config.order, {})
    else:
        def score(system: StateSpace) -> float:
            return free_run_nrmse(system, config.init, *check)

        def short(system: StateSpace) -> tuple[StateSpace, int]:  # step 3's short refinement of a candidate
            refined, report = _refine(system, config, train, check, score(system), False,
                                      max(1, config.evaluations // 10))
            return refined, report["evaluations"]

        choice = choose_order(fit.singular_values, min(config.max_order, fit.max_order),
                              model=lambda n: _subspace_model(fit, n, *train, radius)[0], score=score,
                              tolerance=config.order_tolerance, count=config.order_candidates,
                              refine=short if config.refine and check_split == "valid" else None,
                              progress=progress)
    order = choice.order
    sys, stabilised = _subspace_model(fit, order, *train, radius)
    before = free_run_nrmse(sys, config.init, *check)
    info = {"method": "N4SID (state sequence), then output-error least squares" if config.refine else "N4SID",
            "order": order, "horizon": s, "singular_values": fit.singular_values.tolist(),
            "order_scores": {str(n): v for n, v in choice.subspace.items()},
            "order_candidates": {str(n): v for n, v in choice.refined.items()}, "stabilised": stabilised,
            "scored_on": check_split, "nrmse_subspace": before, "config": dataclasses.asdict(config),
            "joined": joined,
            "dataset": dict(dataset.source),
            "training_mean": {"u": np.asarray(st.u_mean, dtype=float).tolist(),  # the FMU's start values
                              "y": np.asarray(st.y_mean, dtype=float).tolist()}}
    kept_evaluations = 0  # the refinement evaluations that gave the kept model (what the refit repeats)
    if config.refine and choice.start is None:
        sys, info["refinement"] = _refine(sys, config, train, check, before, progress)
        report = info["refinement"]
        if report["accepted"]:
            kept_evaluations = report.get("best_evaluation") or report["evaluations"]
    elif config.refine:  # the chosen candidate's refinement goes on from its short one (step 3)
        left = max(1, config.evaluations - choice.evaluations)
        sys, report = _refine(choice.start, config, train, check, free_run_nrmse(choice.start, config.init, *check),
                              progress, left)
        after = free_run_nrmse(sys, config.init, *check)
        report.update(evaluations=report["evaluations"] + choice.evaluations, short_evaluations=choice.evaluations,
                      accepted=bool(after < before))
        if after < before:  # kept: its score; discarded: how far refining got, as _refine reports it
            report["nrmse_after"] = after
            kept_evaluations = choice.evaluations + (report.get("best_evaluation") or
                                                     (report["evaluations"] - choice.evaluations))
        else:
            sys = _subspace_model(fit, order, *train, radius)[0]
        info["refinement"] = report
    info["nrmse_valid"] = free_run_nrmse(sys, config.init, *check)
    if config.refit and check_split == "valid":
        data = refit_on if refit_on is not None else Trajectories(dataset.train.u + dataset.valid.u,
                                                                   dataset.train.y + dataset.valid.y)
        refitted = _refit(data, scaling, order, kept_evaluations, config, s, radius)
        if np.isfinite(free_run_nrmse(refitted, config.init, *scaling.apply(data))):
            sys = refitted
            info["refit"] = {"records": int(data.n_traj), "samples": int(np.sum(data.lengths)),
                             "evaluations": int(kept_evaluations), "nrmse_valid_before": info["nrmse_valid"]}
            info["nrmse_valid"] = free_run_nrmse(sys, config.init, *check)  # seen in the refit: not a fair score
    info["spectral_radius"] = sys.spectral_radius
    return LinearModel(scaling.physical(sys), config.init, st.y_std, dataset.Ts,
                       dataset.inputs, dataset.outputs, info, tuple(training_range(dataset.train.u)))
