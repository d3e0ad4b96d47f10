"""A hybrid on a user's model leaves kinematic identities (``dpos/dt = v``) uncorrected by default (issue 23).

On the viscous slider fitted to Stribeck data, correcting ``pos`` too let the first two optimiser steps take
the validation NRMSE from 0.477 to 0.746; with ``v`` alone it fell to 0.40 in six.
"""

from pathlib import Path

from nnfmu.hybrid import HybridConfig
from nnfmu.hybrid.config import physics_system
from nnfmu.hybrid.parameters import kinematic_states
from nnfmu.physics import ModelBuilder, resolve_physics

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
