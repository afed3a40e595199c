"""Atomic file writes: an interruption leaves the previous file or the new one, never a torn one.

Every writer goes through :func:`atomic_path`: the content is written to
``<name>.tmp`` next to the target, which is then renamed over it (a rename
within one folder is atomic); on an error the temporary file is removed and
the target is left as it was.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np


@contextmanager
def atomic_path(path: Path | str) -> Iterator[Path]:
    """A temporary path to write to; it replaces ``path`` when the block ends without error.

    The parent folder is created if needed.

    Parameters
    ----------
    path : Path or str
        The file to write.

    Yields
    ------
    Path
        ``path`` with ``.tmp`` appended to its name (same folder). Writers
        that infer a format from the file name (e.g. ``Figure.savefig``) must
        be given the format explicitly.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    try:
        yield temporary
        temporary.replace(path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def save_npz(path: Path | str, *, compressed: bool = False, **arrays: np.ndarray) -> None:
    """Write ``arrays`` to an ``.npz`` file atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : Path or str
        The ``.npz`` file.
    compressed : bool
        Use ``np.savez_compressed`` instead of ``np.savez``.
    **arrays : ndarray
        The arrays, by name.
    """
    with atomic_path(path) as temporary, open(temporary, "wb") as stream:
        (np.savez_compressed if compressed else np.savez)(stream, **arrays)


def save_text(path: Path | str, text: str) -> None:
    """Write ``text`` to a file atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : Path or str
        The text file.
    text : str
        Its whole content.
    """
    with atomic_path(path) as temporary:
        temporary.write_text(text)
