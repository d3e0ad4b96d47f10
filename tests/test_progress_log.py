"""Progress bars written to a log file or a pipe: a line every few seconds, not one per update (issue 21, cause 6)."""

import io
import re

import numpy as np

import nnfmu.progress as progress


class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _log_lines(text: str) -> list[str]:
    """The lines a log viewer shows: a carriage return starts a new one there."""
    return [line for line in re.split(r"[\r\n]", text) if line.strip()]


def test_a_bar_in_a_log_file_prints_a_line_every_few_seconds_and_its_end(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(progress, "_clock", clock)
    log = io.StringIO()  # not a terminal
    bar = progress.tqdm(total=1000, file=log, unit="evaluation", desc="linear: refine")
    for i in range(1000):  # 1000 evaluations over 80 s, each refreshing the postfix like the refinement's bar
        clock.now += 0.08
        bar.update(1)
        bar.set_postfix(cost=f"{1.0 / (i + 1):.6g}")
    bar.close()
    lines = _log_lines(log.getvalue())
    expected = 80.0 / progress.LOG_INTERVAL_S
    assert expected - 2 <= len(lines) <= expected + 3, lines
    assert "1000/1000" in lines[-1] and "cost=0.001" in lines[-1]


def test_a_short_bar_in_a_log_file_still_shows_its_result(monkeypatch):
    monkeypatch.setattr(progress, "_clock", _Clock())  # no time passes
    log = io.StringIO()
    with progress.tqdm(total=5, file=log, desc="orders") as bar:
        for _ in range(5):
            bar.update(1)
    lines = _log_lines(log.getvalue())
    assert len(lines) <= 2 and "5/5" in lines[-1]


def test_a_quiet_linear_run_says_what_it_does_before_the_long_part(tmp_path, capsys):
    from nnfmu.cli import main
    from nnfmu.data import from_arrays, save_dataset

    rng = np.random.default_rng(0)
    u = rng.normal(size=(3, 200, 1))
    y = np.cumsum(u, axis=1) * 0.05
    save_dataset(from_arrays(Ts=0.1, u_train=u[:2], y_train=y[:2], u_test=u[2:], y_test=y[2:]), tmp_path / "d")
    assert main(["linear", "--data", str(tmp_path / "d"), "--quiet", "--order", "1", "--max-evaluations", "5",
                 "--save", str(tmp_path / "l.json")]) == 0
    out = capsys.readouterr()
    lines = out.out.splitlines()
    assert lines[0].startswith("linear: identifying on") and "up to 5 refinement evaluations" in lines[0]
    assert any(line.startswith("free-run NRMSE on test") for line in lines) and out.err == ""


def test_ipykernel_imported_outside_a_kernel_still_gets_log_lines(monkeypatch):
    """A test suite that runs notebooks imports ipykernel; that alone must not switch a log file to terminal bars."""
    import sys
    import types

    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: None))
    assert not progress._in_notebook()
