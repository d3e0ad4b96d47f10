"""What the user reads around a model: the FMU named after its file, the fit's FMU declaring its valid input range
as the other FMUs do, ``nnfmu evaluate`` in a log without a bar, and a validation warning that only suggests what
applies."""

from __future__ import annotations

import fmpy
import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import Trajectories, from_arrays, save_dataset
from nnfmu.training import TrainConfig
from nnfmu.training.horizons import validation_trajectories
from nnfmu.valid_range import training_range
from tests.slider_cases import slider_dataset


def test_a_fits_fmu_is_named_after_its_file_declares_its_training_range_and_evaluate_warns_beyond_it(tmp_path,
                                                                                                      capsys):
    ds, folder = slider_dataset(2, tmp_path)
    fit, fmu = tmp_path / "fit.json", tmp_path / "axis-frozen.fmu"
    assert main(["fit", "slider", "--data", str(folder), "--quiet", "-o", str(fit)]) == 0
    assert main(["export", str(fit), "-o", str(fmu)]) == 0
    md = fmpy.read_model_description(str(fmu))
    assert md.coSimulation.modelIdentifier == "axis_frozen"  # its file's name, not the data's or the physics'
    (force,) = [v for v in md.modelVariables if v.causality == "input"]
    (lo, hi), = training_range(ds.train.u)
    assert (float(force.min), float(force.max)) == pytest.approx((lo, hi))  # the slider declares no limits of its own
    beyond = ds.replace(splits={**ds.splits, "test": Trajectories((1.5 * ds.test.u[0],), ds.test.y)})
    capsys.readouterr()
    assert main(["evaluate", str(fmu), "--data", str(save_dataset(beyond, tmp_path / "beyond"))]) == 0
    captured = capsys.readouterr()
    assert "inputs outside the valid range of axis-frozen:" in captured.out
    assert "\r" not in captured.err and "it/s" not in captured.err  # no progress bar: stderr is not a terminal


def _ds(n_train: int, length: int, test_length: int, valid: int = 0):
    rng = np.random.default_rng(0)
    u = [rng.normal(size=(length, 1)) for _ in range(n_train + valid)]
    extra = {} if not valid else {"u_valid": u[n_train:], "y_valid": u[n_train:]}
    return from_arrays(Ts=0.1, u_train=u[:n_train], y_train=u[:n_train], u_test=[rng.normal(size=(test_length, 1))],
                       y_test=[rng.normal(size=(test_length, 1))], **extra)


def test_the_short_validation_warning_suggests_what_applies_to_the_data():
    """One training record: its validation is one tail, so joining it changes nothing; the warning asks for a longer
    tail. Several validation records: they may be joined."""
    one = _ds(1, 400, 4000).with_validation(0.1)
    _, notes = validation_trajectories(one, TrainConfig(valid_fraction=0.1))
    (warning,) = [n for n in notes if n.startswith("WARNING")]
    assert "--valid-fraction" in warning and "joined" not in warning
    several = _ds(3, 400, 4000, valid=3)
    _, notes = validation_trajectories(several, TrainConfig())
    (warning,) = [n for n in notes if n.startswith("WARNING")]
    assert "valid_horizon='joined'" in warning
