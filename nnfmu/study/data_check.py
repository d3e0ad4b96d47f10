"""Refuse a study's data when they are not of the study's system, before anything is written.

A study scores its networks next to the system's physics model, whose FMU has
the physics model's inputs and outputs; data of another system would train for
minutes and then fail at scoring, or, worse, compare unrelated models. Which
model a study compares with, and what marks its data, come from the physics
registry (:func:`nnfmu.physics.study_preset`).
"""

from __future__ import annotations

from nnfmu.data import Dataset
from nnfmu.errors import DataError
from nnfmu.physics import physics_names, study_names, study_preset


def declared_system(ds: Dataset) -> str | None:
    """The study the data say they come from: a study's measured data (its ``data_kind``), or data generated
    by a registered model that has a study of its own name; None when the source names none."""
    source = ds.source
    kinds = {study_preset(name)[1].data_kind: name for name in study_names()}
    if source.get("kind") in kinds.keys() - {None}:
        return kinds[source["kind"]]
    system = source.get("system")
    return system if system in study_names() and system in physics_names() else None


def check_study_data(system: str, ds: Dataset, where: str) -> None:
    """Raise :class:`DataError` unless ``ds`` (read from ``where``) fits the study of ``system``."""
    if "test" not in ds.splits:
        raise DataError(f"{where} has no 'test' split (splits: {', '.join(ds.splits)}); the study scores every "
                        "model on the test split: add test.npz to the dataset folder")
    entry = study_preset(system)[0]
    declared = declared_system(ds)
    if declared is not None and study_preset(declared)[0] is not entry:  # the robot's data fit the arm's study
        raise DataError(f"{where} holds {declared} data, not {system} data; run 'nnfmu reproduce {declared}' on "
                        f"them, or give --data of the {system}")
    physics = entry.build()
    want = ([v.name for v in physics.inputs], [v.name for v in physics.outputs])
    if (ds.input_names, ds.output_names) != want:
        raise DataError(f"{where} has inputs {ds.input_names} and outputs {ds.output_names}, but the {system} study "
                        f"needs inputs {want[0]} and outputs {want[1]} (those of its physics model); give --data of "
                        f"the {system}")
