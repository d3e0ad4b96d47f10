"""``--init-window`` through the commands: a fit scored after the window is what its FMU scores in ``evaluate``.

``nnfmu fit --init-window N`` scores every split from the state that the FMU's estimator fits to the first N
samples and keeps N in the fit file; ``nnfmu export FIT.json`` then builds that FMU, and ``nnfmu evaluate
--init-window N`` gives the same NRMSE (1e-9). ``nnfmu physics-fmu --init-window N`` builds a model's FMU with
the window; a bad N, or a window for a network (its own is learned), is one line and status 2.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.cosim import inspect_fmu
from nnfmu.data import save_dataset
from nnfmu.greybox import load_fit
from nnfmu.physics import generate_model_dataset

MODEL = f"{Path(__file__).resolve().parents[1] / 'examples' / 'two_tanks.py'}:two_tanks"
N = 20


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return save_dataset(generate_model_dataset(MODEL, size="small", noise=0.01), tmp_path_factory.mktemp("tanks") / "d")


def test_a_fit_scored_after_the_window_scores_the_same_as_its_fmu(data, tmp_path, capsys):
    fit, fmu, scores = tmp_path / "fit.json", tmp_path / "fit.fmu", tmp_path / "scores.json"
    assert main(["fit", MODEL, "--data", str(data), "-o", str(fit), "--init-window", str(N), "--window", "100",
                 "--max-evaluations", "5", "--quiet"]) == 0
    _, report = load_fit(fit)
    assert report["init_window"] == N and len(report["output_scales"]) == 1
    assert main(["export", str(fit), "-o", str(fmu)]) == 0
    assert inspect_fmu(fmu).init_window == N
    assert main(["evaluate", str(fmu), "--data", str(data), "--split", "valid", "--init-window", str(N),
                 "--json", str(scores)]) == 0
    got = json.loads(scores.read_text())["models"][0]["nrmse"]
    assert got == pytest.approx(report["scores"]["valid"]["nrmse"], rel=1e-9)
    capsys.readouterr()


def test_physics_fmu_takes_an_init_window(tmp_path):
    fmu = tmp_path / "tanks.fmu"
    assert main(["physics-fmu", MODEL, "--init-window", "8", "--no-model-exchange", "-o", str(fmu)]) == 0
    info = inspect_fmu(fmu)
    assert info.init_window == 8 and "h2_past[7]" in info.parameters and "u_past[1]" in info.parameters


def test_a_bad_window_is_one_line_and_status_2(tmp_path, capsys):
    assert main(["physics-fmu", MODEL, "--init-window", "0", "-o", str(tmp_path / "x.fmu")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--init-window must be a whole number >= 1 and <= 100000, got 0" in err
    assert not (tmp_path / "x.fmu").exists()
