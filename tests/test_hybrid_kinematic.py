"""A hybrid on a user's model by default corrects no kinematic identity (``dpos/dt = v``) and does not show its
network an ignorable state (``pos`` on a rail, which no derivative depends on) (issue 23).

On the viscous slider fitted to Stribeck data, correcting ``pos`` too let the first two optimiser steps take
the validation NRMSE from 0.477 to 0.746; with ``v`` alone it fell to 0.40 in six. Seeing ``pos`` as well, the
best validation NRMSE in 120 steps was 0.20, against 0.149 without.
"""

from pathlib import Path

import numpy as np
import torch

from nnfmu.data import Channel, from_arrays
from nnfmu.hybrid import HybridConfig, HybridStepModel
from nnfmu.hybrid.config import physics_system
from nnfmu.hybrid.parameters import ignorable_states, kinematic_states
from nnfmu.physics import ModelBuilder, resolve_physics
from nnfmu.training import TrainConfig, train

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "slider_viscous.py"


def _model(rhs):
    m = ModelBuilder("two", Ts=0.1)
    a, b = m.state("a"), m.state("b")
    u = m.input("u")
    m.ode(**rhs(a, b, u))
    m.output("y", "", "a", a)
    return m.build()


def test_kinematic_identities_are_found():
    assert kinematic_states(resolve_physics(f"{EXAMPLE}:slider_viscous")) == ("pos",)
    assert kinematic_states(physics_system("arm")) == tuple(f"q{j}" for j in range(1, 7))
    assert kinematic_states(_model(lambda a, b, u: {"a": 2 * b, "b": u - a})) == ()  # scaled: not an identity
    assert kinematic_states(_model(lambda a, b, u: {"a": a, "b": u})) == ()  # its own state: not kinematic


def test_a_user_model_corrects_its_dynamic_states_by_default():
    user = HybridConfig(n_u=1, n_y=1, physics=f"{EXAMPLE}:slider_viscous")
    assert user.corrected_states == ("v",)  # as the registered slider's entry chose by hand
    assert HybridConfig(n_u=1, n_y=1, physics=f"{EXAMPLE}:slider_viscous",
                        corrected_states=("pos", "v")).corrected_states == ("pos", "v")  # still a choice
    both = _model(lambda a, b, u: {"a": b, "b": a})  # every derivative is a state: correct them all
    assert HybridConfig(n_u=1, n_y=1, physics=both).corrected_states == ("a", "b")



def test_the_correction_does_not_see_an_ignorable_state():
    """``pos`` on a rail: no derivative depends on it, so the network's weights on it are zero and stay zero."""
    assert ignorable_states(resolve_physics(f"{EXAMPLE}:slider_viscous")) == ("pos",)
    assert ignorable_states(_model(lambda a, b, u: {"a": b, "b": u - a})) == ()
    config = HybridConfig(n_u=1, n_y=1, physics=f"{EXAMPLE}:slider_viscous", hidden=8, physics_backend="sx")
    assert config.correction_inputs == ("v",)
    rng = np.random.default_rng(0)
    u, y = rng.uniform(-6, 6, size=(60, 1)), np.cumsum(rng.normal(scale=0.01, size=(60, 1)), axis=0)
    ds = from_arrays(Ts=0.01, u_train=u, y_train=y, u_test=u[:30], y_test=y[:30],
                     input_names=[Channel("F", "N")], output_names=[Channel("pos", "m")])
    torch.manual_seed(0)
    model = train(ds, config, TrainConfig(epochs=3, truncate=20, batch_size=1, dtype="float64", patience=0),
                  progress=False).model
    first = model.correction[0].weight.detach()
    assert (first[:, 0] == 0).all() and (first[:, 1:] != HybridStepModel(config).double().correction[0].weight
                                          .detach()[:, 1:]).any()  # v and F learned, pos never
    model.correction[0].weight.grad = None
    (model.correction[0].weight * torch.randn_like(first)).sum().backward()  # any path that reads the weight
    assert (model.correction[0].weight.grad[:, 0] == 0).all()


def test_a_stored_config_from_before_the_option_sees_every_state():
    user = HybridConfig(n_u=1, n_y=1, physics=f"{EXAMPLE}:slider_viscous")
    old = {k: v for k, v in user.to_dict().items() if k != "correction_inputs"}
    assert HybridConfig.from_dict(old).correction_inputs == ("pos", "v")  # as its network was trained
    assert HybridConfig.from_dict(user.to_dict()) == user
    assert HybridConfig(n_u=1, n_y=1, physics="slider").correction_inputs == ("pos", "v")  # registered: as before
    assert user.replace(physics="slider", corrected_states=None).correction_inputs == ("pos", "v")  # its own default
