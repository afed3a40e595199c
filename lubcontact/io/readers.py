"""Read any external frictional contact problem by its suffix (Siconos ``.dat``, FCLIB HDF5).

The formats and their writers live in :mod:`lubcontact.io.siconos` and
:mod:`lubcontact.io.fclib`; this module only dispatches:

- ``.dat`` (``*.hdf5.dat`` included: Siconos text dumps of FCLIB problems) -> Siconos;
- ``.hdf5`` / ``.h5`` -> FCLIB.
"""
from __future__ import annotations

from pathlib import Path

from ..problem.global_form import GlobalProblem, global_to_local
from ..problem.local import LocalProblem
from .fclib import read_fclib, read_fclib_global
from .siconos import read_siconos, read_siconos_global

__all__ = ["global_to_local", "read_fclib", "read_global", "read_problem", "read_siconos"]

SICONOS_SUFFIXES = (".dat",)
FCLIB_SUFFIXES = (".hdf5", ".h5")


def _format(path: Path) -> str:
    if path.suffix in SICONOS_SUFFIXES:
        return "siconos"
    if path.suffix in FCLIB_SUFFIXES:
        return "fclib"
    raise ValueError(f"path: unknown problem format {path.suffix!r} for {path} "
                     "(.dat: Siconos, .hdf5/.h5: FCLIB)")


def read_problem(path: str | Path) -> LocalProblem:
    """Read a ``.dat`` (Siconos) or ``.hdf5``/``.h5`` (FCLIB) problem, local or global, in local form.

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        For an unknown suffix or malformed content (the message names the file and the field).
    """
    path = Path(path)
    return read_siconos(path) if _format(path) == "siconos" else read_fclib(path)


def read_global(path: str | Path) -> GlobalProblem:
    """Read a global problem (Siconos ``gfc2d``/``gfc3d`` ``.dat`` or FCLIB ``fclib_global``).

    Raises
    ------
    ValueError
        When the file holds a local problem, or for malformed content.
    """
    path = Path(path)
    return read_siconos_global(path) if _format(path) == "siconos" else read_fclib_global(path)
