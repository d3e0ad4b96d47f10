"""Issue 37, item 6: the last messages that named the wrong problem, gave the wrong fix or took many lines; each is
now one line that names the problem and its fix, with exit status 2."""

from __future__ import annotations

import builtins
import errno
import io
import os

import pytest
from fmu_cases import oscillator_dataset
from slider_cases import slider_dataset
from test_cli_messages import META
from test_cli_nothing_lost import one_line_error

from nnfmu.cli import main as nnfmu_main
from nnfmu.models import ModelConfig, build_model, save_checkpoint

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    root = tmp_path_factory.mktemp("last_messages")
    data = oscillator_dataset(root / "data")
    ckpt = save_checkpoint(root / "g.pt", build_model(ModelConfig(arch="gru", n_u=1, n_y=2, hidden=4), META))
    lin = root / "lin.json"
    assert nnfmu_main(["linear", "--data", str(data), "--order", "2", "--no-refine", "--quiet",
                       "--save", str(lin)]) == 0
    csv = root / "d.csv"
    csv.write_text("u,y\n" + "".join(f"{k % 7 - 3},{k % 5}\n" for k in range(60)))
    (root / "d2.csv").write_text(csv.read_text())
    return {"root": root, "data": str(data), "ckpt": str(ckpt), "lin": str(lin), "csv": str(csv),
            "csv2": str(root / "d2.csv"), "slider": str(slider_dataset(0, root)[1])}


READS = {  # a command, and the file it reads that the test makes unreadable
    "info checkpoint": (lambda w: ["info", w["ckpt"]], "g.pt"),
    "info dataset": (lambda w: ["info", w["data"]], "meta.json"),
    "export": (lambda w: ["export", w["ckpt"], "-o", str(w["root"] / "x.fmu")], "g.pt"),
    "evaluate": (lambda w: ["evaluate", "--data", w["data"], w["ckpt"]], "meta.json"),
    "fit": (lambda w: ["fit", "slider", "--data", w["data"], "--quiet", "-o", str(w["root"] / "f.json")],
            "meta.json"),
    "import": (lambda w: ["import", "csv", w["csv"], "--inputs", "u", "--outputs", "y", "--Ts", "0.01",
                          "--test", w["csv2"], "-o", str(w["root"] / "imported")], "d.csv"),
    "train --linear-path": (lambda w: ["train", "--data", w["data"], "--arch", "gru", "--hidden", "4", "--epochs",
                                       "1", "--quiet", "--linear-path", w["lin"], "-o", str(w["root"] / "t.pt")],
                            "lin.json"),
}


@pytest.mark.parametrize("command", sorted(READS))
def test_a_file_that_cannot_be_read_is_not_given_a_write_fix(work, capsys, monkeypatch, command):
    argv, name = READS[command]
    real = io.open

    def refusing(file, *args, **kwargs):  # as for a file of mode 000 (root reads those, so a test cannot chmod)
        if isinstance(file, (str, os.PathLike)) and os.fspath(file).endswith(os.sep + name):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(file))
        return real(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", refusing)
    monkeypatch.setattr(io, "open", refusing)
    assert nnfmu_main(argv(work)) == 2
    err = one_line_error(capsys, name, "Permission denied; check the permissions of it and its folders")
    assert "write" not in err


MODEL = '''import casadi as ca
from nnfmu.physics import ModelBuilder


def tank():
    m = ModelBuilder({name!r}, Ts=0.1, n_sub={n_sub})
    h = m.state("h", "m")
    q = m.input("q", "m3/s", min=0, max=1)
    a = m.parameter("a", 1.0)
    m.output("level", "m", "level", h)
    m.ode({ode})
    return m.build()
'''


def model_file(folder, name="tank", n_sub=1, ode="h=q - a * ca.sqrt(h * h + 1)"):
    path = folder / "tank.py"
    path.write_text(MODEL.format(name=name, n_sub=n_sub, ode=ode))
    return f"{path}:tank"


@pytest.mark.parametrize("ode, words", [
    ("h=[q, a]", ["tank: the ODE's derivative of h is 2x1, expected 1x1"]),
    ("h='q'", ["tank: the ODE's derivative of h is a str, not a CasADi expression"]),
    ("ca.vertcat(q, a)", ["tank: the ODE gives 2x1 derivatives for 1 states (h)"]),
])
def test_an_ode_of_the_wrong_size_is_one_line_with_the_sizes(tmp_path, capsys, ode, words):
    assert nnfmu_main(["info", model_file(tmp_path, ode=ode)]) == 2
    err = one_line_error(capsys, *words)
    assert "prototypes" not in err and not err.endswith("; fix the model file")


@pytest.mark.parametrize("name", ["../evil name", "modèle", "tank_", "_tank", "t" * 200])
def test_a_bad_model_name_is_refused_by_the_rule_for_model_names(tmp_path, capsys, name):
    assert nnfmu_main(["info", model_file(tmp_path, name=name)]) == 2
    err = one_line_error(capsys)
    assert "model name" in err and "cannot see" not in err
    assert "single underscores" in err or "nnfmu.limits.MAX_MODEL_NAME" in err


@pytest.mark.parametrize("command", [["info"], ["physics-fmu"], ["generate", "--size", "small"]])
def test_a_model_files_n_sub_has_the_clis_cap(tmp_path, capsys, command):
    """Item 5: n_sub = 10**9 ran physics-fmu past 75 s at 865 MB; now every command refuses it at once."""
    spec = model_file(tmp_path, n_sub=10**9)
    out = [] if command == ["info"] else ["-o", str(tmp_path / "out")]
    assert nnfmu_main([command[0], spec, *command[1:], *out]) == 2
    one_line_error(capsys, "n_sub must be a whole number from 1 to 10,000", "MAX_RK4_SUBSTEPS", "1000000000")
    assert not (tmp_path / "out").exists()


def test_export_refuses_a_name_too_long_for_file_names_before_compiling(work, tmp_path, capsys):
    out = tmp_path / "m.fmu"
    assert nnfmu_main(["export", work["ckpt"], "--name", "a" * 300, "-o", str(out)]) == 2
    one_line_error(capsys, "--name has 300 characters", "MAX_MODEL_NAME")
    assert not out.exists()


def test_demo_into_an_existing_file_names_the_fix(tmp_path, capsys):
    existing = tmp_path / "a.csv"
    existing.write_text("u,y\n")
    assert nnfmu_main(["demo", "--quiet", "-o", str(existing)]) == 2
    one_line_error(capsys, f"{existing} is a file, not a folder; choose another path")
    assert existing.read_text() == "u,y\n"


def test_physics_params_naming_a_folder_names_the_fix(work, tmp_path, capsys):
    argv = ["train", "--data", work["data"], "--arch", "hybrid", "--physics", "slider", "--physics-params",
            str(tmp_path), "--epochs", "1", "--quiet", "-o", str(tmp_path / "h.pt")]
    assert nnfmu_main(argv) == 2
    err = one_line_error(capsys, "it is a folder; give the path of a file")
    assert "[Errno" not in err


def test_a_fit_bound_beyond_what_the_solver_can_square_is_one_line(work, tmp_path, capsys):
    out = tmp_path / "f.json"
    assert nnfmu_main(["fit", "slider", "--data", work["slider"], "--bounds", "m=0:1e308", "--quiet",
                       "-o", str(out)]) == 2
    err = one_line_error(capsys, "the bounds of m", "1e+308", "--bounds m=")
    assert "RuntimeWarning" not in err and not out.exists()


def test_a_fit_is_written_only_to_a_json_name(work, tmp_path, capsys):
    out = tmp_path / "g.pt"
    assert nnfmu_main(["fit", "slider", "--data", work["slider"], "--quiet", "-o", str(out)]) == 2
    one_line_error(capsys, "a fit is written as JSON", "-o g.json")
    assert not out.exists()


def test_a_closed_output_pipe_ends_quietly(work):
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "nnfmu", "info", work["data"]], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before the first line: as `nnfmu info D | head -0`
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 141 and err == b""


def test_linear_on_constant_data_prints_nothing_before_its_error(tmp_path, capsys):
    import numpy as np

    from nnfmu.data import from_arrays, save_dataset

    ones = [np.ones((200, 1))] * 4  # long enough for the default orders: the data, not the horizon, are refused
    data = save_dataset(from_arrays(Ts=0.01, u_train=ones[:3], y_train=ones[:3], u_test=ones[3:],
                                    y_test=ones[3:]), tmp_path / "constant")
    assert nnfmu_main(["linear", "--data", str(data), "--save", str(tmp_path / "l.json")]) == 2
    assert capsys.readouterr().out == ""
    assert not (tmp_path / "l.json").exists()


def test_a_seeds_run_that_kept_one_seed_says_so(work, tmp_path, capsys, monkeypatch):
    from types import SimpleNamespace

    import nnfmu.training
    from nnfmu.training.ensemble import SeedsResult

    rows = [{"seed": s, "best_valid_nrmse": v, "test_nrmse": None, "stop_reason": "epochs"}
            for s, v in ((0, 0.2), (1, 0.3))]
    one = SimpleNamespace(config=SimpleNamespace(members=1))
    monkeypatch.setattr(nnfmu.training, "train_seeds", lambda *a, **k: SeedsResult(
        one, "ensemble", 0.2, None, None, rows, tmp_path / "m.pt",
        ["fewer than two seeds trained: kept seed 0 alone instead of an ensemble"]))
    argv = ["train", "--data", work["data"], "--arch", "gru", "--hidden", "4", "--epochs", "1", "--seeds", "2",
            "--keep", "ensemble", "--linear-path", "off", "--quiet", "-o", str(tmp_path / "m.pt")]
    assert nnfmu_main(argv) == 0
    out = capsys.readouterr().out
    assert "kept seed 0 alone (of 2 seeds): validation free-run NRMSE 0.2000" in out
    assert "kept the ensemble" not in out
