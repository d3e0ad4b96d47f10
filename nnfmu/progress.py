"""Progress bars: tqdm's notebook widget where it can be drawn, and the training bar (epochs or time budget).

``tqdm.auto`` picks the widget bar inside Jupyter, but without ``ipywidgets``
it warns "IProgress not found" and draws nothing useful; :func:`tqdm` then
takes the text bar instead, which prints fine in a notebook too. Written to a log
file or a pipe, the text bar prints a line every few seconds (:data:`LOG_INTERVAL_S`),
not one per update.
"""

from __future__ import annotations

import importlib.util
import sys
import time

from nnfmu.limits import UNBOUNDED_EPOCHS


#: On a stream that is not a terminal (a log file, a pipe), a bar prints at most one line per this many seconds.
LOG_INTERVAL_S = 5.0
_clock = time.monotonic  # replaced in tests


class _LogLines:
    """A text stream for a bar that is not drawn on a terminal: whole lines, at most one per ``interval`` s.

    tqdm redraws a bar by writing ``\\r`` and the new text, and on a terminal the line is
    overwritten; in a log file each redraw stays, and a bar that refreshes on every
    ``set_postfix`` leaves one line per update. Here a redraw is held back until ``interval`` s
    have passed since the last line, and the bar's last state is written when it closes.
    """

    def __init__(self, stream, interval: float):
        self.stream, self.interval, self.last, self.pending = stream, interval, None, None

    def write(self, text: str) -> None:
        for piece in text.split("\r"):
            line = piece.rstrip()
            if line:
                self.pending = line
                now = _clock()
                if self.last is None or now - self.last >= self.interval:
                    self._emit(now)
            if piece.endswith("\n"):  # the bar closes: its last state is its result
                self._emit(_clock())

    def _emit(self, now: float) -> None:
        if self.pending is not None:
            self.stream.write(self.pending + "\n")
            self.stream.flush()
            self.pending, self.last = None, now

    def flush(self) -> None:
        self.stream.flush()


def _in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (its output area overwrites a line on a carriage return, like a
    terminal). ipykernel merely imported (a test suite that runs notebooks does) is not enough."""
    ipython = sys.modules.get("IPython")
    if "ipykernel" not in sys.modules or ipython is None:
        return False
    try:
        shell = ipython.get_ipython()
    except Exception:  # noqa: BLE001 - an IPython without get_ipython: not a kernel we know
        return False
    return type(shell).__name__ == "ZMQInteractiveShell"


def tqdm(*args, **kwargs):
    """A tqdm bar: the notebook widget if ipywidgets is installed (tqdm.auto), else the text bar.

    On a stream that is not a terminal, outside a notebook, the text bar prints a line at most
    every :data:`LOG_INTERVAL_S` seconds, and its final state when it closes.
    """
    if importlib.util.find_spec("ipywidgets") is not None and _in_notebook():
        from tqdm.auto import tqdm as bar

        return bar(*args, **kwargs)
    from tqdm import tqdm as bar

    stream = kwargs.get("file") or sys.stderr
    drawn = kwargs.get("disable", False) is False  # disable=None: tqdm's own "off where not a terminal"
    if drawn and not _in_notebook() and not getattr(stream, "isatty", lambda: False)():
        kwargs.update(file=_LogLines(stream, LOG_INTERVAL_S), dynamic_ncols=False,  # no width to fit: no cut
                      mininterval=max(kwargs.get("mininterval", 0.1), LOG_INTERVAL_S))
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
