"""What a failed or stopped ``nnfmu train`` leaves at ``--out``: nothing, unless an epoch finished.

The trainer writes the checkpoint before the first epoch (the untrained
network, epoch 0) so that ``--resume`` always has a file. If the command then
fails or is stopped before any training epoch finishes, that file holds
nothing worth keeping, and ``export`` would happily turn it into an FMU; a
checkpoint this command created is therefore removed again. Once an epoch has
finished, the checkpoint is kept: it is the resumable work.
"""

from __future__ import annotations

from pathlib import Path


def remove_if_untrained(out: Path) -> bool:
    """Delete the checkpoint at ``out`` if no training epoch finished in it; True if it was removed."""
    from nnfmu.errors import CheckpointError
    from nnfmu.models import load_checkpoint

    if not out.is_file():
        return False
    try:
        ckpt = load_checkpoint(out)
    except CheckpointError:
        return False  # not ours to judge: leave it
    if int((ckpt.get("resume") or {}).get("epoch", 0)) > 0:
        return False
    out.unlink(missing_ok=True)
    return True
