"""Readers for external frictional contact problems (Siconos ``.dat``, FCLIB HDF5).

Every reader returns a :class:`~lubcontact.local.LocalProblem` (``u = W r + q``
with Coulomb cones, in our force layout), ready for
:func:`lubcontact.fixed_point.solve_coulomb`.

Formats (learnt from the files under ``benchmarks/``):

- Siconos ``.dat`` (``frictionContact_printInFile``): whitespace-separated
  ``dim``, ``nc``, then a NumericsMatrix (storage type, rows, columns, and
  for storage 2, a sparse-origin code followed by the CSparse ``cs_print``
  listing ``col j : locations a to b`` / ``i : value``; for storage 0 the
  dense entries in column-major order), then ``q`` (``nc dim`` numbers) and
  ``mu`` (``nc`` numbers). ``cs_print`` writes values with 6 significant
  digits: the matrix of the file is the problem, rounding included.
- FCLIB HDF5: group ``fclib_local`` (``W``, ``vectors/q``, ``vectors/mu``,
  ``spacedim``) or ``fclib_global`` (``M``, ``H``, ``vectors/f``,
  ``vectors/w``, ``vectors/mu``, ``spacedim``), with
  ``M v = H r + f`` and ``u = H^T v + w``, so that the local form is
  ``W = H^T M^-1 H`` and ``q = H^T M^-1 f + w``. Matrices are stored as
  ``m, n, nz, p, i, x``: ``nz = -1`` compressed columns, ``nz = -2``
  compressed rows, ``nz >= 0`` triplets (``i`` rows, ``p`` columns in the
  files seen). Vectors are contact-major (normal first per contact).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import checks
from ..problem.local import LocalProblem

_SPARSE, _DENSE = 2, 0


def read_problem(path: str | Path) -> LocalProblem:
    """Read a ``.dat`` (Siconos) or ``.hdf5``/``.h5`` (FCLIB local or global) problem.

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        For an unknown suffix or malformed content (the message names the field).
    """
    path = Path(path)
    if path.suffix == ".dat":
        return read_siconos(path)
    if path.suffix in (".hdf5", ".h5"):
        return read_fclib(path)
    raise ValueError(f"path: unknown problem format {path.suffix!r} for {path}")


def _existing(path: str | Path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no problem file {path}")
    return path


SICONOS_HEADER = ("dim", "nc", "storage", "rows", "columns")


def read_siconos(path: str | Path) -> LocalProblem:
    """Read a Siconos frictional contact problem written by ``frictionContact_printInFile``."""
    path = _existing(path)
    lines = path.read_text().splitlines()
    dim, n_contacts, storage, rows, cols = _read_header(lines, path)
    n = n_contacts * dim
    checks.require((rows, cols) == (n, n), f"{path}: W",
                   f"expected shape {(n, n)} for {n_contacts} contacts in {dim}D", (rows, cols))
    if storage == _SPARSE:
        matrix, after = _read_cs_print(lines, 6, n)
    elif storage == _DENSE:
        numbers, after = _read_numbers(lines, 5, n * n, "W")
        matrix = sp.csr_matrix(numbers.reshape(n, n, order="F"))
    else:
        raise ValueError(f"{path}: storage: matrix storage type {storage} is not supported (0 or 2)")
    q, after = _read_numbers(lines, after, n, "q")
    mu, _ = _read_numbers(lines, after, n_contacts, "mu")
    return LocalProblem.from_contact_major(matrix, q, mu, dim, name=path.stem)


def _read_header(lines: list[str], path: Path) -> list[int]:
    """``dim, nc, storage, rows, columns``: the first word of each of the first five lines."""
    values = []
    for line, field in enumerate(SICONOS_HEADER):
        words = lines[line].split() if line < len(lines) else []
        try:
            values.append(int(words[0]))
        except (IndexError, ValueError):
            raise ValueError(f"{path}: {field}: expected an integer on line {line + 1}, got "
                             f"{' '.join(words)!r}") from None
    checks.require(values[0] in (2, 3), f"{path}: dim", "must be 2 or 3", values[0])
    checks.require(values[1] >= 0, f"{path}: nc", "must be >= 0", values[1])
    return values


def _read_numbers(lines: list[str], start: int, count: int, field: str) -> tuple[np.ndarray, int]:
    """``count`` floats of ``field`` from ``lines[start:]``; returns them and the next line index."""
    values, line = [], start
    while len(values) < count and line < len(lines):
        values.extend(lines[line].split())
        line += 1
    if len(values) != count:
        raise ValueError(f"{field}: expected {count} numbers from line {start + 1}, found "
                         f"{len(values)}")
    try:
        return np.array(values, dtype=float), line
    except ValueError:
        raise ValueError(f"{field}: non-numeric entry from line {start + 1}") from None


def _read_cs_print(lines: list[str], start: int, n: int) -> tuple[sp.csr_matrix, int]:
    """Parse a CSparse ``cs_print`` listing of a compressed-column matrix."""
    line = start
    while line < len(lines) and not lines[line].lstrip().startswith("col") \
            and "nnz" not in lines[line]:
        line += 1
    if line >= len(lines) or "nnz" not in lines[line]:
        raise ValueError(f"W: line {line + 1}: expected the cs_print size line")
    nnz = int(lines[line].split("nnz:")[1].split(",")[0])
    body = lines[line + 1: line + 1 + nnz + n]
    columns = np.array([not entry.lstrip().startswith("col") for entry in body])
    if not body or columns[0] or columns.sum() != nnz:
        raise ValueError(f"W: line {line + 2}: malformed cs_print listing ({columns.sum()} of "
                         f"{nnz} entries)")
    column_of_entry = np.cumsum(~columns)[columns] - 1
    entries = np.array([entry.split(":") for entry, keep in zip(body, columns) if keep], dtype=float)
    matrix = sp.csc_matrix((entries[:, 1], (entries[:, 0].astype(int), column_of_entry)), shape=(n, n))
    return matrix.tocsr(), line + 1 + nnz + n


def read_fclib(path: str | Path) -> LocalProblem:
    """Read an FCLIB HDF5 problem (local, or global converted to local form)."""
    import h5py

    path = _existing(path)
    with h5py.File(path, "r") as handle:
        if "fclib_local" in handle:
            group = handle["fclib_local"]
            return LocalProblem.from_contact_major(
                _fclib_matrix(_member(group, "W")), _member(group, "vectors/q")[()],
                _member(group, "vectors/mu")[()], _spacedim(group), name=path.stem)
        if "fclib_global" in handle:
            group = handle["fclib_global"]
            delassus, q = global_to_local(
                _fclib_matrix(_member(group, "M")), _fclib_matrix(_member(group, "H")),
                _member(group, "vectors/f")[()], _member(group, "vectors/w")[()])
            return LocalProblem.from_contact_major(delassus, q, _member(group, "vectors/mu")[()],
                                                   _spacedim(group), name=path.stem)
    raise ValueError(f"{path}: neither an fclib_local nor an fclib_global group")


def _member(group, name: str):
    if name not in group:
        raise ValueError(f"{group.name}/{name}: missing from {group.file.filename}")
    return group[name]


def _spacedim(group) -> int:
    value = np.ravel(_member(group, "spacedim")[()])
    checks.require(value.size == 1 and value[0] in (2, 3), f"{group.name}/spacedim",
                   "must be one number, 2 or 3", value)
    return int(value[0])


def global_to_local(mass: sp.spmatrix, jacobian: sp.spmatrix, force: np.ndarray,
                    offset: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """``W = H^T M^-1 H`` and ``q = H^T M^-1 f + w`` of ``M v = H r + f``, ``u = H^T v + w``.

    Parameters
    ----------
    mass : sparse, shape (n_dof, n_dof)
        ``M``, symmetric positive definite.
    jacobian : sparse, shape (n_dof, n_rows)
        ``H``.
    force, offset : ndarray, shapes (n_dof,), (n_rows,)
        ``f`` and ``w``.
    """
    mass, jacobian = sp.csc_matrix(mass), sp.csc_matrix(jacobian)
    n_dof, n_rows = jacobian.shape
    checks.require(mass.shape == (n_dof, n_dof), "M", f"expected shape {(n_dof, n_dof)} (rows of H)",
                   mass.shape)
    force = checks.as_array("f", force, shape=(n_dof,))
    offset = checks.as_array("w", offset, shape=(n_rows,))
    off_diagonal = mass - sp.diags(mass.diagonal())
    if off_diagonal.count_nonzero() == 0:
        inverse_h = sp.diags(1.0 / mass.diagonal()) @ jacobian
        inverse_f = force / mass.diagonal()
    else:
        factor = spla.splu(mass)
        inverse_h = sp.csc_matrix(factor.solve(jacobian.toarray()))
        inverse_f = factor.solve(force)
    delassus = sp.csr_matrix(jacobian.T @ inverse_h)
    return delassus, jacobian.T @ inverse_f + offset


def _fclib_matrix(group) -> sp.csr_matrix:
    """An FCLIB matrix group (``m, n, nz, p, i, x``; module docstring)."""
    m, n, nz = (int(np.ravel(_member(group, key)[()])[0]) for key in ("m", "n", "nz"))
    p, i, x = (_member(group, key)[()] for key in ("p", "i", "x"))
    try:
        if nz == -1:
            return sp.csc_matrix((x, i, p), shape=(m, n)).tocsr()
        if nz == -2:
            return sp.csr_matrix((x, i, p), shape=(m, n))
        if nz >= 0:
            return sp.csr_matrix((x[:nz], (i[:nz], p[:nz])), shape=(m, n))
    except ValueError as exc:
        raise ValueError(f"{group.name}: inconsistent m, n, p, i, x ({exc})") from None
    raise ValueError(f"{group.name}/nz: unknown FCLIB matrix storage nz={nz}")
