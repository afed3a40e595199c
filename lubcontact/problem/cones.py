"""Per-contact force sets (cones): one description for projection, cvxpy and residuals.

A force vector ``lam`` of a step problem is laid out as
``[lam_n (nc), lam_T (nt * tangent_dim)]``: one normal component per contact,
then the tangential components of the contacts listed in ``Cones.tangential``
(in that order). Force sets, by kind:

=========  ===============================================  ======================
kind       force set ``K_c``                                 velocity set ``K_c*``
=========  ===============================================  ======================
NONNEG     ``lam_n >= 0``                                    ``g_n >= 0``
FREE       ``lam_n`` in R                                    ``g_n = 0``
NONPOS     ``lam_n <= 0`` (pulled, frictionless)             ``g_n <= 0``
COULOMB    ``|lam_T| <= mu lam_n``                           ``g_n >= mu |g_T|``
UNION      COULOMB cone union ``{lam_n <= 0, lam_T = 0}``    (not convex)
=========  ===============================================  ======================

Tangential components of a contact whose kind is not COULOMB or UNION are
forced to zero (their velocity rows are unconstrained).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from functools import cached_property
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:                       # cvxpy is imported lazily, by the cvxpy methods only
    from cvxpy import Constraint, Expression


class ConeKind(IntEnum):
    NONNEG = 0
    FREE = 1
    NONPOS = 2
    COULOMB = 3
    UNION = 4


_KINDS = tuple(ConeKind)
"""The kinds by value (an Enum's own look-up by value costs 0.3 us each)."""


def project_friction_cone(normal: np.ndarray, tangential: np.ndarray,
                          mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean projection onto ``{|t| <= mu n}``, vectorised.

    Parameters
    ----------
    normal : ndarray, shape (m,)
    tangential : ndarray, shape (m, k)
    mu : ndarray, shape (m,)
        Friction coefficients, >= 0 (mu = 0 gives the half-line ``n >= 0``).

    Returns
    -------
    (ndarray (m,), ndarray (m, k))
    """
    norm_t = tangent_norms(tangential)
    inside = (norm_t <= mu * normal) & (normal >= 0.0)
    # outside: the boundary's point, whose normal part is scale; 0 on the polar cone
    # (mu |t| <= -n, where n + mu |t| <= 0)
    scale = np.maximum((normal + mu * norm_t) / (1.0 + mu * mu), 0.0)
    factor = np.divide(mu * scale, norm_t, out=inside.astype(float),     # of the tangential part
                       where=~inside & (norm_t > 0))
    return np.where(inside, normal, scale), factor[:, None] * tangential


def tangent_norms(tangential: np.ndarray) -> np.ndarray:
    """``|t|`` per row of ``tangential`` (m, k), shape (m,): ``np.linalg.norm(tangential,
    axis=1)``, to the bit for k = 1 and 2 (2D and 3D contacts), 1.8x faster on 13 or 1 000
    contacts."""
    return np.sqrt(np.einsum("ij,ij->i", tangential, tangential))


def project_dual_friction_cone(normal: np.ndarray, tangential: np.ndarray,
                               mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean projection onto the dual cone ``{mu |t| <= n}``, vectorised.

    Same arguments as :func:`project_friction_cone`; ``mu = 0`` gives the
    half-space ``n >= 0``. (The polar cone of ``{|t| <= mu n}`` is minus this one.)
    """
    norm_t = tangent_norms(tangential)
    inside = mu * norm_t <= normal
    polar = norm_t <= -mu * normal
    scale = (mu * normal + norm_t) / (1.0 + mu * mu)
    new_n = np.where(inside, normal, np.where(polar, 0.0, mu * scale))
    ratio = np.divide(scale, norm_t, out=np.zeros_like(norm_t), where=norm_t > 0)
    new_t = np.where(inside[:, None], tangential,
                     np.where(polar[:, None], 0.0, ratio[:, None] * tangential))
    return new_n, new_t


@dataclass
class Cones:
    """Force sets of every contact of a step problem.

    Attributes
    ----------
    kinds : ndarray of int8, shape (nc,)
        :class:`ConeKind` per contact.
    mu : ndarray, shape (nc,)
        Friction coefficients (ignored unless the kind is COULOMB or UNION).
    tangential : ndarray of int, shape (nt,)
        Contacts that have tangential force rows, in row order.
    tangent_dim : int
        Tangential components per contact (dim - 1).
    """

    kinds: np.ndarray
    mu: np.ndarray
    tangential: np.ndarray
    tangent_dim: int

    @classmethod
    def frictionless(cls, kinds: np.ndarray, tangent_dim: int) -> Cones:
        kinds = np.asarray(kinds, dtype=np.int8)
        return cls(kinds=kinds, mu=np.zeros(len(kinds)), tangential=np.zeros(0, dtype=int),
                   tangent_dim=tangent_dim)

    @cached_property     # (read many times a solve; the arrays are never replaced nor written)
    def count(self) -> int:
        return self.kinds.shape[0]

    @cached_property
    def n_rows(self) -> int:
        return self.count + self.tangential.shape[0] * self.tangent_dim

    @property
    def has_friction(self) -> bool:
        return self.tangential.shape[0] > 0

    @cached_property
    def is_convex(self) -> bool:
        return not self.mask(ConeKind.UNION).any()

    @cached_property
    def present_kinds(self) -> frozenset[ConeKind]:
        """The kinds of at least one contact."""
        counts = np.bincount(self.kinds, minlength=len(ConeKind))
        return frozenset(_KINDS[k] for k in np.flatnonzero(counts).tolist())

    def same_as(self, other: Cones) -> bool:
        """Whether ``other`` holds the same force sets, bit for bit.

        The same kinds, coefficients, tangential rows (of the same dtype and shape) and tangent
        dimension: what the cached properties are derived from. Conservative: ``-0.0`` and
        ``0.0`` differ, as do the same rows in integers of another width."""
        return self.tangent_dim == other.tangent_dim and all(
            mine.dtype == theirs.dtype and mine.shape == theirs.shape and mine.tobytes() == theirs.tobytes()
            for mine, theirs in zip(self.arrays, other.arrays))

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(kinds, mu, tangential)``: the arrays the force sets are given by."""
        return self.kinds, self.mu, self.tangential

    def mask(self, kind: ConeKind) -> np.ndarray:
        """The contacts of ``kind``, shape (nc,) of bool.

        (Compared as a plain int: numpy compares an array with an ``IntEnum`` member 5x slower,
        2 us on a few contacts, which a small problem's solve paid several times.)
        """
        return self.kinds == int(kind)

    def split(self, forces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normal part (nc,) and tangential part (nt, tangent_dim) of a force vector."""
        nc = self.count
        return forces[:nc], forces[nc:].reshape(-1, self.tangent_dim)

    def join(self, normal: np.ndarray, tangential: np.ndarray) -> np.ndarray:
        return np.concatenate([normal, np.reshape(tangential, -1)])

    def pulled(self, forces: np.ndarray) -> np.ndarray:
        """The UNION contacts whose force lies on the pulled piece (``lam_n < 0``), shape (nc,)."""
        return self.mask(ConeKind.UNION) & (forces[: self.count] < 0)

    def with_branches(self, pulled: np.ndarray) -> Cones:
        """Convex cones with each UNION contact replaced by one of its pieces.

        Parameters
        ----------
        pulled : ndarray of bool, shape (nc,)
            True: the pulled piece (NONPOS); False: the pushed piece (COULOMB).
        """
        kinds = self.kinds.copy()
        union = self.mask(ConeKind.UNION)
        kinds[union & pulled] = ConeKind.NONPOS
        kinds[union & ~pulled] = ConeKind.COULOMB
        return Cones(kinds=kinds, mu=self.mu, tangential=self.tangential, tangent_dim=self.tangent_dim)

    @cached_property
    def projector(self) -> ConeProjector:
        """The projection with its index arrays prepared once (for iterative solvers)."""
        return ConeProjector(self)

    def project(self, forces: np.ndarray) -> np.ndarray:
        """Euclidean projection of ``forces`` onto the product of the force sets.

        For UNION contacts this is the nearer of the projections onto the two
        pieces (a projection onto a non-convex set, unique almost everywhere;
        ties go to the friction cone).
        """
        return self.projector(forces)

    def project_polar(self, forces: np.ndarray) -> np.ndarray:
        """Euclidean projection onto the polar cone ``K° = {y : y.x <= 0 for x in K}``.

        Computed from the polar sets themselves (R- for R+, {0} for R, R+ for
        R-, minus the dual cone ``{mu |t| <= n}`` for a friction cone), so that
        the Moreau decomposition ``x = P_K(x) + P_K°(x)`` is a real check.

        Raises
        ------
        ValueError
            If some contact is of the non-convex UNION kind.
        """
        self._require_convex()
        return self.projector.polar(forces)

    def natural_residual(self, forces: np.ndarray, gradient: np.ndarray,
                         project: Callable[[Cones, np.ndarray], np.ndarray] | None = None) -> float:
        """``|lam - P_K(lam - grad)|``, the natural-map residual (Euclidean norm).

        A UNION contact is measured on the piece its force lies on (pulled if
        ``lam_n < 0``, else pushed): stationarity on a union of convex sets is
        local, and the projection of ``lam - grad`` onto the whole union can
        jump to the other piece at a point that is optimal on its own.

        ``project(cones, x)``: ``P_K(x)`` for ``cones`` (convex here), where the caller has a
        faster one with the same floating-point operations (the solvers' compiled 2D projection,
        :func:`lubcontact.solvers.registry.solve`'s check); default :meth:`project`.
        """
        cones = self
        if not self.is_convex:
            cones = self.with_branches(self.pulled(forces))
        projected = cones.project(forces - gradient) if project is None else project(cones, forces - gradient)
        difference = forces - projected
        return float(np.sqrt(difference @ difference))      # np.linalg.norm's own sum, without its overhead

    def velocity_violation(self, constraint: np.ndarray) -> np.ndarray:
        """How far each contact's ``g_c`` lies outside ``K_c*`` (>= 0, length units).

        Parameters
        ----------
        constraint : ndarray, shape (n_rows,)
            ``g = D + s + dt H v`` laid out like a force vector.
        """
        g_n, g_t = self.split(constraint)
        violation = np.zeros(self.count)
        nonneg, nonpos, free = (self.mask(kind) for kind in (ConeKind.NONNEG, ConeKind.NONPOS,
                                                                ConeKind.FREE))
        violation[nonneg] = np.maximum(-g_n[nonneg], 0.0)
        violation[nonpos] = np.maximum(g_n[nonpos], 0.0)
        violation[free] = np.abs(g_n[free])
        if self.has_friction:
            idx = self.tangential
            cone = (self.mask(ConeKind.COULOMB) | self.mask(ConeKind.UNION))[idx]
            slip = self.mu[idx] * np.linalg.norm(g_t, axis=1)
            violation[idx[cone]] = np.maximum(slip[cone] - g_n[idx[cone]], 0.0)
        return violation

    # -- cvxpy ------------------------------------------------------------------------------
    def cvxpy_force_constraints(self, normal: Expression, tangential: Expression | None,
                                polyhedral: bool = False) -> list[Constraint]:
        """cvxpy constraints ``lam_c in K_c`` on expressions of the force components.

        Parameters
        ----------
        normal : cvxpy expression, shape (nc,)
        tangential : cvxpy expression, shape (nt * tangent_dim,) or None
        polyhedral : bool
            In 2D, write each friction cone as two half-planes (a QP) instead
            of a second-order cone.
        """
        import cvxpy as cp

        self._require_convex()
        constraints = []
        for kind, sense in ((ConeKind.NONNEG, 1.0), (ConeKind.NONPOS, -1.0)):
            rows = np.flatnonzero(self.mask(kind))
            if rows.size:
                constraints.append(sense * normal[rows] >= 0)
        if self.has_friction:
            coulomb = self.mask(ConeKind.COULOMB)[self.tangential]
            cone_contacts = self.tangential[coulomb]
            if cone_contacts.size:
                t_rows = self._tangent_rows(np.flatnonzero(coulomb))
                bound = cp.multiply(self.mu[cone_contacts], normal[cone_contacts])
                constraints += _cone_constraints(cp, bound, tangential, t_rows, self.tangent_dim, polyhedral)
                # with mu = 0 the cone only says lam_T = 0: lam_n >= 0 must be explicit
                degenerate = cone_contacts[self.mu[cone_contacts] == 0]
                if degenerate.size:
                    constraints.append(normal[degenerate] >= 0)
            zero_rows = self._tangent_rows(np.flatnonzero(~coulomb))
            if zero_rows.size:
                constraints.append(tangential[zero_rows.ravel()] == 0)
        return constraints

    def cvxpy_velocity_constraints(self, normal: Expression, tangential: Expression | None,
                                   polyhedral: bool = False) -> list[Constraint]:
        """cvxpy constraints ``g_c in K_c*`` on the primal's constraint expressions.

        Returns the constraints in the order ``[NONNEG, FREE, NONPOS, COULOMB]``
        (each present only when that kind occurs) so that
        :meth:`forces_from_duals` can read the multipliers back.
        """
        import cvxpy as cp

        self._require_convex()
        kinds = self.kinds
        constraints = []
        for kind in (ConeKind.NONNEG, ConeKind.FREE, ConeKind.NONPOS):
            rows = np.flatnonzero(kinds == kind)
            if rows.size:
                expr = normal[rows]
                constraints.append(expr >= 0 if kind == ConeKind.NONNEG else
                                   expr == 0 if kind == ConeKind.FREE else expr <= 0)
        coulomb = self._coulomb_positions()
        if coulomb.size:
            cone_contacts = self.tangential[coulomb]
            t_rows = self._tangent_rows(coulomb)
            constraints += _cone_constraints(cp, normal[cone_contacts], tangential, t_rows,
                                             self.tangent_dim, polyhedral, scale=self.mu[cone_contacts])
        return constraints

    def forces_from_duals(self, constraints: list, polyhedral: bool = False) -> np.ndarray:
        """Contact forces from the multipliers of :meth:`cvxpy_velocity_constraints`."""
        kinds = self.kinds
        normal = np.zeros(self.count)
        tangential = np.zeros((self.tangential.shape[0], self.tangent_dim))
        position = 0
        for kind, sign in ((ConeKind.NONNEG, 1.0), (ConeKind.FREE, -1.0), (ConeKind.NONPOS, -1.0)):
            rows = np.flatnonzero(kinds == kind)
            if rows.size:
                normal[rows] = sign * np.asarray(constraints[position].dual_value).ravel()
                position += 1
        coulomb = self._coulomb_positions()
        if coulomb.size:
            cone_contacts = self.tangential[coulomb]
            mu = self.mu[cone_contacts]
            if polyhedral:
                upper = np.asarray(constraints[position].dual_value).ravel()
                lower = np.asarray(constraints[position + 1].dual_value).ravel()
                normal[cone_contacts] = upper + lower
                tangential[coulomb, 0] = mu * (lower - upper)
            else:
                dual_t, dual_x = constraints[position].dual_value
                normal[cone_contacts] = np.ravel(dual_t)
                tangential[coulomb] = mu[:, None] * np.reshape(dual_x, (self.tangent_dim, -1)).T
        return self.join(normal, tangential)

    def _coulomb_positions(self) -> np.ndarray:
        if not self.has_friction:
            return np.zeros(0, dtype=int)
        return np.flatnonzero(self.mask(ConeKind.COULOMB)[self.tangential])

    def _tangent_rows(self, positions: np.ndarray) -> np.ndarray:
        """Row indices into the tangential block, shape (len(positions), tangent_dim)."""
        return positions[:, None] * self.tangent_dim + np.arange(self.tangent_dim)

    def _require_convex(self) -> None:
        if not self.is_convex:
            raise ValueError("cones.kinds: UNION contacts are not convex; fix a branch first "
                             "with Cones.with_branches")


def _cone_constraints(cp: ModuleType, bound: Expression, tangential: Expression, t_rows: np.ndarray,
                      tangent_dim: int, polyhedral: bool,
                      scale: np.ndarray | None = None) -> list[Constraint]:
    """``|scale * x_T| <= bound`` for each contact, as SOC or (2D) as two half-planes."""
    t_expr = tangential[t_rows.ravel()]
    if scale is not None:
        t_expr = cp.multiply(np.repeat(scale, tangent_dim), t_expr)
    if polyhedral:
        if tangent_dim != 1:
            raise ValueError(f"polyhedral: friction cones are polyhedral only in 2D, "
                             f"tangent_dim={tangent_dim}")
        return [bound - t_expr >= 0, bound + t_expr >= 0]
    return [cp.SOC(bound, cp.reshape(t_expr, (tangent_dim, -1), order="F"), axis=0)]


def _normal_bounds() -> np.ndarray:
    """Lower and upper bound (rows) of a contact's normal row, indexed by its :class:`ConeKind`,
    shape (2, 5): ``[0, inf)`` NONNEG, ``R`` FREE, ``(-inf, 0]`` NONPOS; ``R`` for the friction
    cones, whose rows :class:`ConeProjector` projects after the box."""
    bounds = np.array([np.full(len(ConeKind), -np.inf), np.full(len(ConeKind), np.inf)])
    bounds[0, ConeKind.NONNEG] = bounds[1, ConeKind.NONPOS] = 0.0
    bounds.flags.writeable = False
    return bounds


_NORMAL_BOUNDS = _normal_bounds()


class ConeProjector:
    """Projection onto a product of force sets, index arrays prepared once.

    Frictionless rows are a box (per-row bounds ``lower``, ``upper``: ``[0, inf)``,
    ``R``, ``(-inf, 0]``; tangential rows of frictionless contacts ``{0}``);
    friction contacts go through :func:`project_friction_cone`. No Python loop
    over contacts.

    Attributes
    ----------
    lower, upper : ndarray, shape (n_rows,)
        The box's bounds (a friction contact's rows get theirs from its cone).
    friction_normal, friction_tangent, friction_mu, friction_union : ndarray
        The friction contacts (COULOMB, then UNION, each kind in row order; a contact of
        another kind with tangential rows has no cone): normal rows (nf,),
        tangential rows (nf, tangent_dim), coefficients (nf,) and which are UNION (nf,) of
        bool. Solvers that loop over the contacts read them here rather than joining the pieces
        (read only: ``friction_normal`` is ``cones.tangential`` itself where all are COULOMB).
    planar_tangent : ndarray of int, shape (nf,)
        In 2D (``tangent_dim`` 1): each friction contact's one tangential row, as the 2D loops
        of newton-ac, APGD and Gauss-Seidel take them (``friction_tangent`` is a view of it);
        also where there is no friction contact (empty), as on a frictionless 3D problem, which
        those loops solve too. Absent on 3D problems with friction.
    pieces : list of tuple of ndarray
        The COULOMB and the UNION contacts' ``(normal rows, tangential rows, mu)``: views of
        the ``friction_`` arrays.
    """

    def __init__(self, cones: Cones):
        nc, dim_t = cones.count, cones.tangent_dim
        kinds = cones.kinds
        bounds = np.zeros((2, cones.n_rows))          # tangential rows: {0}
        bounds[:, :nc] = _NORMAL_BOUNDS[:, kinds]
        self.lower, self.upper = bounds
        tangential = cones.tangential if cones.has_friction else np.zeros(0, dtype=int)
        coulomb = kinds[tangential] == int(ConeKind.COULOMB)
        if coulomb.all():                 # the common case: every one COULOMB, in order
            split = coulomb.size
            positions = np.arange(split)
            self.friction_normal = tangential
        else:
            split = int(np.count_nonzero(coulomb))
            union = kinds[tangential] == int(ConeKind.UNION)
            positions = np.concatenate([np.flatnonzero(coulomb), np.flatnonzero(union)])
            self.friction_normal = tangential[positions]
        if dim_t == 1:
            self.planar_tangent = nc + positions
            self.friction_tangent = self.planar_tangent[:, None]
        else:
            self.friction_tangent = nc + positions[:, None] * dim_t + np.arange(dim_t)
            if not positions.size:          # no friction contact: a 2D loop has no row to read
                self.planar_tangent = positions
        self.friction_mu = cones.mu[self.friction_normal]
        self.friction_union = np.arange(positions.size) >= split
        self.pieces = [(self.friction_normal[:split], self.friction_tangent[:split],
                        self.friction_mu[:split]),
                       (self.friction_normal[split:], self.friction_tangent[split:],
                        self.friction_mu[split:])]

    @cached_property
    def box_rows(self) -> np.ndarray:
        """The rows in no friction cone (the box's rows), increasing, shape (n_box,)."""
        in_box = np.ones(self.lower.size, dtype=bool)
        for normal_rows, tangent_rows, _ in self.pieces:
            in_box[normal_rows] = in_box[tangent_rows] = False
        return np.flatnonzero(in_box)

    def __call__(self, forces: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``P_K(forces)``; ``out`` may be given to avoid an allocation (not ``forces``)."""
        out = np.maximum(forces, self.lower, out=out)     # np.clip costs 4x more on small vectors
        np.minimum(out, self.upper, out=out)
        (cone_n, cone_t, cone_mu), (union_n, union_t, union_mu) = self.pieces
        if cone_n.size:
            new_n, new_t = project_friction_cone(forces[cone_n], forces[cone_t], cone_mu)
            out[cone_n] = new_n
            out[cone_t] = new_t
        if union_n.size:
            normal, tangential = forces[union_n], forces[union_t]
            new_n, new_t = project_friction_cone(normal, tangential, union_mu)
            pull_n = np.minimum(normal, 0.0)
            d_cone = (new_n - normal) ** 2 + np.sum((new_t - tangential) ** 2, axis=1)
            d_pull = (pull_n - normal) ** 2 + np.sum(tangential**2, axis=1)
            take_cone = d_cone <= d_pull
            out[union_n] = np.where(take_cone, new_n, pull_n)
            out[union_t] = np.where(take_cone[:, None], new_t, 0.0)
        return out

    def polar(self, forces: np.ndarray) -> np.ndarray:
        """``P_K°(forces)`` for convex cones (see :meth:`Cones.project_polar`)."""
        # per row: polar of [0, inf) is (-inf, 0], of R is {0}, of (-inf, 0] is [0, inf), of {0} is R
        lower = np.where(self.lower == -np.inf, 0.0, -np.inf)
        upper = np.where(self.upper == np.inf, 0.0, np.inf)
        out = np.clip(forces, lower, upper)
        cone_n, cone_t, cone_mu = self.pieces[0]
        if cone_n.size:
            new_n, new_t = project_dual_friction_cone(-forces[cone_n], -forces[cone_t], cone_mu)
            out[cone_n] = -new_n
            out[cone_t] = -new_t
        return out
