"""Figures in the style of the paper's Figs. 2 and 3: inputs on top, predicted vs measured outputs below.

Measured outputs are dashed black lines; each model is a coloured line
labelled with its NRMSE on that trajectory. The output axes are scaled to the
measurement (with a margin), so that one model drifting far away does not
flatten the others; its line leaves the axes and its legend entry says so.
The legend sits below the axes, in as many columns as fit the figure's width
(long names wrap), and the figure grows to hold it, so that ten models with
long names stay readable.
"""

from __future__ import annotations

import os
import textwrap
from pathlib import Path
from typing import Sequence

import numpy as np

from nnfmu.atomic import write_atomic
from nnfmu.data import Dataset


def representative_index(evaluations: Sequence) -> int:
    """The trajectory whose mean NRMSE over all models is the median one (the 'typical' case)."""
    scores = np.mean([ev.result.per_trajectory for ev in evaluations], axis=0)
    return int(np.argsort(scores)[len(scores) // 2])


def _measured_limits(y: np.ndarray, margin: float = 0.5) -> tuple[float, float]:
    """Axis limits: the measured range widened by ``margin`` times its width on each side."""
    lo, hi = float(np.min(y)), float(np.max(y))
    pad = margin * (hi - lo) if hi > lo else max(abs(lo), 1.0) * 0.1
    return lo - pad, hi + pad


def _axis_label(channel) -> str:
    return f"{channel.name} [{channel.unit}]" if channel.unit else channel.name


def _time_axis(n: int, Ts: float) -> tuple[np.ndarray, str]:
    t = np.arange(n) * Ts
    if t[-1] < 1.0:
        return t * 1e3, "time [ms]"
    return t, "time [s]"


def plot_trajectory(dataset: Dataset, evaluations: Sequence, path: str | os.PathLike, *,
                    split: str = "test", index: int | None = None, max_inputs: int = 4) -> Path:
    """Write a PNG comparing every evaluated model with the measurement on one trajectory.

    Parameters
    ----------
    dataset : the scored dataset; evaluations : :class:`nnfmu.cosim.Evaluation` list on ``split``.
    index : trajectory to show; default :func:`representative_index`.
    max_inputs : inputs are drawn on top only if there are at most this many (the robot's six
        torques are left out, as in the paper's Fig. 3).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    idx = representative_index(evaluations) if index is None else index
    tr = dataset.split(split)
    u, y = tr.u[idx], tr.y[idx]
    t, t_label = _time_axis(len(u), dataset.Ts)
    show_u = dataset.n_u <= max_inputs
    n_rows = (dataset.n_u if show_u else 0) + dataset.n_y
    fig, axes = plt.subplots(n_rows, 1, sharex=True, figsize=(8, 1.6 * n_rows + 0.8), squeeze=False,
                             layout="constrained")
    axes = axes[:, 0]
    row = 0
    if show_u:
        for j, ch in enumerate(dataset.inputs):
            axes[row].plot(t, u[:, j], color="tab:gray", lw=1.0)
            axes[row].set_ylabel(_axis_label(ch))
            row += 1
    limits = [_measured_limits(y[:, j]) for j in range(dataset.n_y)]
    leaves = [any(np.any((ev.predictions[idx][:, j] < lo) | (ev.predictions[idx][:, j] > hi))
                  for j, (lo, hi) in enumerate(limits)) for ev in evaluations]
    for j, ch in enumerate(dataset.outputs):
        ax = axes[row + j]
        ax.plot(t, y[:, j], "k--", lw=1.2, label="measured" if j == 0 else None)
        for ev, off_axes in zip(evaluations, leaves):
            note = ", leaves the axes" if off_axes else ""
            label = f"{ev.name} ({ev.result.per_trajectory[idx]:.3f}{note})" if j == 0 else None
            ax.plot(t, ev.predictions[idx][:, j], lw=1.0, label=label)
        ax.set_ylim(*limits[j])
        ax.set_ylabel(_axis_label(ch))
    axes[-1].set_xlabel(t_label)
    fig.suptitle(f"{split} trajectory {idx}: predicted vs measured (NRMSE in brackets)", fontsize="medium")
    _legend_below(fig, axes[row])
    try:
        return write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=120, format="png"), suffix=".png")
    finally:
        plt.close(fig)


def _legend_below(fig, ax, wrap: int = 60) -> None:
    """The legend of ``ax``'s lines below the axes, in the most columns that fit the figure's width.

    Labels longer than ``wrap`` characters wrap onto more lines. The figure grows by the
    legend's height, so the axes keep their size.
    """
    handles, labels = ax.get_legend_handles_labels()
    labels = [textwrap.fill(text, wrap) for text in labels]
    renderer = fig.canvas.get_renderer()
    for ncol in range(min(len(labels), 4), 0, -1):
        legend = fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize="small", frameon=False)
        if ncol == 1 or legend.get_window_extent(renderer).width <= 0.98 * fig.bbox.width:
            break
        legend.remove()
    height = legend.get_window_extent(renderer).height / fig.dpi
    fig.set_figheight(fig.get_figheight() + height)
