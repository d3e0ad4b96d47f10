"""Issue 37, item 6: the last messages that named the wrong problem, gave the wrong fix or took many lines; each is
now one line that names the problem and its fix, with exit status 2."""

from __future__ import annotations

import builtins
import errno
import io
import os

import pytest
from fmu_cases import oscillator_dataset

from nnfmu.cli import main as nnfmu_main
from nnfmu.models import ModelConfig, build_model, save_checkpoint

pytestmark = pytest.mark.usefixtures("one_thread")
META = {"name": "osc_gru", "Ts": 0.01, "inputs": [{"name": "force", "unit": "N"}],
        "outputs": [{"name": "pos", "unit": "m"}, {"name": "vel", "unit": "m/s"}]}


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    root = tmp_path_factory.mktemp("last_messages")
    data = oscillator_dataset(root / "data")
    ckpt = save_checkpoint(root / "g.pt", build_model(ModelConfig(arch="gru", n_u=1, n_y=2, hidden=4), META))
    lin = root / "lin.json"
    assert nnfmu_main(["linear", "--data", str(data), "--order", "2", "--no-refine", "--quiet", "--save", str(lin)]) == 0
    csv = root / "d.csv"
    csv.write_text("u,y\n" + "".join(f"{k % 7 - 3},{k % 5}\n" for k in range(60)))
    (root / "d2.csv").write_text(csv.read_text())
    return {"root": root, "data": str(data), "ckpt": str(ckpt), "lin": str(lin), "csv": str(csv),
            "csv2": str(root / "d2.csv")}


def one_line_error(capsys, *words: str) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and ": error: " in err and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    return err


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
