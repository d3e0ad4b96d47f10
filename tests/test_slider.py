"""The slider (an integrating plant) and its generated datasets."""

from __future__ import annotations

import numpy as np
import pytest

from nnfmu.cli import main
from nnfmu.data import load_dataset
from nnfmu.errors import ConfigError
from nnfmu.physics import generate_dataset, slider_system
from nnfmu.physics.generate_slider import SLIDER_SIZES
from nnfmu.physics.slider import SLIDER_F_MAX

EPOCHS = 15  # the parallel GRU of the last test: enough to beat the linear baseline, a few seconds


@pytest.fixture(scope="module")
def slider_small_dir(tmp_path_factory):
    """``nnfmu generate slider --size small`` written by the CLI; returns the folder."""
    out = tmp_path_factory.mktemp("gen") / "slider_small"
    assert main(["generate", "slider", "--size", "small", "--out", str(out), "--quiet"]) == 0
    return out


def test_slider_dataset_has_the_promised_shape_names_and_units(slider_small_dir):
    ds = load_dataset(slider_small_dir)
    assert ds.Ts == 0.01
    assert [(c.name, c.unit) for c in ds.inputs] == [("F", "N")]
    assert [(c.name, c.unit) for c in ds.outputs] == [("pos", "m")]
    assert (ds.train.n_traj, set(ds.train.lengths)) == (16, {400})
    assert (ds.valid.n_traj, ds.test.n_traj, set(ds.test.lengths)) == (2, 2, {1600})
    assert max(np.abs(u).max() for u in ds.train.u) <= SLIDER_F_MAX


def test_every_record_starts_at_rest_at_its_own_position(slider_small_dir):
    """The physics model started from y0 at rest (what init(y0, u0) assumes) reproduces every record exactly."""
    ds = load_dataset(slider_small_dir)
    model = slider_system().model()
    for split in (ds.train, ds.valid, ds.test):
        for u, y in zip(split.u, split.y):
            np.testing.assert_allclose(model.simulate(u, y[0]), y, rtol=0, atol=1e-9)
    starts = np.array([y[0, 0] for y in ds.train.y])
    low, high = SLIDER_SIZES["small"].start_range
    assert starts.min() >= low and starts.max() <= high
    assert starts.std() > 0.2 * (high - low) / np.sqrt(12)  # spread over the range, not one position


def test_slider_generation_is_reproducible_and_seeded():
    a, b = generate_dataset("slider", size="small", seed=3), generate_dataset("slider", size="small", seed=3)
    c = generate_dataset("slider", size="small", seed=4)
    np.testing.assert_array_equal(np.concatenate(a.test.y), np.concatenate(b.test.y))
    assert not np.allclose(np.concatenate(a.test.y), np.concatenate(c.test.y))


def test_unknown_slider_size_names_the_valid_ones():
    with pytest.raises(ConfigError, match="standard, small"):
        generate_dataset("slider", size="huge")


@pytest.mark.usefixtures("one_thread")
def test_a_parallel_network_beats_the_linear_baseline_on_the_slider(slider_small_dir):
    """The integrating plant: a parallel GRU in increment mode (the slider preset, a short budget) simulates the
    test records better than the linear state-space baseline identified on the same data."""
    from nnfmu.linear import identify_linear
    from nnfmu.metrics import nrmse
    from nnfmu.models import ModelConfig
    from nnfmu.training import TrainConfig, train

    ds = load_dataset(slider_small_dir)
    result = train(ds, ModelConfig(arch="gru", n_u=1, n_y=1, hidden=32, increment=True),
                   TrainConfig(strategy="parallel", epochs=EPOCHS, patience=0, truncate=200, batch_size=8, seed=0),
                   progress=False)
    linear = identify_linear(ds, refine=False)
    linear_test = nrmse(list(ds.test.y), [linear.simulate(u, y[0]) for u, y in zip(ds.test.u, ds.test.y)]).mean
    assert result.test_nrmse < 0.85 * linear_test, (result.test_nrmse, linear_test)
