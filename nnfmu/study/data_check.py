"""Refuse a study's data when they are not of the study's system, before anything is written.

A study scores its networks next to the system's physics model, whose FMU has
the physics model's inputs and outputs; data of another system would train for
minutes and then fail at scoring, or, worse, compare unrelated models.
"""

from __future__ import annotations

from nnfmu.data import Dataset
from nnfmu.errors import DataError

# the physics model a study compares with (the measured robot is compared with the arm model)
PHYSICS_OF = {"valve": "valve", "arm": "arm", "robot": "arm"}


def declared_system(ds: Dataset) -> str | None:
    """The system the data say they come from: generated valve or arm data, or the robot benchmark."""
    source = ds.source
    if source.get("kind") == "robot-benchmark":
        return "robot"
    return source.get("system") if source.get("system") in ("valve", "arm") else None


def check_study_data(system: str, ds: Dataset, where: str) -> None:
    """Raise :class:`DataError` unless ``ds`` (read from ``where``) fits the study of ``system``."""
    from nnfmu.physics import arm_system, valve_system

    if "test" not in ds.splits:
        raise DataError(f"{where} has no 'test' split (splits: {', '.join(ds.splits)}); the study scores every "
                        "model on the test split: add test.npz to the dataset folder")
    declared = declared_system(ds)
    if declared is not None and declared != system and not {declared, system} <= {"arm", "robot"}:
        raise DataError(f"{where} holds {declared} data, not {system} data; run 'nnfmu reproduce {declared}' on "
                        f"them, or give --data of the {system}")
    physics = valve_system() if PHYSICS_OF[system] == "valve" else arm_system()
    want = ([v.name for v in physics.inputs], [v.name for v in physics.outputs])
    if (ds.input_names, ds.output_names) != want:
        raise DataError(f"{where} has inputs {ds.input_names} and outputs {ds.output_names}, but the {system} study "
                        f"needs inputs {want[0]} and outputs {want[1]} (those of its physics model); give --data of "
                        f"the {system}")
