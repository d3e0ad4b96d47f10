"""The CLI contract under hostile arguments, read from the argparse definitions (issue 24's permanent guard).

Every numeric option of every command gets the values -1, 0, a huge number, NaN and infinity, on top of
otherwise-valid arguments. A value the option accepts (:data:`ACCEPTED`) must reach the command's work; any
other must be refused first: exit status 2, one line on stderr that names the option, no traceback, nothing
written at ``--out``. The work itself (training, identification, FMU building, simulation, data writing) is
replaced by :class:`WorkStarted`, so no case trains or compiles anything, and a refusal that comes too late
fails the test. A new command needs a base line in :func:`base_argv`; a new numeric option joins by default.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from test_cli_contract import read_only_folder  # noqa: F401  (a fixture)

from nnfmu.cli import build_parser
from nnfmu.cli import main as nnfmu_main

HUGE = {int: "1000000000000", float: "1e308"}
HOSTILE = {int: ["-1", "0", HUGE[int], "nan"], float: ["-1", "0", HUGE[float], "nan", "inf", "-inf"]}
#: Hostile-looking values that an option accepts: (command, option) -> values. Everything else is refused.
ACCEPTED = {
    **{(c, "--seed"): {"0"} for c in ("demo", "generate", "import", "reproduce", "train", "tune")},
    ("train", "--dropout"): {"0"}, ("train", "--weight-decay"): {"0"}, ("train", "--clip"): {"0", HUGE[float]},
    ("train", "--feedback-noise"): {"0"}, ("train", "--patience"): {"0", HUGE[int]},
    ("tune", "--patience"): {"0", HUGE[int]}, ("tune", "--gpus-per-trial"): {"0"},
    ("evaluate", "--trajectory"): {"0"}, ("evaluate", "--horizon"): {HUGE[int]}, ("generate", "--noise"): {"0"},
    ("fit", "--seed"): {"0"}, ("linear", "--valid-fraction"): {"0"},
}
#: Work that a command starts once its arguments are accepted; each is replaced by WorkStarted.
WORK = ["nnfmu.training.train", "nnfmu.training.train_seeds", "nnfmu.linear.identify_linear",
        "nnfmu.export.build_fmu", "nnfmu.cosim.simulate_split", "nnfmu.study.run_demo",
        "nnfmu.study.pipeline.Study.check_manifest",  # reproduce: after its own input checks, before any cell
        "nnfmu.study.tune_architecture", "nnfmu.physics.generate_dataset", "nnfmu.data.save_dataset",
        "nnfmu.greybox.fit_greybox"]


class WorkStarted(BaseException):
    """Raised where a command would start its real work: its arguments were accepted."""


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _numeric_cases() -> list[tuple[str, str, str]]:
    cases = []
    for command, parser in sorted(_commands().items()):
        for action in parser._actions:
            if action.type in HOSTILE and action.option_strings and not action.choices:
                flag = max(action.option_strings, key=len)
                cases += [(command, flag, value) for value in HOSTILE[action.type]]
    return cases


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A tiny dataset, a checkpoint, an FMU-looking file and a CSV: inputs every base line can accept."""
    from nnfmu.data import Channel, from_arrays, save_dataset
    from nnfmu.models import ModelConfig, build_model, save_checkpoint

    root = tmp_path_factory.mktemp("hostile")
    rng = np.random.default_rng(0)
    us = [rng.normal(size=(40, 1)) for _ in range(4)]
    ys = [np.cumsum(u, axis=0) for u in us]
    ds = from_arrays(Ts=0.01, u_train=us[:3], y_train=ys[:3], u_test=us[3:], y_test=ys[3:],
                     input_names=[Channel("u", "N")], output_names=[Channel("y", "m")])
    data = save_dataset(ds, root / "data")
    net = build_model(ModelConfig(arch="gru", n_u=1, n_y=1, hidden=4),
                      {"name": "g", "Ts": 0.01, "inputs": [{"name": "u", "unit": "N"}],
                       "outputs": [{"name": "y", "unit": "m"}]})
    ckpt = save_checkpoint(root / "g.pt", net)
    csv = root / "d.csv"
    csv.write_text("u,y\n" + "".join(f"{a:.4f},{b:.4f}\n" for a, b in zip(us[0][:, 0], ys[0][:, 0])))
    csv2 = root / "d2.csv"
    csv2.write_text(csv.read_text())
    fmu = root / "m.fmu"
    assert nnfmu_main(["linear", "--data", str(data), "--order", "1", "--no-refine", "--quiet", "-o", str(fmu)]) == 0
    (root / "empty").write_bytes(b"")
    (root / "afile").write_text("a regular file where a folder should be")
    return {"data": str(data), "ckpt": str(ckpt), "csv": str(csv), "csv2": str(csv2), "fmu": str(fmu),
            "empty": root / "empty", "afile": root / "afile"}


def base_argv(command: str, w: dict, out: Path) -> list[str]:
    """Valid arguments of ``command`` that reach its work, writing under ``out``."""
    d = w["data"]
    return {
        "demo": ["demo", "--quiet", "-o", str(out / "demo")],
        "evaluate": ["evaluate", "--data", d, w["fmu"], "-o", str(out / "scores")],
        "export": ["export", w["ckpt"], "-o", str(out / "m.fmu")],
        "fit": ["fit", "slider", "--data", d, "--quiet", "-o", str(out / "fit.json")],
        "generate": ["generate", "valve", "--size", "small", "--quiet", "-o", str(out / "gen")],
        "import": ["import", "csv", w["csv"], "--inputs", "u", "--outputs", "y", "--Ts", "0.01",
                   "--test", w["csv2"], "-o", str(out / "imported")],
        "info": ["info", d],
        "linear": ["linear", "--data", d, "--save", str(out / "l.json")],
        "physics-fmu": ["physics-fmu", "valve", "-o", str(out / "p.fmu")],
        "reproduce": ["reproduce", "valve", "--budget", "smoke", "--quiet", "-o", str(out / "study")],
        "train": ["train", "--data", d, "--arch", "gru", "--hidden", "4", "--epochs", "1", "--quiet",
                  "-o", str(out / "m.pt")],
        "tune": ["tune", "--data", d, "--arch", "gru", "--system", "valve", "-o", str(out / "best.json")],
    }[command]


def run_cli(argv: list[str], capsys) -> tuple[int | str, str]:
    """(exit status, or "work" if the work started; stderr). argparse's own errors exit through SystemExit."""
    patches = [mock.patch(target, side_effect=WorkStarted(target)) for target in WORK]
    for p in patches:
        p.start()
    try:
        status = nnfmu_main(argv)
    except WorkStarted:
        status = "work"
    except SystemExit as exc:
        status = exc.code
    finally:
        for p in patches:
            p.stop()
    return status, capsys.readouterr().err


def assert_refused(status, err: str, *names: str) -> None:
    """Status 2 and one line on stderr (after any progress bar) that names one of ``names``."""
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    assert status == 2, (status, err)
    assert "Traceback" not in err and "Warning" not in err, err
    assert len(lines) == 1 and ": error: " in lines[0], err
    assert any(n in lines[0] for n in names), (names, lines[0])


def test_every_command_has_a_base_line(work, tmp_path):
    for command in _commands():
        assert base_argv(command, work, tmp_path)[0] == command


@pytest.mark.parametrize("command, flag, value", _numeric_cases())
def test_a_hostile_number_is_refused_before_any_work(work, tmp_path, capsys, command, flag, value):
    out = tmp_path / "out"
    status, err = run_cli(base_argv(command, work, out) + [flag, value], capsys)
    if value in ACCEPTED.get((command, flag), ()):
        assert status == "work", (status, err)
    else:
        assert_refused(status, err, flag)
    assert not out.exists(), sorted(out.rglob("*"))


def test_the_accepted_table_names_real_options():
    numeric = {(c, f) for c, f, _ in _numeric_cases()}
    assert set(ACCEPTED) <= numeric, set(ACCEPTED) - numeric


def test_each_base_line_reaches_the_work(work, tmp_path, capsys):
    """Without this, a base line that fails by itself would make every hostile case pass vacuously."""
    for command in _commands():
        if command == "info":
            continue  # nothing to replace: it only reads
        status, err = run_cli(base_argv(command, work, tmp_path / command), capsys)
        assert status == "work", (command, status, err)



#: What each path-like option of a command is: read (an input) or written (an output). Every option that takes a
#: string and has no fixed choices must be listed here or in TEXT, so that a new one joins the cases below.
INPUTS = {"data": "data", "checkpoint": "ckpt", "fmus": "fmu", "path": "data", "files": "csv", "test": "csv2",
          "valid": "csv2", "physics_params": None, "linear_path": None}
OUTPUTS = {"out", "json", "plots", "save", "storage"}
TEXT = {"target_isa", "platforms", "name", "address", "device", "grid", "size", "inputs", "outputs", "units", "time",
        "Ts_column", "fs_column", "test_columns", "valid_columns", "train_physics", "data_dir", "increment",
        "system"}  # system: a physics spec (a built-in name, file.py:NAME or a .json; tests/test_user_physics_cli.py)
TEXT |= {"free", "fixed", "bounds", "start"}  # fit: parameter names and NAME=VALUE lists
#: Commands whose outputs are checked when written, not before the work starts (their writers keep the contract
#: at write time; tests/test_cli_contract.py writes through them for real).
LATE_OUTPUT_CHECK = {"generate", "import"}


def _path_actions() -> list[tuple[str, argparse.Action]]:
    return [(command, a) for command, parser in sorted(_commands().items()) for a in parser._actions
            if a.type in (None, str) and a.nargs != 0 and not a.choices and a.dest not in ("help", "command")
            and not isinstance(a, (argparse._StoreTrueAction, argparse._StoreConstAction))]


def test_every_path_like_option_is_classified():
    unknown = {(c, a.dest) for c, a in _path_actions() if a.dest not in INPUTS and a.dest not in OUTPUTS | TEXT}
    assert not unknown, f"classify these options in tests/test_cli_hostile.py: {sorted(unknown)}"


def _with(argv: list[str], action: argparse.Action, old: str | None, new: str) -> list[str]:
    """``argv`` with the value ``old`` of ``action`` replaced by ``new``, or ``flag new`` appended."""
    if old is not None and old in argv:
        return [new if a == old else a for a in argv]
    flag = max(action.option_strings, key=len) if action.option_strings else None
    return argv + ([flag, new] if flag else [new])


def _input_cases():
    for command, action in _path_actions():
        if action.dest in INPUTS:
            for kind in ("empty", "missing"):
                yield pytest.param(command, action.dest, kind, id=f"{command}-{action.dest}-{kind}")


@pytest.mark.parametrize("command, dest, kind", list(_input_cases()))
def test_an_empty_or_missing_input_is_refused_before_any_work(work, tmp_path, capsys, command, dest, kind):
    action = next(a for c, a in _path_actions() if c == command and a.dest == dest)
    hostile = str(work["empty"]) if kind == "empty" else str(tmp_path / "nothing-here")
    old = work[INPUTS[dest]] if INPUTS[dest] else None
    out = tmp_path / "out"
    status, err = run_cli(_with(base_argv(command, work, out), action, old, hostile), capsys)
    flags = [f for f in action.option_strings] or [dest]
    assert_refused(status, err, hostile, *flags)
    assert not out.exists()


def _output_cases():
    for command, action in _path_actions():
        if action.dest in OUTPUTS and command not in LATE_OUTPUT_CHECK:
            for kind in ("through-a-file", "read-only"):
                yield pytest.param(command, action.dest, kind, id=f"{command}-{action.dest}-{kind}")


@pytest.mark.parametrize("command, dest, kind", list(_output_cases()))
def test_an_unwritable_output_is_refused_before_any_work(work, tmp_path, capsys, read_only_folder, command, dest,
                                                           kind):
    action = next(a for c, a in _path_actions() if c == command and a.dest == dest)
    folder = work["afile"] if kind == "through-a-file" else read_only_folder
    hostile = str(folder / "target")
    argv = base_argv(command, work, tmp_path / "out")
    old = next((argv[i + 1] for i, a in enumerate(argv[:-1]) if a in action.option_strings), None)
    status, err = run_cli(_with(argv, action, old, hostile), capsys)
    assert_refused(status, err, str(folder))
    assert not (folder / "target").exists() and not (tmp_path / "out").exists()
    assert work["afile"].read_text().startswith("a regular file")
