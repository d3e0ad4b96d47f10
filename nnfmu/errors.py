"""The one error hierarchy of nnfmu.

Every error the toolkit raises on purpose derives from :class:`NnfmuError`
and from the built-in exception a Python user would expect, so that both
``except nnfmu.NnfmuError`` and ``except ValueError`` work.

Messages follow one pattern: what was expected, what arrived, and what to do,
for example ``"train.npz: array 'u' has shape (3, 10), expected (n_traj,
n_steps, n_u); save u as a 3-D array"``.
"""

from __future__ import annotations


class NnfmuError(Exception):
    """Base class of every error raised by nnfmu on purpose."""


class ShapeError(NnfmuError, ValueError):
    """An array or a model size does not match what the caller promised."""


class DataError(NnfmuError, ValueError):
    """A dataset is invalid: NaN, a missing split, mismatched names or units."""


class DataFileError(NnfmuError, OSError):
    """A file or folder cannot be read or written (missing, corrupt, unwritable)."""


class ConfigError(NnfmuError, ValueError):
    """An option has an invalid value; the message lists the valid ones."""


class UnknownOptionError(NnfmuError, TypeError):
    """A configuration got an option it does not have; the message lists the valid ones."""


class CheckpointError(NnfmuError, ValueError):
    """A checkpoint is missing, corrupt or not an nnfmu checkpoint."""


class TrainingError(NnfmuError, RuntimeError):
    """Training cannot go on (for example the loss became NaN)."""


class ExportError(NnfmuError, ValueError):
    """A model cannot be turned into CasADi functions (unsupported layer ...)."""


class FmuBuildError(NnfmuError, RuntimeError):
    """Writing or compiling an FMU failed; the compiler's stderr is attached."""


class SimulationError(NnfmuError, RuntimeError):
    """Simulating a model or an FMU failed or produced non-finite values."""


class MetricError(NnfmuError, ValueError):
    """A score cannot be computed (for example a constant measured output)."""


def check_options(given: dict, valid: set | list | tuple, what: str) -> None:
    """Raise :class:`UnknownOptionError` (a ``TypeError``) listing the valid options if ``given`` has unknown keys.

    Used by typed, keyword-only configurations built from dictionaries (JSON
    files, CLI overrides), so that a typo is never silently ignored.
    """
    unknown = sorted(set(given) - set(valid))
    if unknown:
        raise UnknownOptionError(
            f"unknown {what} option(s) {', '.join(map(repr, unknown))}; "
            f"valid options are: {', '.join(sorted(valid))}"
        )
