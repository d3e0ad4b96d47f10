"""Size limits checked before anything big is allocated, so that a typo gives one clear line.

``nnfmu train --hidden 100000`` would ask for a 30-billion-parameter GRU
(120 GB) and end in an allocation traceback deep inside torch. The command
line checks sizes here first:

- a network may have at most :data:`MAX_PARAMETERS` trainable parameters,
  counted exactly by building it on torch's ``meta`` device (no memory;
  :func:`nnfmu.models.size.check_network_size`, which sits above the networks it builds);
- ``--batch-size`` at most :data:`MAX_BATCH_SIZE` trajectories or windows;
- ``nnfmu linear --order/--max-order`` at most :data:`MAX_LINEAR_ORDER` states;
- ``nnfmu physics-fmu --n-sub``, and a model file's ``n_sub``, at most :data:`MAX_RK4_SUBSTEPS` RK4
  sub-steps per sample;
- the init window that a physics model, fit or hybrid estimates its state from (``physics-fmu``, ``export``,
  ``fit --init-window``) at most :data:`MAX_INIT_WINDOW` samples: each is a parameter per channel of the FMU;
- a model name (``export --name``, a model file's name) at most :data:`MAX_MODEL_NAME` characters: it names the
  FMU's binary and source files, and file names end at 255 bytes.

The limits are far above what the paper's study uses (GRU-64: 13 k parameters)
and what an FMU can hold in practice; the messages name them and the fix.
"""

from __future__ import annotations

from nnfmu.errors import ConfigError

MAX_PARAMETERS = 50_000_000
MAX_BATCH_SIZE = 100_000
MAX_LINEAR_ORDER = 200
MAX_RK4_SUBSTEPS = 10_000
MAX_MODEL_NAME = 128
MAX_INIT_WINDOW = 100_000
#: An epoch limit that no time budget reaches: ``TrainConfig(epochs=UNBOUNDED_EPOCHS, max_minutes=M)``
#: trains until the wall-clock budget ends (``nnfmu train --max-minutes M`` alone), and its progress bar
#: counts time instead of epochs.
UNBOUNDED_EPOCHS = 10**9


def check_at_most(option: str, value: int | None, limit: int, constant: str) -> None:
    """Raise ConfigError if ``value`` (of command-line ``option``) exceeds ``limit``."""
    if value is not None and value > limit:
        raise ConfigError(f"{option} {value} is above nnfmu's limit of {limit:,} (nnfmu.limits.{constant}); "
                          f"choose a smaller {option}")
