"""Identifiability, reported (issue 34, item 2): a fit names the parameters its data cannot tell apart, says how to
fix them with its own options, and still exits 0; a well-posed fit says nothing of the kind.

The redundant case is the issue's: the two tanks of docs/own-physics.md with the upper tank unmeasured, whose
cross-section ``A1`` is freed beside its outlet ``a1`` (a larger upper tank with a wider outlet looks the same
from the lower tank). The well-posed case is the same model with ``A1`` held (and the slider of
tests/test_greybox_fit.py).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import save_dataset
from nnfmu.greybox.identifiability import RELATIVE_LIMIT, covariance, describe, identifiability_report
from nnfmu.physics import generate_model_dataset, resolve_physics

ROOT = Path(__file__).resolve().parents[1]
START = "a1=8e-5,a2=4e-5,k_p=1e-5"


@pytest.fixture(scope="module")
def tanks(tmp_path_factory):
    """The tanks' model file and a small noisy dataset from it: 6 training records of 400 s, one validation."""
    work = tmp_path_factory.mktemp("ident")
    model = work / "two_tanks.py"
    shutil.copy(ROOT / "examples" / "two_tanks.py", model)
    ds = generate_model_dataset(resolve_physics(f"{model}:two_tanks"), size="small", noise=0.01, seed=4)
    ds = ds.replace(splits={"train": ds.train.subset(range(6)), "valid": ds.valid.subset([0]),
                            "test": ds.test.subset([0])})
    return f"{model}:two_tanks", save_dataset(ds, work / "data"), work


def _fit(tanks, free: str, capsys, *extra) -> tuple[str, dict]:
    spec, data, work = tanks
    out = work / f"fit_{free.replace(',', '_')}.json"
    assert main(["fit", spec, "--data", str(data), "--free", free, "--start", START, "--quiet", "-o", str(out),
                 *extra]) == 0
    return capsys.readouterr().out, json.loads(out.read_text())["fit"]


def test_redundant_parameters_are_flagged_by_name_with_the_fix_and_the_fit_exits_0(tanks, capsys):
    printed, report = _fit(tanks, "A1,a1,a2,k_p", capsys)
    flags = [line for line in printed.splitlines() if line.startswith("identifiability:")]
    assert len(flags) == 1, printed
    assert "A1 and a1 cannot be told apart" in flags[0] or "a1 and A1 cannot be told apart" in flags[0]
    assert "--fixed " in flags[0] and "--start " in flags[0]  # the fit's own options, with the value to hold
    assert "a2" not in flags[0].replace("a1 and", "") and "k_p" not in flags[0]
    section = report["identifiability"]
    assert [sorted(f["parameters"]) for f in section["flags"]] == [["A1", "a1"]]
    assert describe(section)[-1] == flags[0]  # a script reads the same lines back from the file
    assert section["limits"]["relative_std_error"] == RELATIVE_LIMIT
    weakest = section["weak_directions"][0]
    assert set(n for n, c in weakest["components"].items() if abs(c) > 0.3) == {"A1", "a1"}
    assert weakest["relative_std_error"] is None or weakest["relative_std_error"] > RELATIVE_LIMIT  # None: Inf
    assert report["converged"] and "converged" in report["stopped"]  # the default runs until it converges
    assert "solver: converged" in printed


def test_the_well_posed_fit_prints_no_flag_and_no_test_score_unless_asked(tanks, capsys):
    printed, report = _fit(tanks, "a1,a2,k_p", capsys)
    assert "identifiability:" not in printed and report["identifiability"]["flags"] == []
    assert "correlation" in printed and "weakest direction" in printed
    assert "valid: NRMSE" in printed and "test:" not in printed and set(report["scores"]) == {"train", "valid"}
    assert all(p["std_error"] < 0.05 * p["value"] for p in report["parameters"].values())
    printed, report = _fit(tanks, "a1,a2,k_p", capsys, "--report-test")
    assert "test: NRMSE" in printed and set(report["scores"]) == {"train", "valid", "test"}


def test_a_limit_the_user_set_is_reported_as_theirs(tanks, capsys):
    printed, report = _fit(tanks, "a1,a2,k_p", capsys, "--max-evaluations", "3")
    assert not report["converged"]
    assert "solver: stopped at the limit of 3 evaluations that --max-evaluations set" in printed


def test_an_exactly_redundant_pair_has_infinite_standard_errors_and_is_named():
    # residuals depend on a + b only (scaled unknowns), c on its own: F = [[1,1,0],[1,1,0],[0,0,4]]
    information = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 4.0]])
    cov, null = covariance(information, 0.01)
    assert null.tolist() == [True, True, False]
    assert cov[2, 2] == pytest.approx(0.01 / 4)
    section = identifiability_report(["a", "b", "c"], np.array([2.0, 3.0, 1.0]), np.ones(3), information, 0.01)
    assert section["relative_std_error"]["a"] == np.inf and section["relative_std_error"]["c"] == pytest.approx(0.05)
    assert section["correlation"][0][1] == pytest.approx(-1.0)  # only a + b is seen: a up, b down
    assert [f["parameters"] for f in section["flags"]] == [["a", "b"]] or \
           [f["parameters"] for f in section["flags"]] == [["b", "a"]]
    assert "+-inf" in section["flags"][0]["message"]
    lines = describe(section)
    assert lines[-1].startswith("identifiability: ") and "cannot be told apart" in lines[-1]


def test_one_uninformed_parameter_is_told_to_be_fixed_or_excited():
    information = np.diag([100.0, 1e-4])  # scaled unknowns; sigma 0.1: a to 1 %, b to 1000 %
    section = identifiability_report(["a", "b"], np.array([1.0, 1.0]), np.ones(2), information, 0.01)
    (flag,) = section["flags"]
    assert flag["parameters"] == ["b"] and flag["kind"] == "undetermined"
    assert "--fixed b --start b=1" in flag["message"] and "excite" in flag["message"]


def test_many_parameters_print_only_the_strong_pairs():
    rng = np.random.default_rng(0)
    J = rng.standard_normal((200, 8))
    J[:, 7] = J[:, 6] + 0.05 * rng.standard_normal(200)  # p6 and p7 nearly collinear: their estimates anti-correlate
    names = [f"p{i}" for i in range(8)]
    section = identifiability_report(names, np.ones(8), np.ones(8), J.T @ J, 1e-4)
    lines = describe(section)
    assert lines[0].startswith("strongest correlations: p7~p6 -0.99") and "p1~" not in lines[0]
    assert not any(line.startswith("correlation ") for line in lines)


def test_each_pair_that_the_data_cannot_separate_is_one_flag():
    """The robot's case: each joint's viscous and Coulomb friction nearly collinear, a well-determined third."""
    rng = np.random.default_rng(1)
    base = rng.standard_normal((400, 3))
    J = np.column_stack([base[:, 0], base[:, 0] + 0.01 * rng.standard_normal(400),
                         base[:, 1], base[:, 1] + 0.01 * rng.standard_normal(400), base[:, 2]])
    names = ["f_vis1", "f_coul1", "f_vis2", "f_coul2", "m"]
    section = identifiability_report(names, np.ones(5), np.ones(5), J.T @ J, 0.01)  # sigma 0.1: 5 % alone
    assert sorted(sorted(f["parameters"]) for f in section["flags"]) == [["f_coul1", "f_vis1"], ["f_coul2", "f_vis2"]]
    assert all(f["kind"] == "collinear" and "cannot be told apart" in f["message"] for f in section["flags"])
    assert section["relative_std_error"]["m"] < RELATIVE_LIMIT


def test_the_help_states_the_default_guard_that_the_solver_uses(capsys):
    from nnfmu.greybox.solvers import DEFAULT_MAX_EVALUATIONS

    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"until converged, at most {DEFAULT_MAX_EVALUATIONS}" in text and "--report-test" in text
