"""Physics reference models (CasADi SX ODEs), their RK4 discretisation and data generation.

- :class:`PhysicsSystem`: a continuous-time model with named variables; ``.model()`` gives the
  RK4-discretised ``(init, step)`` pair (:class:`nnfmu.system.CasadiModel`).
- :class:`ModelBuilder`: write a model in a few lines of CasADi (docs/own-physics.md); the built-in
  models below are written with it.
- :func:`valve_system` / :class:`ValveParams`: the two-stage pneumatic valve.
- :func:`arm_system` / :class:`ArmParams`: the KUKA KR300 arm (RNEA in :mod:`nnfmu.physics.arm_dynamics`).
- :func:`slider_system` / :class:`SliderParams`: a mass on a rail with friction (an integrating plant).
- :func:`rk4_step`, :func:`rk4_function`: the fixed-step RK4 used everywhere.
- :func:`estimating_model`, :func:`with_init_window`: a model whose ``init`` estimates the whole state from an
  init window (:mod:`nnfmu.physics.initial_state`), for the FMUs of physics models, fits and hybrids.
- :func:`generate_dataset`: simulated datasets (``nnfmu generate``); :func:`generate_model_dataset` for any
  model (a user's own) with the toolkit's excitation signals.
- :func:`resolve_physics` / :func:`register_physics`: the models by name (:mod:`nnfmu.physics.registry`),
  by model file (``path/to/file.py:NAME``, which runs that file; :func:`models_in_file`) or JSON document;
  :func:`system_to_document`: a model as JSON with its CasADi Functions serialized.
"""

from nnfmu.physics.arm import ARM_F_B_CAP, ARM_N_SUB, ArmParams, arm_system
from nnfmu.physics.arm_dynamics import bias_torque, forward_dynamics, kinetic_energy, mass_matrix, rnea
from nnfmu.physics.base import PhysicsSystem, parameter_variables, params_to_json, unpack_parameters
from nnfmu.physics.builder import ModelBuilder, check_system
from nnfmu.physics.compiled import compile_function
from nnfmu.physics.document import system_from_document, system_to_document
from nnfmu.physics.generate import check_request, generate_dataset
from nnfmu.physics.generate_model import generate_model_dataset
from nnfmu.physics.initial_state import estimating_model, with_init_window
from nnfmu.physics.model_file import models_in_file
from nnfmu.physics.rk4 import rk4_function, rk4_step
from nnfmu.physics.slider import SliderParams, slider_system
from nnfmu.physics.valve import ValveParams, valve_system
from nnfmu.physics.registry import (PhysicsEntry, StudyPreset, physics_entry, physics_names, register_physics,
                                    resolve_physics, study_names, study_preset)

# The built-in models register themselves (with their generators and studies) in these modules.
from nnfmu.physics import generate_arm, generate_slider, generate_valve  # noqa: E402,F401  isort: skip

__all__ = [
    "ModelBuilder",
    "check_system",
    "generate_model_dataset",
    "estimating_model",
    "with_init_window",
    "models_in_file",
    "PhysicsEntry",
    "StudyPreset",
    "study_names",
    "study_preset",
    "physics_entry",
    "physics_names",
    "register_physics",
    "resolve_physics",
    "system_from_document",
    "system_to_document",
    "ARM_F_B_CAP",
    "ARM_N_SUB",
    "ArmParams",
    "PhysicsSystem",
    "SliderParams",
    "ValveParams",
    "arm_system",
    "bias_torque",
    "compile_function",
    "forward_dynamics",
    "check_request",
    "generate_dataset",
    "kinetic_energy",
    "mass_matrix",
    "parameter_variables",
    "params_to_json",
    "rk4_function",
    "rk4_step",
    "rnea",
    "slider_system",
    "unpack_parameters",
    "valve_system",
]
