"""Progress bars: tqdm's notebook widget where it can be drawn, and the training bar (epochs or time budget).

``tqdm.auto`` picks the widget bar inside Jupyter, but without ``ipywidgets``
it warns "IProgress not found" and draws nothing useful; :func:`tqdm` then
takes the text bar instead, which prints fine in a notebook too.
"""

from __future__ import annotations

import importlib.util
import time

from nnfmu.limits import UNBOUNDED_EPOCHS


def tqdm(*args, **kwargs):
    """A tqdm bar: the notebook widget if ipywidgets is installed (tqdm.auto), else the text bar."""
    if importlib.util.find_spec("ipywidgets") is not None:
        from tqdm.auto import tqdm as bar
    else:
        from tqdm import tqdm as bar
    return bar(*args, **kwargs)


def training_bar(epoch: int, epochs: int, max_minutes: float | None, *, desc: str, progress: bool):
    """The bar of one training call, over what bounds it.

    When the budget ``max_minutes`` alone ends the training (``epochs`` is
    :data:`nnfmu.limits.UNBOUNDED_EPOCHS`), the bar counts seconds, shows the time used of the
    budget, and :func:`advance` keeps the epoch count in its description. Otherwise it counts
    epochs; a ``max_minutes`` safety net is named in the description.
    """
    from tqdm import tqdm as text_bar

    if max_minutes is None or epochs < UNBOUNDED_EPOCHS:
        limit = "" if max_minutes is None else f" (time limit {text_bar.format_interval(round(60.0 * max_minutes))})"
        return tqdm(total=epochs, initial=min(epoch, epochs), disable=not progress, unit="epoch", desc=desc + limit,
                    dynamic_ncols=True)
    total = round(60.0 * max_minutes)
    bar = tqdm(total=total, disable=not progress, unit="s", desc=f"{desc} epoch {epoch}", dynamic_ncols=True,
               smoothing=0, bar_format="{desc} |{bar}| {elapsed} of " + text_bar.format_interval(total)
               + " budget{postfix}")
    bar.budget_desc, bar.budget_start = desc, time.monotonic()
    return bar


def advance(bar, epoch: int) -> None:
    """After an epoch: one step of an epoch bar, or the seconds used of a budget bar."""
    if not hasattr(bar, "budget_start"):
        bar.update(1)
        return
    used = min(bar.total, time.monotonic() - bar.budget_start)
    bar.set_description_str(f"{bar.budget_desc} epoch {epoch}", refresh=False)
    bar.update(used - bar.n)
