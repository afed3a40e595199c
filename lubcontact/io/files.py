"""Atomic file writes: an interruption leaves the previous file or the new one, never a torn one."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def save_npz(path: Path | str, *, compressed: bool = False, **arrays) -> None:
    """Write ``arrays`` to ``path`` through a temporary file and a rename: an
    interruption leaves the previous file or the new one, never a torn one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    try:
        with open(temporary, "wb") as stream:
            (np.savez_compressed if compressed else np.savez)(stream, **arrays)
        temporary.replace(path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
