"""Frictional contact problems given in local form ``u = W r + q`` (FCLIB, Siconos).

External benchmark problems come as a Delassus matrix ``W`` and a free
velocity ``q`` in *contact-major* layout: for each contact its normal
component first, then its ``dim - 1`` tangential components. Our force layout
is ``[all normals, then all tangential blocks]`` (see :mod:`lubcontact.problem.cones`),
so :class:`LocalProblem` permutes once on construction and offers the same
protocol as :class:`~lubcontact.problem.StepProblem` (``delassus``,
``offset``, ``cones``, ``gradient``, ``natural_residual``, ``normalized``,
``velocity``, ``with_shift``; no ``delassus_factor``: no factor ``W = L^T L``
is known), so that :func:`lubcontact.solvers.solve` and
:func:`lubcontact.solvers.coulomb.solve_coulomb` work on it unchanged.

The problem is the Coulomb problem of FCLIB: ``r_c`` in the cone
``{|r_T| <= mu r_n}``, ``u_c + mu_c |u_T,c| e_n`` in its dual, orthogonal.
The convex relaxation solved for a frozen shift ``s`` is

    min 1/2 r^T W r + r^T (q + [s, 0])   s.t.  r_c in K_c

(the ``dt = 1`` analogue of a step problem, lengths being velocities here).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .. import checks
from .cones import ConeKind, Cones
from .conic import ConicProblemMixin, Scaling


def contact_major_permutation(n_contacts: int, dim: int) -> np.ndarray:
    """Indices ``p`` such that ``ours = contact_major[p]``.

    Parameters
    ----------
    n_contacts : int
    dim : int
        Components per contact (2 or 3).

    Returns
    -------
    ndarray of int, shape (n_contacts * dim,)
    """
    starts = np.arange(n_contacts) * dim
    tangential = (starts[:, None] + np.arange(1, dim)).ravel()
    return np.concatenate([starts, tangential])


@dataclass
class LocalProblem(ConicProblemMixin):
    """``u = W r + q`` with Coulomb cones, in our force layout.

    Attributes
    ----------
    delassus : scipy.sparse.csr_matrix, shape (n_rows, n_rows)
        ``W``, symmetric positive semi-definite (velocity per force).
    free_velocity : ndarray, shape (n_rows,)
        ``q`` (velocity), without the shift.
    cones : Cones
        One COULOMB cone per contact, all contacts with tangential rows.
    shift : ndarray, shape (nc,)
        ``s`` of the fixed point (added to the normal rows of ``q``).
    name : str
        Where the problem came from (file stem).
    scaling : Scaling or None
        Set on the normalised copy: ``r = force * r_scaled``, ``u = velocity * u_scaled``.
    """

    delassus: sp.csr_matrix
    free_velocity: np.ndarray
    cones: Cones
    shift: np.ndarray | None = None
    name: str = ""
    scaling: Scaling | None = field(default=None, repr=False)

    def __post_init__(self):
        n = self.cones.n_rows
        if not sp.isspmatrix_csr(self.delassus):        # a copy with another shift keeps W itself
            self.delassus = sp.csr_matrix(self.delassus)
        checks.require(self.delassus.shape == (n, n), "W", f"expected shape {(n, n)}",
                       self.delassus.shape)
        self.free_velocity = checks.as_array("q", self.free_velocity, shape=(n,))
        if self.shift is None:
            self.shift = np.zeros(self.cones.count)
        self.shift = checks.as_array("shift", self.shift, shape=(self.cones.count,))

    @classmethod
    def from_contact_major(cls, delassus: sp.spmatrix | sp.sparray | np.ndarray, free_velocity: ArrayLike,
                           mu: ArrayLike, dim: int, name: str = "") -> LocalProblem:
        """Build from FCLIB/Siconos arrays (normal component first per contact).

        Parameters
        ----------
        delassus : sparse or dense, shape (nc * dim, nc * dim)
        free_velocity : array_like, shape (nc * dim,)
        mu : array_like, shape (nc,)
            Friction coefficients, >= 0.
        dim : int
            2 or 3.
        """
        checks.require(dim in (2, 3), "dim", "must be 2 or 3", dim)
        mu = checks.nonnegative("mu", mu, shape=(None,))
        n_contacts = mu.shape[0]
        order = contact_major_permutation(n_contacts, dim)
        delassus = sp.csr_matrix(delassus)
        checks.require(delassus.shape == (order.size, order.size), "W",
                       f"expected shape {(order.size, order.size)} for {n_contacts} contacts",
                       delassus.shape)
        q = checks.as_array("q", free_velocity, shape=(order.size,))
        cones = Cones(kinds=np.full(n_contacts, ConeKind.COULOMB, dtype=np.int8), mu=mu,
                      tangential=np.arange(n_contacts), tangent_dim=dim - 1)
        return cls(delassus=delassus[order][:, order].tocsr(), free_velocity=q[order], cones=cones,
                   name=name)

    # -- protocol in common with StepProblem (the common members: ConicProblemMixin) ---------------
    @property
    def delassus_factor(self) -> None:
        """No factor ``W = L^T L`` is known for a problem given by ``W``."""
        return None

    @property
    def delassus_factor_transpose(self) -> None:
        """No factor, so no transpose of it (:attr:`delassus_factor`)."""
        return None

    @cached_property
    def dense_delassus(self) -> np.ndarray:
        """``W`` as a dense array, shape (n_rows, n_rows) (for small problems)."""
        return self.delassus.toarray()

    @property
    def dim(self) -> int:
        return self.cones.tangent_dim + 1

    @cached_property
    def offset(self) -> np.ndarray:
        """``b = q + [s, 0]``."""
        out = self.free_velocity.copy()
        out[: self.n_contacts] += self.shift
        return out

    def velocity(self, forces: np.ndarray) -> np.ndarray:
        """Local velocities ``u = W r + q`` (no shift), shape (n_rows,)."""
        return self.delassus @ forces + self.free_velocity

    def constraint_values(self, velocity: np.ndarray) -> np.ndarray:
        """``u + [s, 0]`` (the shifted local velocity) from a local velocity ``u``, shape (n_rows,)."""
        out = velocity.copy()
        out[: self.n_contacts] += self.shift
        return out

    def gradient(self, forces: np.ndarray) -> np.ndarray:
        """``W r + b`` (the shifted local velocity)."""
        return self.delassus @ forces + self.offset

    def dual_objective(self, forces: np.ndarray) -> float:
        return float(0.5 * forces @ (self.delassus @ forces) + forces @ self.offset)

    def normalized(self) -> LocalProblem:
        """The same problem with ``W`` of unit mean diagonal and ``q`` of unit rms.

        Velocities are divided by ``V = rms(q)`` and forces by
        ``F = V / mean(diag W)`` (each falls back to 1 when zero), so that
        ``W_scaled = W F / V`` and ``q_scaled = q / V``.
        """
        speed = float(np.sqrt(np.mean(self.free_velocity**2))) if self.n_rows else 0.0
        speed = speed if speed > 0 else 1.0
        diagonal = float(np.mean(self.delassus.diagonal())) if self.n_rows else 0.0
        force = speed / diagonal if diagonal > 0 else speed
        scaling = Scaling(velocity=np.full(self.n_rows, speed), force=force, length=speed)
        return LocalProblem(delassus=self.delassus * (force / speed),
                            free_velocity=self.free_velocity / speed, cones=self.cones,
                            shift=self.shift / speed, name=self.name, scaling=scaling)

    # -- FCLIB layout ---------------------------------------------------------------------------
    def to_contact_major(self, vector: np.ndarray) -> np.ndarray:
        """A force or velocity vector in FCLIB layout (normal first per contact)."""
        out = np.empty_like(vector)
        out[contact_major_permutation(self.n_contacts, self.dim)] = vector
        return out

    def from_contact_major_vector(self, vector: np.ndarray) -> np.ndarray:
        """A vector in FCLIB layout, returned in our layout."""
        return np.asarray(vector)[contact_major_permutation(self.n_contacts, self.dim)]
