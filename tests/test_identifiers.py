"""Names that reach C are checked one way (nnfmu.identifiers): ASCII ``[A-Za-z_][A-Za-z0-9_]*``."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import nnfmu
from nnfmu.data import load_csv
from nnfmu.data.dataset import Channel
from nnfmu.errors import DataError, ShapeError
from nnfmu.identifiers import is_c_identifier, to_c_identifier
from nnfmu.system import SystemSpec, Variable

NON_ASCII = ("Düse", "Ωm", "名前", "ｘ")  # all four pass str.isidentifier


@pytest.mark.parametrize("name, ok", [("valve", True), ("_x1", True), ("A_2b", True), ("2x", False), ("", False),
                                      ("a-b", False), ("a b", False), (None, False), *[(n, False) for n in NON_ASCII]])
def test_is_c_identifier(name, ok):
    assert is_c_identifier(name) is ok


@pytest.mark.parametrize("text, prefix, expected", [("valve", "m_", "valve"), ("Düse 2", "m_", "D_se_2"),
                                                    ("2 tanks", "d_", "d_2_tanks"), ("-x-", "m_", "x"),
                                                    ("名前", "c_", "c_")])
def test_to_c_identifier_makes_one(text, prefix, expected):
    assert to_c_identifier(text, prefix) == expected and is_c_identifier(expected)


@pytest.mark.parametrize("name", NON_ASCII)
def test_every_check_refuses_a_non_ascii_name(name):
    assert name.isidentifier()
    with pytest.raises(ShapeError, match="not a C identifier"):
        Variable(name)
    with pytest.raises(ShapeError, match="not a C identifier"):
        SystemSpec(name, 1.0, ["u"], ["y"])
    with pytest.raises(DataError, match="not an identifier"):
        Channel(name)


def test_the_cli_refuses_a_non_ascii_name(tmp_path):
    run = subprocess.run([sys.executable, "-m", "nnfmu", "linear", "--data", str(tmp_path), "--name", "Düse",
                          "-o", str(tmp_path / "m.fmu")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "--name must be a C identifier" in run.stderr and not list(tmp_path.iterdir())


def test_imported_columns_with_non_ascii_names_become_ascii_channels(tmp_path):
    rng = np.random.default_rng(0)
    files = {}
    for split in ("train", "test"):
        rows = "\n".join(",".join(f"{v:.6f}" for v in r) for r in rng.standard_normal((40, 3)))
        files[split] = tmp_path / f"düse_{split}.csv"
        files[split].write_text("Druck_ü,Hub²,y\n" + rows + "\n", encoding="utf-8")
    ds = load_csv(files, inputs=[0, 1], outputs=[2], Ts=0.1)
    assert ds.input_names == ["Druck", "Hub"] and all(map(is_c_identifier, [*ds.input_names, ds.source["name"]]))


def test_nothing_else_checks_identifiers_with_str_isidentifier():
    root = Path(nnfmu.__file__).parent
    calls = [f"{p.relative_to(root)}:{n.lineno}" for p in root.rglob("*.py")
             for n in ast.walk(ast.parse(p.read_text(encoding="utf-8")))
             if isinstance(n, ast.Attribute) and n.attr == "isidentifier"]
    assert calls == []
