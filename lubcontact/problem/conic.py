"""What every solver may ask of a problem: the :class:`ConicProblem` protocol.

A conic problem is the dual of one contact step, over contact forces ``lam``
laid out as ``[all normal rows, then the tangential block of each contact in
cones.tangential]``::

    min_lam 1/2 lam^T W lam + lam^T b   s.t.  lam_c in K_c

:class:`~lubcontact.problem.StepProblem` (from a time step, ``W = dt^2 H M^-1 H^T``)
and :class:`~lubcontact.problem.LocalProblem` (from an FCLIB/Siconos file,
``W`` given) both satisfy it; solvers see nothing else.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp

from .. import checks
from .cones import Cones

if TYPE_CHECKING:                       # typing.Self exists from Python 3.11
    from typing import Self


@dataclass
class Scaling:
    """Map between a problem and its normalised form.

    Physical velocity ``v = velocity * v_scaled`` (per degree of freedom),
    force ``lam = force * lam_scaled``, length ``D = length * D_scaled``.
    """

    velocity: np.ndarray
    force: float
    length: float


@runtime_checkable
class ConicProblem(Protocol):
    """The members a solver, the fixed point on s and the error measures use.

    Attributes
    ----------
    cones : Cones
        Force set of each contact (its kinds fix the row layout).
    shift : ndarray, shape (nc,)
        ``s`` of the fixed point on s, added to the normal rows of ``b``.
    scaling : Scaling or None
        Set on a problem returned by :meth:`normalized`.
    """

    cones: Cones
    shift: np.ndarray
    scaling: Scaling | None

    @property
    def n_contacts(self) -> int: ...

    @property
    def n_rows(self) -> int: ...

    @property
    def delassus(self) -> sp.csr_matrix:
        """``W``, shape (n_rows, n_rows)."""

    @property
    def delassus_factor(self) -> sp.csr_matrix | None:
        """``L`` with ``W = L^T L`` when known (a step problem), else None."""

    @property
    def delassus_factor_transpose(self) -> sp.csr_matrix | None:
        """``L^T`` in CSR form when ``L`` is known, else None."""

    @property
    def delassus_rank_bound(self) -> int:
        """An upper bound on the rank of ``W``."""

    @property
    def dense_delassus(self) -> np.ndarray:
        """``W`` as a dense array, shape (n_rows, n_rows) (built on demand: small problems)."""

    @property
    def offset(self) -> np.ndarray:
        """``b``, shape (n_rows,), the shift included."""

    def gradient(self, forces: np.ndarray) -> np.ndarray:
        """``W lam + b``, shape (n_rows,)."""

    def velocity(self, forces: np.ndarray) -> np.ndarray:
        """The velocities the forces produce."""

    def constraint_values(self, velocity: np.ndarray) -> np.ndarray:
        """``W lam + b`` from ``velocity(lam)``, shape (n_rows,)."""

    def dual_objective(self, forces: np.ndarray) -> float: ...

    def natural_residual(self, forces: np.ndarray) -> float: ...

    def normalized(self) -> ConicProblem:
        """The same problem in scaled units, carrying its :class:`Scaling`."""

    def with_shift(self, shift: np.ndarray) -> ConicProblem: ...

    def with_cones(self, cones: Cones) -> ConicProblem: ...

    def keep_matrices(self, copy: ConicProblem) -> None: ...


class ConicProblemMixin:
    """Members both problem classes derive the same way.

    The class using it is a dataclass with fields ``cones`` and ``shift`` and
    a method ``gradient(forces)``.
    """

    @property
    def n_contacts(self) -> int:
        return self.cones.count

    @property
    def n_rows(self) -> int:
        return self.cones.n_rows

    @property
    def delassus_rank_bound(self) -> int:
        """An upper bound on the rank of ``W``: ``n_rows`` where nothing else is known."""
        return self.n_rows

    def natural_residual(self, forces: np.ndarray) -> float:
        """``|lam - P_K(lam - (W lam + b))|`` in this problem's units."""
        return self.cones.natural_residual(forces, self.gradient(forces))

    def with_shift(self, shift: np.ndarray) -> Self:
        """A copy with another shift ``s``, sharing the matrices (``W`` is not rebuilt)."""
        return self._replaced(shift=shift)           # checked and copied there (checks.as_array)

    def with_cones(self, cones: Cones) -> Self:
        """A copy with other force sets of the same layout, sharing the matrices."""
        checks.require(cones.n_rows == self.n_rows, "cones", "must keep the row layout",
                       cones.n_rows)
        return self._replaced(cones=cones)

    def keep_matrices(self, copy: ConicProblem) -> None:
        """Keep the cached matrices (``MATRICES``) that ``copy``, a copy of this problem with
        another shift or other cones, has built and this problem has not: they depend on
        neither, and later copies of this problem then share them."""
        for name in MATRICES:
            if name in copy.__dict__:
                self.__dict__.setdefault(name, copy.__dict__[name])

    def _replaced(self, **changes: Any) -> Self:
        """A copy with ``changes`` (checked by the constructor) and this problem's cached matrices
        (they depend on neither shift nor cones)."""
        other = replace(self, **changes)
        for name in MATRICES:
            if name in self.__dict__:
                other.__dict__.setdefault(name, self.__dict__[name])
        return other


MATRICES = ("delassus", "delassus_factor", "delassus_factor_transpose", "jacobian_transpose",
            "dense_jacobian", "dense_delassus")
"""Cached matrices of a problem, independent of its shift and cones."""
