"""The per-step contact problem (docs/guide/model.md section 4), independent of geometry.

Primal, over generalised velocities ``v`` (n_dof,)::

    min_v 1/2 (v - U)^T M (v - U)   s.t.  g_c(v) = (D_c + s_c + dt u_n,c, dt u_T,c) in K_c*

Dual, over contact forces ``lam`` (n_rows,)::

    min_lam 1/2 lam^T W lam + lam^T b   s.t. lam_c in K_c
    W = dt^2 H M^-1 H^T,  b = [D + s, 0] + dt H U,  v = U + dt M^-1 H^T lam

``H`` stacks the normal rows ``B`` (one per contact) and the tangential rows
``T`` (``tangent_dim`` per contact listed in ``cones.tangential``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from .. import checks
from .cones import Cones
from .conic import MATRICES, ConicProblem, ConicProblemMixin, Scaling


@dataclass
class StepProblem(ConicProblemMixin):
    """One time step's contact problem.

    Attributes
    ----------
    mass : ndarray, shape (n_dof,)
        Diagonal of ``M`` (masses, then inertias when rotations are modelled).
    free_velocity : ndarray, shape (n_dof,)
        ``U = v^k + dt M^-1 F_ext``.
    jacobian : scipy.sparse.csr_matrix, shape (n_rows, n_dof)
        ``H``: normal rows then tangential rows.
    gaps : ndarray, shape (nc,)
        ``D`` (length).
    cones : Cones
        Force set of each contact.
    dt : float
        Time step.
    shift : ndarray, shape (nc,)
        ``s`` of the fixed point on s (zeros for the convex relaxation).
    keys : ndarray of int64, shape (nc,) or None
        Pair identities, used only to match warm starts between steps.
    obstacle_offset : ndarray, shape (n_rows,) or None
        What obstacles moving at a prescribed velocity ``w`` add to ``g``:
        ``-dt (n . w, t . w)`` per contact (length); None (zeros) when every
        obstacle is at rest.
    """

    mass: np.ndarray
    free_velocity: np.ndarray
    jacobian: sp.csr_matrix
    gaps: np.ndarray
    cones: Cones
    dt: float
    shift: np.ndarray | None = None
    keys: np.ndarray | None = None
    scaling: Scaling | None = field(default=None, repr=False)
    obstacle_offset: np.ndarray | None = None

    def __post_init__(self):
        self.dt = checks.positive_scalar("dt", self.dt)
        n_dof = self.mass.shape[0]
        checks.positive("mass", self.mass, shape=(n_dof,))
        checks.as_array("free_velocity", self.free_velocity, shape=(n_dof,))
        checks.as_array("gaps", self.gaps, shape=(self.cones.count,))
        checks.require(self.jacobian.shape == (self.cones.n_rows, n_dof), "jacobian",
                       f"expected shape {(self.cones.n_rows, n_dof)}", self.jacobian.shape)
        if self.shift is None:
            self.shift = np.zeros(self.cones.count)
        checks.as_array("shift", self.shift, shape=(self.cones.count,))
        if self.obstacle_offset is not None:
            checks.as_array("obstacle_offset", self.obstacle_offset, shape=(self.cones.n_rows,))
        if not isinstance(self.jacobian, sp.csr_matrix):   # a CSR matrix is kept, not re-wrapped
            self.jacobian = sp.csr_matrix(self.jacobian)

    @property
    def n_dof(self) -> int:
        return self.mass.shape[0]

    @property
    def delassus_rank_bound(self) -> int:
        """An upper bound on the rank of ``W = dt^2 H M^-1 H^T``: ``min(n_dof, n_rows)``. A
        packing with more contact rows than degrees of freedom (a pile at rest, hyperstatic)
        has a singular ``W``."""
        return min(self.n_dof, self.n_rows)

    @cached_property
    def jacobian_transpose(self) -> sp.csc_matrix:
        """``H^T`` (n_dof x n_rows) in CSC form, sharing ``H``'s arrays: the products ``H^T lam``."""
        return self.jacobian.T

    @cached_property
    def delassus_factor(self) -> sp.csr_matrix:
        """``L = dt M^-1/2 H^T`` (n_dof x n_rows), so that ``W = L^T L``."""
        weight = self._factor_weight
        transpose = self.jacobian_transpose.tocsr()
        factor = transpose if weight is None else diagonal_scaled(transpose, rows=weight)
        factor.sum_duplicates()        # a Jacobian given with duplicate entries: one per position
        return factor

    @cached_property
    def delassus_factor_transpose(self) -> sp.csr_matrix:
        """``L^T = dt H M^-1/2`` (n_rows x n_dof) in CSR form: ``H``'s columns scaled, ``H``
        itself on a normalised problem (no transposition)."""
        weight = self._factor_weight
        return self.jacobian if weight is None else diagonal_scaled(self.jacobian, columns=weight)

    @cached_property
    def delassus(self) -> sp.csr_matrix:
        """``W = dt^2 H M^-1 H^T`` (sparse, n_rows x n_rows), as the product of the CSR forms of
        ``L^T`` and ``L`` (no conversion)."""
        return sp.csr_matrix(self.delassus_factor_transpose @ self.delassus_factor)

    @cached_property
    def dense_jacobian(self) -> tuple[np.ndarray, np.ndarray]:
        """``H`` on the degrees of freedom its rows involve, as a dense block, for small problems.

        Only those columns: a scene of many grains with few contacts (a pile forming) has
        ``n_dof`` far above ``n_rows``, and making the whole ``H`` dense made
        :attr:`dense_delassus` 10-60x slower than the sparse ``W`` (100 rows, 6 000 degrees of
        freedom: 1.9 ms, 31.6 on a first call, against 0.16 ms; 0.36 ms on the involved
        columns). Once built (by :attr:`dense_delassus`, which the solvers'
        dense lane of small problems asks for: ``DENSE_OPERATOR_LIMIT`` in
        :mod:`lubcontact.solvers.dual_data`), the products with ``H`` (:attr:`offset`,
        :meth:`velocity`, :meth:`constraint_values`, :meth:`gaps_after`) use it: on such sizes
        a sparse product or transpose costs more in fixed cost than the dense one in arithmetic.
        A normalised problem scales its source's block (which the source keeps) without
        building its own sparse ``H`` (:meth:`normalized`). Compiled:
        :func:`~lubcontact.problem.dense_forms.dense_rows`.

        Returns
        -------
        (ndarray of int, ndarray)
            ``columns``, shape (k,), sorted, and ``block = H[:, columns]``, shape (n_rows, k)
            (entries stored twice are summed).
        """
        source = self.__dict__.get("_jacobian_source")
        if source is not None:
            problem, factors = source
            columns, block = problem.dense_jacobian
            return columns, block * factors[columns]
        from .dense_forms import dense_rows  # numba, imported on first use

        jacobian = self.jacobian
        return dense_rows(jacobian.indptr, jacobian.indices, jacobian.data, self.n_dof)

    @cached_property
    def dense_delassus(self) -> np.ndarray:
        """``W`` as a dense array, shape (n_rows, n_rows), from the dense Jacobian
        (:attr:`dense_jacobian`) summed over its nonzeros
        (:func:`~lubcontact.problem.dense_forms.weighted_gram`), for small problems, where the
        sparse products' fixed cost is most of a solve's set-up."""
        from .dense_forms import weighted_gram  # numba, imported on first use

        columns, block = self.dense_jacobian
        weight = self._factor_weight
        return weighted_gram(block, np.ones(columns.size) if weight is None else weight[columns])

    def _jacobian_product(self, vector: np.ndarray) -> np.ndarray:
        """``H x``, shape (n_rows,), from :attr:`dense_jacobian` once it is built."""
        dense = self.__dict__.get("dense_jacobian")
        if dense is None:
            return self.jacobian @ vector
        columns, block = dense
        return block @ vector[columns]

    def _transpose_product(self, forces: np.ndarray) -> np.ndarray:
        """``H^T lam``, shape (n_dof,), from :attr:`dense_jacobian` once it is built."""
        dense = self.__dict__.get("dense_jacobian")
        if dense is None:
            return self.jacobian_transpose @ forces
        columns, block = dense
        out = np.zeros(self.n_dof)
        out[columns] = forces @ block
        return out

    @cached_property
    def _factor_weight(self) -> np.ndarray | None:
        """``dt M^-1/2`` per degree of freedom, None where it is 1 (a normalised problem)."""
        weight = self.dt / np.sqrt(self.mass)
        return None if np.all(weight == 1.0) else weight

    @property
    def constant_rows(self) -> np.ndarray:
        """``[D + s, 0]`` (plus the moving obstacles' offset): the part of ``g`` that does not
        depend on ``v``."""
        out = np.zeros(self.n_rows) if self.obstacle_offset is None else self.obstacle_offset.copy()
        out[: self.n_contacts] += self.gaps + self.shift
        return out

    @cached_property
    def offset(self) -> np.ndarray:
        """``b = [D + s, 0] + dt H U``."""
        return self.constant_rows + self.dt * self._jacobian_product(self.free_velocity)

    def velocity(self, forces: np.ndarray) -> np.ndarray:
        """``v = U + dt M^-1 H^T lam``."""
        return self.free_velocity + self.dt * self._transpose_product(forces) / self.mass

    def constraint_values(self, velocity: np.ndarray) -> np.ndarray:
        """``g = [D + s, 0] + dt H v``, laid out like a force vector."""
        return self.constant_rows + self.dt * self._jacobian_product(velocity)

    def gradient(self, forces: np.ndarray) -> np.ndarray:
        """Gradient of the dual objective, ``W lam + b`` (equal to ``g(v(lam))``)."""
        return self.constraint_values(self.velocity(forces))

    def dual_objective(self, forces: np.ndarray) -> float:
        return float(0.5 * forces @ (self.gradient(forces) - self.offset) + forces @ self.offset)

    def gaps_after(self, velocity: np.ndarray) -> np.ndarray:
        """Gaps after the step, ``D + dt u_n`` (without the shift; ``u_n`` relative to a moving
        obstacle), shape (nc,)."""
        gaps = self.gaps + self.dt * self._jacobian_product(velocity)[: self.n_contacts]
        if self.obstacle_offset is not None:
            gaps += self.obstacle_offset[: self.n_contacts]
        return gaps

    def normalized(self, dense: bool = False) -> StepProblem:
        """The same problem in scaled units: ``M = I``, ``dt = 1``, velocities O(1).

        With a velocity scale ``V`` (the mass-weighted rms of ``U``), each
        velocity component is divided by ``S_i = V sqrt(m_ref / M_i)``, lengths
        by ``dt V`` and forces by ``m_ref V / dt`` (``m_ref`` = mean of ``M``).
        The returned problem carries the :class:`Scaling` that maps back. Its sparse
        Jacobian is built on first use only (:meth:`__getattr__`): one convex solve of a small
        problem by a method of the solvers' dense lane uses the dense one
        (:attr:`dense_jacobian`) and never asks for it (the fixed point on s builds it once,
        for the methods that use the sparse ``W``).

        With ``dense``, where this problem holds no dense Jacobian (and is not itself a normalised
        problem), the normalised problem's dense forms (:attr:`dense_jacobian`,
        :attr:`dense_delassus`) are built now, the same arrays, in one compiled call
        (:func:`~lubcontact.problem.dense_forms.scaled_forms`) that leaves nothing cached on this
        problem: for a small solve that knows it takes the dense lane (elsewhere they are built
        on first use, as without ``dense``).
        """
        n_dof = self.n_dof                 # means as sum / n: np.mean's own overhead is 2 us each
        m_ref = float(self.mass.sum() / n_dof) if n_dof else 1.0
        speed = float(np.sqrt((self.mass * self.free_velocity**2).sum() / n_dof / m_ref)) if n_dof else 0.0
        if not speed > 0:
            positive = np.abs(self.gaps[self.gaps != 0])
            speed = float(np.median(positive)) / self.dt if positive.size else 1.0
        velocity_scale = speed * np.sqrt(m_ref / self.mass)
        length = self.dt * speed
        scaling = Scaling(velocity=velocity_scale, force=m_ref * speed / self.dt, length=length)
        factors = velocity_scale / speed
        scaled = StepProblem._derived(mass=np.ones(self.n_dof),
                                      free_velocity=self.free_velocity / velocity_scale,
                                      _jacobian_source=(self, factors),
                                      gaps=self.gaps / length, cones=self.cones,
                                      dt=1.0, shift=self.shift / length, keys=self.keys,
                                      scaling=scaling, _factor_weight=None,   # M = I, dt = 1
                                      obstacle_offset=None if self.obstacle_offset is None
                                      else self.obstacle_offset / length)
        if dense and "dense_jacobian" not in self.__dict__ and "_jacobian_source" not in self.__dict__:
            from .dense_forms import scaled_forms  # numba, imported on first use

            jacobian = self.jacobian
            columns, block, delassus = scaled_forms(jacobian.indptr, jacobian.indices,
                                                    jacobian.data, n_dof, factors)
            scaled.__dict__.update(dense_jacobian=(columns, block), dense_delassus=delassus)
        return scaled

    @classmethod
    def _derived(cls, **fields: Any) -> StepProblem:
        """A problem whose every field is derived from a checked problem (its scaled copy), built
        without :meth:`__post_init__`'s checks: on small problems they cost as much as the
        solve's products."""
        problem = object.__new__(cls)
        problem.__dict__.update(fields)
        return problem

    def keep_matrices(self, copy: ConicProblem) -> None:
        """:meth:`ConicProblemMixin.keep_matrices`, and the Jacobian of a normalised problem once
        ``copy`` has built it (:meth:`__getattr__`): later copies then share it instead of each
        scaling ``H`` again."""
        super().keep_matrices(copy)
        if "jacobian" in copy.__dict__:
            self.__dict__.setdefault("jacobian", copy.__dict__["jacobian"])

    def _replaced(self, **changes: Any) -> StepProblem:
        """The copy :meth:`with_shift` and :meth:`with_cones` make, without the constructor: this
        checked problem's fields and cached matrices (``MATRICES``), the unbuilt Jacobian of a
        normalised problem included, with ``changes`` (``shift`` or ``cones``) checked here."""
        if "shift" in changes:
            changes["shift"] = checks.as_array("shift", changes["shift"], shape=(self.n_contacts,))
        if "cones" in changes:
            checks.require(changes["cones"].count == self.n_contacts, "cones",
                           "must keep the contacts", changes["cones"].count)
        kept = {name: value for name, value in self.__dict__.items() if name in _SHARED_BY_COPIES}
        return StepProblem._derived(**{**kept, **changes})

    def __getattr__(self, name: str) -> Any:
        """The Jacobian of a normalised problem, built on first use: ``H`` of the source problem
        with its columns scaled (:meth:`normalized` leaves it as ``_jacobian_source``).

        Any other missing attribute raises ``AttributeError`` naming it; as with every
        ``__getattr__``, an ``AttributeError`` raised inside one of the class's properties
        surfaces as that property missing.
        """
        source = self.__dict__.get("_jacobian_source")
        if name != "jacobian" or source is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        problem, columns = source
        self.jacobian = diagonal_scaled(problem.jacobian, columns=columns)
        return self.jacobian

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Plain arrays describing the problem (for ``np.savez``); see :meth:`from_arrays`."""
        h = self.jacobian
        arrays = dict(mass=self.mass, free_velocity=self.free_velocity, gaps=self.gaps,
                      shift=self.shift, dt=np.array(self.dt), h_data=h.data, h_indices=h.indices,
                      h_indptr=h.indptr, h_shape=np.array(h.shape), cone_kinds=self.cones.kinds,
                      cone_mu=self.cones.mu, cone_tangential=self.cones.tangential,
                      tangent_dim=np.array(self.cones.tangent_dim))
        for name in ("keys", "obstacle_offset"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> StepProblem:
        """Rebuild a problem written by :meth:`to_arrays` (a dict or an ``NpzFile``)."""
        jacobian = sp.csr_matrix((arrays["h_data"], arrays["h_indices"], arrays["h_indptr"]),
                                 shape=tuple(arrays["h_shape"]))
        cones = Cones(kinds=np.asarray(arrays["cone_kinds"], dtype=np.int8), mu=arrays["cone_mu"],
                      tangential=np.asarray(arrays["cone_tangential"], dtype=int),
                      tangent_dim=int(arrays["tangent_dim"]))
        optional = {name: arrays[name] for name in ("keys", "obstacle_offset") if name in arrays}
        return cls(mass=arrays["mass"], free_velocity=arrays["free_velocity"], jacobian=jacobian,
                   gaps=arrays["gaps"], cones=cones, dt=float(arrays["dt"]), shift=arrays["shift"],
                   **optional)


_SHARED_BY_COPIES = frozenset({f.name for f in fields(StepProblem)} | set(MATRICES)
                              | {"_jacobian_source"})
"""What a copy with another shift or other cones keeps (:meth:`StepProblem._replaced`): the
fields, the cached matrices, which depend on neither, and a normalised problem's unbuilt
Jacobian; not ``offset``, which depends on the shift."""


def diagonal_scaled(matrix: sp.csr_matrix, rows: np.ndarray | None = None,
                    columns: np.ndarray | None = None) -> sp.csr_matrix:
    """``diag(rows) @ matrix @ diag(columns)`` for a CSR ``matrix``, by scaling its stored values.

    Parameters
    ----------
    matrix : scipy.sparse.csr_matrix, shape (m, n)
    rows : ndarray, shape (m,), optional
        Row factors (none when None).
    columns : ndarray, shape (n,), optional
        Column factors (none when None).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (m, n)
        The pattern of ``matrix`` (index arrays copied) with each value
        ``(rows_i * value) * columns_j``, as the sparse products compute it,
        and explicit zeros dropped, as they drop them. No sparse product (for
        small problems, their fixed cost dominates).
    """
    values = matrix.data.copy()          # never the input's own array (eliminate_zeros compacts it)
    if rows is not None:
        values = np.repeat(rows, np.diff(matrix.indptr)) * values
    if columns is not None:
        values = values * columns[matrix.indices]
    out = sp.csr_matrix((values, matrix.indices.copy(), matrix.indptr.copy()), shape=matrix.shape)
    if not np.all(values):
        out.eliminate_zeros()
    return out
