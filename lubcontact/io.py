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

from .local import LocalProblem

_SPARSE, _DENSE = 2, 0


def read_problem(path: str | Path) -> LocalProblem:
    """Read a ``.dat`` (Siconos) or ``.hdf5``/``.h5`` (FCLIB local or global) problem."""
    path = Path(path)
    if path.suffix == ".dat":
        return read_siconos(path)
    if path.suffix in (".hdf5", ".h5"):
        return read_fclib(path)
    raise ValueError(f"path: unknown problem format {path.suffix!r} for {path}")


def read_siconos(path: str | Path) -> LocalProblem:
    """Read a Siconos frictional contact problem written by ``frictionContact_printInFile``."""
    path = Path(path)
    lines = path.read_text().splitlines()
    header = [int(lines[k].split()[0]) for k in range(5)]
    dim, n_contacts, storage, rows, cols = header
    n = n_contacts * dim
    if (rows, cols) != (n, n):
        raise ValueError(f"{path}: matrix is {rows}x{cols}, expected {n}x{n} for "
                         f"{n_contacts} contacts in {dim}D")
    if storage == _SPARSE:
        matrix, after = _read_cs_print(lines, 6, n)
    elif storage == _DENSE:
        numbers, after = _read_numbers(lines, 5, n * n)
        matrix = sp.csr_matrix(numbers.reshape(n, n, order="F"))
    else:
        raise ValueError(f"{path}: matrix storage type {storage} is not supported (0 or 2)")
    q, after = _read_numbers(lines, after, n)
    mu, _ = _read_numbers(lines, after, n_contacts)
    return LocalProblem.from_contact_major(matrix, q, mu, dim, name=path.stem)


def _read_numbers(lines: list[str], start: int, count: int) -> tuple[np.ndarray, int]:
    """``count`` floats from ``lines[start:]``; returns them and the next line index."""
    values, line = [], start
    while len(values) < count:
        if line >= len(lines):
            raise ValueError(f"expected {count} numbers from line {start + 1}, found {len(values)}")
        values.extend(lines[line].split())
        line += 1
    if len(values) != count:
        raise ValueError(f"expected {count} numbers from line {start + 1}, found {len(values)}")
    return np.array(values, dtype=float), line


def _read_cs_print(lines: list[str], start: int, n: int) -> tuple[sp.csr_matrix, int]:
    """Parse a CSparse ``cs_print`` listing of a compressed-column matrix."""
    line = start
    while not lines[line].lstrip().startswith("col") and "nnz" not in lines[line]:
        line += 1
    if "nnz" not in lines[line]:
        raise ValueError(f"line {line + 1}: expected the cs_print size line")
    nnz = int(lines[line].split("nnz:")[1].split(",")[0])
    body = lines[line + 1: line + 1 + nnz + n]
    columns = np.array([not entry.lstrip().startswith("col") for entry in body])
    if not body or columns[0] or columns.sum() != nnz:
        raise ValueError(f"line {line + 2}: malformed cs_print listing ({columns.sum()} of "
                         f"{nnz} entries)")
    column_of_entry = np.cumsum(~columns)[columns] - 1
    entries = np.array([entry.split(":") for entry, keep in zip(body, columns) if keep], dtype=float)
    matrix = sp.csc_matrix((entries[:, 1], (entries[:, 0].astype(int), column_of_entry)), shape=(n, n))
    return matrix.tocsr(), line + 1 + nnz + n


def read_fclib(path: str | Path) -> LocalProblem:
    """Read an FCLIB HDF5 problem (local, or global converted to local form)."""
    import h5py

    path = Path(path)
    with h5py.File(path, "r") as handle:
        if "fclib_local" in handle:
            group = handle["fclib_local"]
            dim = int(group["spacedim"][0])
            return LocalProblem.from_contact_major(
                _fclib_matrix(group["W"]), group["vectors/q"][()], group["vectors/mu"][()], dim,
                name=path.stem)
        if "fclib_global" in handle:
            group = handle["fclib_global"]
            dim = int(group["spacedim"][0])
            delassus, q = global_to_local(_fclib_matrix(group["M"]), _fclib_matrix(group["H"]),
                                          group["vectors/f"][()], group["vectors/w"][()])
            return LocalProblem.from_contact_major(delassus, q, group["vectors/mu"][()], dim,
                                                   name=path.stem)
    raise ValueError(f"{path}: neither an fclib_local nor an fclib_global group")


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
    m, n, nz = int(group["m"][0]), int(group["n"][0]), int(group["nz"][0])
    p, i, x = group["p"][()], group["i"][()], group["x"][()]
    if nz == -1:
        return sp.csc_matrix((x, i, p), shape=(m, n)).tocsr()
    if nz == -2:
        return sp.csr_matrix((x, i, p), shape=(m, n))
    if nz >= 0:
        return sp.csr_matrix((x[:nz], (i[:nz], p[:nz])), shape=(m, n))
    raise ValueError(f"{group.name}: unknown FCLIB matrix storage nz={nz}")
