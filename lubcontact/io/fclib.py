"""FCLIB HDF5 frictional contact problems: read and write ``fclib_local`` and ``fclib_global``.

The layout, as FCLIB's ``fclib.h`` (``fclib_write_local``, ``fclib_write_global``,
``write_matrix``, ``fclib_write_solution``) writes it::

    /fclib_local   spacedim (int [1]), W (matrix), vectors/q, vectors/mu, info/
    /fclib_global  spacedim, M (matrix), H (matrix), vectors/f, vectors/w, vectors/mu, info/
    /solution      r, u (and v for a global problem), optional
    /guesses       number_of_guesses, 1/, 2/, ... (same members as /solution; not read)

- local: ``u = W r + q``; global: ``M v = H r + f``, ``u = H^T v + w``
  (:mod:`lubcontact.problem.global_form`); ``W`` is ``m x m``, ``H`` is
  ``n_dof x m``, ``m = spacedim * nc``, vectors contact-major.
- A matrix is a group of ``nzmax, m, n, nz`` (int, one value each) and ``p, i,
  x``: ``nz = -1`` compressed columns (``p`` n+1 column pointers, ``i`` row
  indices), ``nz = -2`` compressed rows (``p`` m+1 row pointers, ``i`` column
  indices), ``nz >= 0`` ``nz`` triplets with ``i`` the row and ``p`` the column
  indices (CSparse's convention, which Siconos' FCLIB interface follows and the
  files use; ``fclib.h``'s comment says the opposite). Only the first
  ``p[-1]`` (compressed) or ``nz`` (triplet) entries count (``nzmax`` may be larger).
- ``info`` holds the strings ``title``, ``description``, ``math_info``;
  FCLIB adds integers as attributes of ``/fclib_local/info``
  (``fclib_create_int_attributes_in_info``); other metadata here is written the same way.

The writers use compressed rows for ``W`` (as the FCLIB collection does) and
compressed columns for ``M`` and ``H`` (Siconos' FCLIB reader does not take
compressed rows for a global problem). HDF5 stores the doubles themselves: a
written problem reads back bit for bit.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeVar, Union

import numpy as np
import scipy.sparse as sp

from ..problem.global_form import GlobalProblem, canonical_csr, global_from_step, step_forces_to_local
from ..problem.local import LocalProblem
from ..problem.step import StepProblem
from .files import atomic_path
from .siconos import contact_major_delassus

if TYPE_CHECKING:
    import h5py

T = TypeVar("T")


class SolutionLike(Protocol):
    """Anything with contact forces (a solver result)."""

    forces: np.ndarray


Solution = Union[np.ndarray, SolutionLike, None]  # noqa: UP007  (a runtime alias: | needs 3.10 types)
"""Forces to store beside a problem: an array, a result with ``forces``, or None."""

INFO_STRINGS = ("title", "description", "math_info")


# -- reading --------------------------------------------------------------------------------------
class _Reader:
    """Reads members of an open FCLIB file; every failure is a ``ValueError`` naming file and member."""

    def __init__(self, path: Path, handle: h5py.File) -> None:
        self.path, self.handle = path, handle

    def fail(self, name: str, message: str) -> ValueError:
        return ValueError(f"{self.path}: {name}: {message}")

    def member(self, group: h5py.Group, name: str) -> h5py.Dataset | h5py.Group:
        full = f"{group.name}/{name}"
        try:
            if name not in group:
                raise self.fail(full, "missing")
            return group[name]
        except (KeyError, OSError, RuntimeError) as exc:
            raise self.fail(full, f"unreadable ({exc})") from None

    def array(self, group: h5py.Group, name: str, kind: str) -> np.ndarray:
        """A 1-D dataset of numbers (``kind`` "float" or "int"), finite."""
        import h5py

        dataset = self.member(group, name)
        full = f"{group.name}/{name}"
        if not isinstance(dataset, h5py.Dataset):
            raise self.fail(full, "expected a dataset, found a group")
        try:
            data = np.asarray(dataset[()])
        except (OSError, RuntimeError, TypeError, ValueError) as exc:
            raise self.fail(full, f"unreadable ({exc})") from None
        if data.dtype.kind not in "fiu" or data.ndim > 1:
            raise self.fail(full, f"expected a vector of numbers, got dtype {data.dtype} shape {data.shape}")
        data = data.ravel()
        if data.dtype.kind == "f":
            bad = np.flatnonzero(~np.isfinite(data))
            if bad.size:
                raise self.fail(full, f"non-finite value {data[bad[0]]} at index {bad[0]}")
        if kind == "int":
            if data.dtype.kind == "f" and np.any(data != np.round(data)):
                raise self.fail(full, "expected integers")
            return data.astype(np.int64)
        return data.astype(float)

    def scalar(self, group: h5py.Group, name: str) -> int:
        data = self.array(group, name, "int")
        if data.size != 1:
            raise self.fail(f"{group.name}/{name}", f"expected one integer, got {data.size} values")
        return int(data[0])

    def vector(self, group: h5py.Group, name: str, size: int | None = None) -> np.ndarray:
        data = self.array(group, name, "float")
        if size is not None and data.size != size:
            raise self.fail(f"{group.name}/{name}", f"expected {size} values, got {data.size}")
        return data

    def spacedim(self, group: h5py.Group) -> int:
        value = self.scalar(group, "spacedim")
        if value not in (2, 3):
            raise self.fail(f"{group.name}/spacedim", f"must be 2 or 3, got {value}")
        return value

    def matrix(self, group: h5py.Group, name: str, shape: tuple[int, int]) -> sp.csr_matrix:
        """An FCLIB matrix group (module docstring) of the expected ``shape``."""
        sub = self.member(group, name)
        where = f"{group.name}/{name}"
        m, n, nz = (self.scalar(sub, key) for key in ("m", "n", "nz"))
        if (m, n) != shape:
            raise self.fail(f"{where}/m, n", f"expected shape {shape}, got {(m, n)}")
        p, i = self.array(sub, "p", "int"), self.array(sub, "i", "int")
        x = self.array(sub, "x", "float")
        if nz in (-1, -2):
            outer, inner, label = (n, m, "column") if nz == -1 else (m, n, "row")
            if p.size != outer + 1 or p[0] != 0 or np.any(np.diff(p) < 0):
                raise self.fail(f"{where}/p", f"expected {outer + 1} non-decreasing {label} pointers "
                                              f"from 0, got {p.size} values")
            count = int(p[-1])
            if count > min(i.size, x.size):
                raise self.fail(f"{where}/i, x", f"the pointers count {count} entries, i has "
                                                 f"{i.size} and x {x.size}")
            index = i[:count]
            if np.any((index < 0) | (index >= inner)):
                raise self.fail(f"{where}/i", f"index outside [0, {inner})")
            if nz == -1:
                return sp.csc_matrix((x[:count], index, p), shape=shape).tocsr()
            return sp.csr_matrix((x[:count], index, p), shape=shape)
        if nz >= 0:
            if min(p.size, i.size, x.size) < nz:
                raise self.fail(f"{where}/p, i, x", f"nz = {nz} triplets, got {p.size}, {i.size}, "
                                                    f"{x.size} values")
            rows, cols = i[:nz], p[:nz]
            if np.any((rows < 0) | (rows >= m)) or np.any((cols < 0) | (cols >= n)):
                raise self.fail(f"{where}/i, p", f"triplet index outside the {m} x {n} matrix")
            return sp.coo_matrix((x[:nz], (rows, cols)), shape=shape).tocsr()
        raise self.fail(f"{where}/nz", f"unknown FCLIB matrix storage nz={nz} (-1 csc, -2 csr, "
                                       ">= 0 triplet)")


def _open(path: str | Path, action: Callable[[_Reader], T]) -> T:
    """Run ``action(reader)`` on the open file; HDF5 failures become ``ValueError`` naming it."""
    import h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no problem file {path}")
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"{path}: not a readable HDF5 file ({exc})") from None
    with handle:
        try:
            return action(_Reader(path, handle))
        except (KeyError, OSError, RuntimeError, TypeError, IndexError) as exc:
            raise ValueError(f"{path}: unreadable FCLIB content ({type(exc).__name__}: {exc})") from None


def _local(reader: _Reader) -> LocalProblem:
    group = reader.member(reader.handle, "fclib_local")
    dim = reader.spacedim(group)
    vectors = reader.member(group, "vectors")
    q = reader.vector(vectors, "q")
    if q.size % dim:
        raise reader.fail(f"{vectors.name}/q", f"{q.size} values, not a multiple of spacedim {dim}")
    mu = reader.vector(vectors, "mu", q.size // dim)
    delassus = reader.matrix(group, "W", (q.size, q.size))
    return _checked(reader, lambda: LocalProblem.from_contact_major(canonical_csr(delassus), q, mu,
                                                                    dim, name=_stem(reader.path)))


def _global(reader: _Reader) -> GlobalProblem:
    group = reader.member(reader.handle, "fclib_global")
    dim = reader.spacedim(group)
    vectors = reader.member(group, "vectors")
    f, w = reader.vector(vectors, "f"), reader.vector(vectors, "w")
    if w.size % dim:
        raise reader.fail(f"{vectors.name}/w", f"{w.size} values, not a multiple of spacedim {dim}")
    mu = reader.vector(vectors, "mu", w.size // dim)
    mass = reader.matrix(group, "M", (f.size, f.size))
    jacobian = reader.matrix(group, "H", (f.size, w.size))
    if "G" in group:
        raise reader.fail(f"{group.name}/G", "equality constraints (G, b) are not supported")
    return _checked(reader, lambda: GlobalProblem(M=mass, H=jacobian, f=f, w=w, mu=mu, dim=dim,
                                                  name=_stem(reader.path)))


def _checked(reader: _Reader, build: Callable[[], T]) -> T:
    try:
        return build()
    except ValueError as exc:
        raise ValueError(f"{reader.path}: {exc}") from None


def _kind(reader: _Reader) -> str:
    for kind in ("fclib_local", "fclib_global"):
        if kind in reader.handle:
            return kind
    raise ValueError(f"{reader.path}: neither an fclib_local nor an fclib_global group "
                     f"(found {sorted(reader.handle.keys())[:5]})")


def read_fclib(path: str | Path) -> LocalProblem:
    """Read an FCLIB problem as a local problem (a global one through ``W = H^T M^-1 H``).

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        For a file that is not HDF5 or malformed content (the message names the file and member).
    """
    def action(reader: _Reader) -> object:
        if _kind(reader) == "fclib_local":
            return _local(reader)
        problem = _global(reader)
        return _checked(reader, problem.to_local)
    return _open(path, action)


def read_fclib_global(path: str | Path) -> GlobalProblem:
    """Read an FCLIB ``fclib_global`` problem as a :class:`GlobalProblem`."""
    def action(reader: _Reader) -> object:
        if _kind(reader) != "fclib_global":
            raise ValueError(f"{reader.path}: a local problem (fclib_local), not a global one")
        return _global(reader)
    return _open(path, action)


def read_fclib_solution(path: str | Path) -> dict[str, np.ndarray] | None:
    """The ``/solution`` group (``r``, ``u``, and ``v`` if present; FCLIB layout), or None."""
    def action(reader: _Reader) -> object:
        if "solution" not in reader.handle:
            return None
        group = reader.handle["solution"]
        return {key: reader.vector(group, key) for key in ("r", "u", "v") if key in group}
    return _open(path, action)


def read_fclib_metadata(path: str | Path) -> dict:
    """The ``info`` group of the problem: its strings and its attributes, as one dict."""
    def action(reader: _Reader) -> object:
        info_path = f"{_kind(reader)}/info"
        if info_path not in reader.handle:
            return {}
        info = reader.handle[info_path]
        out = {key: _text(info[key][()]) for key in INFO_STRINGS if key in info}
        for key, value in info.attrs.items():
            value = np.asarray(value)
            out[key] = _text(value[()]) if value.dtype.kind in "SUO" else \
                (value.ravel()[0].item() if value.size == 1 else value)
        return out
    return _open(path, action)


def _text(value: object) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _stem(path: Path) -> str:
    return path.stem


# -- writing --------------------------------------------------------------------------------------
def _write_matrix(group: h5py.Group, name: str, matrix: sp.spmatrix, layout: str) -> None:
    """An FCLIB matrix group, compressed rows (``layout="csr"``) or columns (``"csc"``)."""
    compressed = sp.csr_matrix(matrix) if layout == "csr" else sp.csc_matrix(matrix)
    compressed.sum_duplicates()
    compressed.sort_indices()
    sub = group.create_group(name)
    m, n = compressed.shape
    for key, value in (("nzmax", compressed.nnz), ("m", m), ("n", n),
                       ("nz", -2 if layout == "csr" else -1)):
        sub.create_dataset(key, data=np.array([value], dtype=np.int32))
    sub.create_dataset("p", data=compressed.indptr.astype(np.int32))
    sub.create_dataset("i", data=compressed.indices.astype(np.int32))
    sub.create_dataset("x", data=compressed.data.astype(float))


def _write_info(group: h5py.Group, metadata: dict | None, title: str) -> None:
    metadata = dict(metadata or {})
    metadata.setdefault("title", title)
    info = group.create_group("info")
    for key in INFO_STRINGS:
        text = str(metadata.pop(key, "")).encode()
        info.create_dataset(key, data=np.array(text, dtype=f"S{len(text) + 1}"))  # NUL-terminated
    for key, value in metadata.items():
        try:
            info.attrs[key] = value
        except (TypeError, ValueError) as exc:
            raise ValueError(f"metadata: {key!r} cannot be stored as an HDF5 attribute ({exc})") from None


def _write_solution(handle: h5py.File, forces: np.ndarray, local_velocity: np.ndarray,
                    velocity: np.ndarray | None = None) -> None:
    group = handle.create_group("solution")
    if velocity is not None:
        group.create_dataset("v", data=np.asarray(velocity, dtype=float))
    group.create_dataset("u", data=np.asarray(local_velocity, dtype=float))
    group.create_dataset("r", data=np.asarray(forces, dtype=float))


def _forces(solution: np.ndarray | SolutionLike) -> np.ndarray:
    """The force vector of ``solution``: an array, or a result with a ``forces`` attribute."""
    return np.asarray(getattr(solution, "forces", solution), dtype=float)


def write_fclib_local(problem: LocalProblem, path: str | Path, *, solution: Solution = None,
                      metadata: dict | None = None) -> Path:
    """Write a local problem as FCLIB's ``fclib_local`` (``W`` in compressed rows), atomically.

    Parameters
    ----------
    problem : LocalProblem
    path : str or Path
    solution : ndarray (n_rows,) or result with ``forces``, optional
        Forces in our layout (as the solvers return them); written as
        ``/solution/r`` and ``/solution/u = W r + q``, contact-major.
    metadata : dict, optional
        ``title`` (default ``problem.name``), ``description``, ``math_info``
        (strings of the ``info`` group) and any other attribute of ``info``
        (numbers, strings or arrays).
    """
    if not isinstance(problem, LocalProblem):
        raise ValueError(f"problem: expected a LocalProblem, got {type(problem).__name__}")
    forces = None
    if solution is not None:
        forces = _forces(solution)
        if forces.shape != (problem.n_rows,):
            raise ValueError(f"solution: expected shape ({problem.n_rows},), got {forces.shape}")
    import h5py

    path = Path(path)
    with atomic_path(path) as temporary, h5py.File(temporary, "w") as handle:
        group = handle.create_group("fclib_local")
        group.create_dataset("spacedim", data=np.array([problem.dim], dtype=np.int32))
        _write_matrix(group, "W", contact_major_delassus(problem), "csr")
        vectors = group.create_group("vectors")
        vectors.create_dataset("q", data=problem.to_contact_major(problem.free_velocity))
        vectors.create_dataset("mu", data=np.asarray(problem.cones.mu, dtype=float))
        _write_info(group, metadata, problem.name)
        if forces is not None:
            _write_solution(handle, problem.to_contact_major(forces),
                            problem.to_contact_major(problem.velocity(forces)))
    return path


def write_fclib_global(M: sp.spmatrix, H: sp.spmatrix, f: np.ndarray, w: np.ndarray, mu: np.ndarray,
                       path: str | Path, *, solution: Solution = None, dim: int | None = None,
                       metadata: dict | None = None, name: str = "") -> Path:
    """Write ``M v = H r + f``, ``u = H^T v + w`` as FCLIB's ``fclib_global``, atomically.

    Parameters
    ----------
    M, H : sparse or dense, shapes (n_dof, n_dof), (n_dof, m)
    f, w, mu : array_like, shapes (n_dof,), (m,), (nc,)
        FCLIB layout (contact-major).
    path : str or Path
    solution : ndarray (m,) or result with ``forces``, optional
        Forces ``r`` in FCLIB layout; ``/solution`` gets ``r``, ``v = M^-1 (H r + f)``
        and ``u = H^T v + w``.
    dim : int, optional
        ``spacedim``; default ``m / nc`` (required when ``nc = 0``).
    metadata : dict, optional
        As for :func:`write_fclib_local` (``title`` defaults to ``name``).
    """
    mu = np.asarray(mu, dtype=float)
    n_rows = sp.csr_matrix(H).shape[1]
    if dim is None:
        if mu.ndim != 1 or mu.size == 0 or n_rows % mu.size:
            raise ValueError(f"dim: cannot infer spacedim from {n_rows} columns of H and "
                             f"{mu.size} contacts; pass dim")
        dim = n_rows // mu.size
    problem = GlobalProblem(M=M, H=H, f=f, w=w, mu=mu, dim=dim, name=name)
    return _write_global(problem, path, None if solution is None else _forces(solution), metadata)


def _write_global(problem: GlobalProblem, path: str | Path, forces: np.ndarray | None,
                  metadata: dict | None) -> Path:
    solution = None
    if forces is not None:
        if forces.shape != (problem.H.shape[1],):
            raise ValueError(f"solution: expected shape ({problem.H.shape[1]},), got {forces.shape}")
        velocity = problem.velocity(forces)
        solution = (forces, problem.H.T @ velocity + problem.w, velocity)
    import h5py

    path = Path(path)
    with atomic_path(path) as temporary, h5py.File(temporary, "w") as handle:
        group = handle.create_group("fclib_global")
        group.create_dataset("spacedim", data=np.array([problem.dim], dtype=np.int32))
        _write_matrix(group, "M", problem.M, "csc")
        _write_matrix(group, "H", problem.H, "csc")
        vectors = group.create_group("vectors")
        for key in ("f", "w", "mu"):
            vectors.create_dataset(key, data=np.asarray(getattr(problem, key), dtype=float))
        _write_info(group, metadata, problem.name)
        if solution is not None:
            _write_solution(handle, *solution)
    return path


def write_fclib(problem: LocalProblem | GlobalProblem | StepProblem, path: str | Path, *,
                solution: Solution = None, metadata: dict | None = None) -> Path:
    """Write any problem in FCLIB format: local as ``fclib_local``, global and step as ``fclib_global``.

    A :class:`StepProblem` is written through
    :func:`lubcontact.problem.global_form.global_from_step` (``H = dt J^T``,
    ``f = M U``, ``w = [D, 0]``, contact-major; ``ValueError`` for FREE,
    NONPOS or UNION contacts); its ``solution`` is the step's forces ``lam``
    (our layout), written as ``r``, with ``v`` the velocity after the step
    and ``u`` the constraint values ``g``.
    """
    if isinstance(problem, LocalProblem):
        return write_fclib_local(problem, path, solution=solution, metadata=metadata)
    forces = None if solution is None else _forces(solution)
    if isinstance(problem, StepProblem):
        if forces is not None:
            forces = step_forces_to_local(problem, forces, contact_major=True)
        problem = global_from_step(problem)
    if not isinstance(problem, GlobalProblem):
        raise ValueError(f"problem: expected a LocalProblem, GlobalProblem or StepProblem, got "
                         f"{type(problem).__name__}")
    return _write_global(problem, path, forces, metadata)
