"""The dual problem ``min 1/2 x.Wx + b.x, x in K`` as the gradient methods iterate on it.

:func:`prepare` builds the :class:`DualData` of a normalised problem (scaled
operator, offset, projection); :class:`ResidualTracker` applies the stopping
rule and keeps the best iterate; :func:`initial_point`, :func:`largest_eigenvalue`
and :func:`initial_lipschitz` start the loops of :mod:`.gradient_loops` and
:mod:`.compiled_apgd`.

Scaling and stopping rule
-------------------------
Jacobi scaling: each contact gets one factor ``s_c = 1 / sqrt(mean of the
diagonal of W over the contact's rows)`` (one per contact, so that every
cone is mapped onto itself), and the scaled variables ``y = x / s`` see
``W' = S W S`` with a unit diagonal (a unit mean diagonal per friction
contact) and ``b' = S b``. ``y`` has the units of a velocity.

All methods stop on the same measure, the Jacobi-scaled natural-map residual
in rms form::

    r(x) = |y - P_K(y - (W' y + b'))|_2 / sqrt(n_rows),     y = x / s

which, on a normalised problem (velocities O(1)), is a velocity in units of
the free velocity: ``r <= tol`` stops with status ``converged``. The method
returns the iterate with the smallest ``r`` seen (the best iterate).
A stopping rule is not an accuracy: see :mod:`.active_set` for the exact
finish of frictionless problems.

Operator
--------
``W x`` is applied either from the assembled sparse W (``operator="matrix"``)
or matrix-free as ``L^T (L x)`` (``operator="factor"``). Measured on the
10^4-grain frictionless pile (docs/records/benchmarks.md) both cost about the same per
product (0.25 ms vs 0.22 ms with a CSR copy of ``L^T``); on a developed
frictional flow, where each contact shares a grain with many others, the
matrix-free product costs half (3200 grains: 104 against 230 us in the
compiled loops). With ``"auto"`` the matrix-free product is used whenever the
factor exists; which methods assemble ``S W S`` instead is said in
:mod:`.gradient`. A small problem (at most :data:`DENSE_OPERATOR_LIMIT` rows)
with ``"auto"`` gets ``S W S`` dense instead, from the problem's dense ``W``
(one BLAS product): below ~100 contacts the sparse set-up, not the
iterations, was most of a solve (``lubcontact bench small``).
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..problem.cones import Cones
from ..problem.conic import ConicProblem
from ..problem.step import diagonal_scaled
from .result import CONVERGED, DIVERGED

DIVERGENCE_FACTOR = 1e12
"""A residual above this factor times ``max(first residual, 1)`` stops a loop as ``diverged``."""
DENSE_LIMIT = 300
"""Size up to which the direct solves of the fast methods are dense (LAPACK LU): the active
block of a Newton system (its active rows), and the exact finish's ``W`` (all its rows, kept
dense for the solve's attempts). A dense LU of 100-250 rows costs a fraction of a sparse
factorisation's set-up (measured: 0.6 ms per SuperLU factorisation of 122 rows). It is also
the size up to which ``newton-ac`` treats a 2D problem as a small system's (its rules:
``AlartCurnier.small`` in :mod:`.newton`); its compiled lane goes on to ``COMPILED_LIMIT``
rows there."""
DENSE_OPERATOR_LIMIT = 128
"""Rows up to which :func:`prepare` builds ``W_it`` from the problem's dense ``W``
(``dense_delassus``, one BLAS product) and applies it as a dense product, and ``nsgs`` and
``newton-ac`` (in 2D up to its ``COMPILED_LIMIT``) work on the dense ``W``: on such sizes the
sparse set-up (transposes, products, scaled copies; about 10 us of fixed cost each) was most
of a warm-started solve (a 59-row step: 230 of 675 us). The dense product costs ``n_rows^2
n_dof``: on settling piles (tol 1e-8, same problem, same process) ``apgd-jacobi`` gained 5-20 %
up to 93 rows, was even at 128 and lost 20-70 % from 136 rows on; ``newton-ac`` (numpy, before
its compiled lane) gained 1.5-1.7x up to 136 rows, 1.3x at 178 and lost at 238."""


@dataclass
class DualData:
    """The dual problem in the iteration variables ``z = x / s_it``.

    Attributes
    ----------
    apply : callable
        ``z -> W_it z`` with ``W_it = S_it W S_it``.
    offset : ndarray, shape (n,)
        ``b_it = S_it b``.
    scale : ndarray, shape (n,)
        ``s_it`` (ones without scaling).
    jacobi : ndarray, shape (n,)
        Jacobi scale ``s`` of the stopping measure.
    project : callable
        Projection onto K (invariant under the per-contact scaling).
    matrix : scipy.sparse matrix or None
        ``W_it`` when assembled (None with the matrix-free operator until
        :meth:`assembled` is called).
    factor : scipy.sparse matrix or None
        ``L S_it`` (``W_it = (L S_it)^T (L S_it)``) for the matrix-free operator.
    factor_transpose : scipy.sparse.csr_matrix or None
        ``(L S_it)^T`` in CSR form, built once with ``factor`` (its rows are the second
        product of the matrix-free operator, here and in the compiled loops).
    dense : ndarray, shape (n, n), or None
        ``W_it`` as a dense array on small problems (:data:`DENSE_OPERATOR_LIMIT`), where
        ``apply`` is its dense product; its sparse form is then built on demand only
        (:meth:`sparse_arrays`, :meth:`assembled`).
    products : int
        Products ``W z`` done so far.
    ratio : ndarray, shape (n,)
        ``s_it / s``: maps ``z`` to the Jacobi-scaled variables of the stopping measure.
    """

    apply: Callable[[np.ndarray], np.ndarray]
    offset: np.ndarray
    scale: np.ndarray
    jacobi: np.ndarray
    project: Callable
    matrix: sp.spmatrix | None = None
    factor: sp.spmatrix | None = None
    factor_transpose: sp.csr_matrix | None = None
    dense: np.ndarray | None = None
    products: int = 0
    ratio: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._arrays = None
        self.ratio = self.scale / self.jacobi
        self._rms = 1.0 / np.sqrt(max(self.offset.size, 1))

    def product(self, z: np.ndarray) -> np.ndarray:
        """``W_it z``, shape (n,), counted in :attr:`products`."""
        self.products += 1
        return self.apply(z)

    def residual(self, z: np.ndarray, gradient: np.ndarray) -> float:
        """The stopping measure ``r`` (module docstring) at ``z`` with gradient ``W_it z + b_it``."""
        y = z * self.ratio
        return float(np.linalg.norm(y - self.project(y - gradient / self.ratio)) * self._rms)

    def objective(self, z: np.ndarray, product: np.ndarray) -> float:
        """``1/2 z.W_it z + b_it.z``, with ``product = W_it z``."""
        return float(0.5 * z @ product + self.offset @ z)

    def assembled(self) -> sp.csr_matrix:
        """``W_it`` as a sparse matrix, assembled from the factor (or the dense ``W_it``) on first
        use."""
        if self.matrix is None:
            if self.dense is None:
                self.matrix = sp.csr_matrix(self.factor_transpose @ self.factor)
            else:
                indptr, indices, values = self.sparse_arrays()
                self.matrix = sp.csr_matrix((values, indices, indptr), shape=self.dense.shape)
        return self.matrix

    def sparse_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(indptr, indices, data)`` of ``W_it`` in CSR form (what the compiled loops read); on
        a small problem from the dense ``W_it`` directly (its nonzeros: the sparse product's
        pattern), without a sparse matrix object."""
        if self.dense is None:
            matrix = self.assembled()
            return matrix.indptr, matrix.indices, matrix.data
        if self._arrays is None:
            self._arrays = dense_csr_arrays(self.dense)
        return self._arrays


def is_small(problem: ConicProblem) -> bool:
    """Whether ``problem`` takes the dense lane (at most :data:`DENSE_OPERATOR_LIMIT` rows): the
    rule :func:`prepare`, ``nsgs`` and ``newton-ac`` follow (``newton-ac`` takes 2D problems
    of up to its ``COMPILED_LIMIT`` rows to its compiled lane)."""
    return problem.n_rows <= DENSE_OPERATOR_LIMIT


_GETRF, _GETRS = sla.get_lapack_funcs(("getrf", "getrs"), dtype=np.float64)


def dense_lu(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """LU factors of a small square matrix by LAPACK's ``getrf`` (``matrix`` may be overwritten:
    pass a copy), or None when a pivot is exactly zero: scipy's ``lu_factor``/``lu_solve`` wrappers (and
    their warning) cost more than factorising a block of a few tens of rows."""
    lu, pivots, info = _GETRF(matrix, overwrite_a=True)
    return None if info != 0 else (lu, pivots)


def dense_lu_solve(factors: tuple[np.ndarray, np.ndarray], rhs: np.ndarray) -> np.ndarray:
    """``A x = rhs`` with the factors of :func:`dense_lu`."""
    return _GETRS(*factors, rhs)[0]


def dense_csr_arrays(dense: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of a dense matrix's nonzeros in CSR form (rows in order,
    columns sorted), without a sparse matrix object.

    Parameters
    ----------
    dense : ndarray, shape (m, n)
    """
    rows, columns = np.nonzero(dense)
    return np.searchsorted(rows, np.arange(dense.shape[0] + 1)), columns, dense[rows, columns]


def jacobi_scale(problem: ConicProblem, diagonal: np.ndarray | None = None) -> np.ndarray:
    """Per-row scale ``s``, constant over each contact's rows (see module docstring).

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem (``delassus`` or ``delassus_factor``, ``cones``).
    diagonal : ndarray, shape (n_rows,), optional
        The diagonal of ``W`` when the caller has it (else read from the factor or ``W``).

    Returns
    -------
    ndarray, shape (n_rows,)
        ``s = 1 / sqrt(mean diagonal of W over the contact's rows)`` (1 where that mean is 0).
    """
    cones = problem.cones
    if diagonal is None:
        factor = problem.delassus_factor
        diagonal = np.asarray(problem.delassus.diagonal()) if factor is None \
            else np.bincount(factor.indices, weights=factor.data**2, minlength=problem.n_rows)
    if not cones.has_friction:                   # one row per contact
        return 1.0 / np.sqrt(np.where(diagonal > 0, diagonal, 1.0))
    nc = cones.count
    total = diagonal[:nc].copy()
    count = np.ones(nc)
    tangent = diagonal[nc:].reshape(-1, cones.tangent_dim)
    total[cones.tangential] += tangent.sum(axis=1)     # each contact listed once
    count[cones.tangential] += cones.tangent_dim
    mean = total / count
    per_contact = 1.0 / np.sqrt(np.where(mean > 0, mean, 1.0))
    scale = np.empty(problem.n_rows)
    scale[:nc] = per_contact
    scale[nc:] = np.repeat(per_contact[cones.tangential], cones.tangent_dim)
    return scale


def prepare(problem: ConicProblem, scaling: bool, operator: str = "auto",
            assembled: bool = False) -> DualData:
    """Build the iteration data of a (normalised) problem.

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem with ``n_rows`` rows.
    scaling : bool
        Iterate on the Jacobi-scaled problem.
    operator : {"auto", "matrix", "factor"}
        How ``W z`` is applied (module docstring). With ``"auto"``, a problem of at most
        :data:`DENSE_OPERATOR_LIMIT` rows gets a dense ``W_it`` (``DualData.dense``);
        ``"matrix"`` always assembles it sparse.
    assembled : bool
        The caller needs ``W_it`` assembled (a compiled box loop, an exact finish): a sparse
        ``W_it`` unless the problem is small and ``operator`` is ``"auto"``.

    Returns
    -------
    DualData
        Its vectors have shape (n_rows,).

    Raises
    ------
    ValueError
        For an unknown ``operator``, or ``"factor"`` on a problem without ``delassus_factor``.
    """
    if operator not in ("auto", "matrix", "factor"):
        raise ValueError(f"operator: must be 'auto', 'matrix' or 'factor', got {operator!r}")
    if operator == "auto" and is_small(problem):
        return _prepare_dense(problem, scaling)
    if assembled:
        operator = "matrix"
    has_factor = problem.delassus_factor is not None
    if operator == "factor" and not has_factor:
        raise ValueError("operator: 'factor' needs a problem with delassus_factor")
    jacobi = jacobi_scale(problem)
    scale = jacobi if scaling else np.ones(problem.n_rows)
    offset = scale * problem.offset
    if has_factor and operator != "matrix":
        factor = diagonal_scaled(problem.delassus_factor, columns=scale)
        transposed = diagonal_scaled(problem.delassus_factor_transpose, rows=scale)
        return DualData(apply=lambda z: transposed @ (factor @ z), offset=offset, scale=scale,
                        jacobi=jacobi, project=problem.cones.projector, factor=factor,
                        factor_transpose=transposed)
    # S W S from the problem's W (assembled once per problem, kept by its copies with
    # another shift): no sparse product here
    matrix = diagonal_scaled(problem.delassus, scale, scale) if scaling else problem.delassus
    return DualData(apply=matrix.dot, offset=offset, scale=scale, jacobi=jacobi,
                    project=problem.cones.projector, matrix=matrix)


def _prepare_dense(problem: ConicProblem, scaling: bool) -> DualData:
    """:func:`prepare` on a small problem: ``W_it = S W S`` from the dense ``W``, applied densely
    (:meth:`DualData.sparse_arrays` gives the compiled loops its CSR arrays)."""
    delassus = problem.dense_delassus
    jacobi = jacobi_scale(problem, np.diag(delassus))
    scale = jacobi if scaling else np.ones(problem.n_rows)
    dense = delassus * np.outer(scale, scale) if scaling else delassus
    return DualData(apply=dense.dot, offset=scale * problem.offset, scale=scale, jacobi=jacobi,
                    project=problem.cones.projector, dense=dense)


@dataclass
class ResidualTracker:
    """Best iterate, residual history and the stopping decision.

    Attributes
    ----------
    data : DualData
        The problem iterated on (its :meth:`~DualData.residual` is the measure).
    tol : float
        ``converged`` once the residual is ``<= tol``.
    best : ndarray, shape (n,), or None
        The iterate with the smallest residual recorded (None before the first).
    best_residual : float
        Its residual.
    first : float or None
        The first residual recorded (the scale of the divergence test).
    history : list of float
        Every residual recorded.
    """

    data: DualData
    tol: float
    best: np.ndarray = None
    best_residual: float = np.inf
    first: float | None = None
    history: list = field(default_factory=list)

    def record(self, z: np.ndarray, gradient: np.ndarray) -> str | None:
        """Record ``z``; return ``converged``/``diverged`` to stop, else None."""
        residual = self.data.residual(z, gradient)
        self.history.append(residual)
        if self.first is None:
            self.first = residual
        if residual < self.best_residual:
            self.best_residual, self.best = residual, z.copy()
        if residual <= self.tol:
            return CONVERGED
        if not np.isfinite(residual) or residual > DIVERGENCE_FACTOR * max(self.first, 1.0):
            return DIVERGED
        return None


def initial_point(data: DualData, warm_start: np.ndarray | None, cones: Cones) -> np.ndarray:
    """The starting iterate: zero, or the warm start in iteration variables, projected onto K;
    on convex cones only when its objective ``1/2 z.W_it z + b_it.z`` is not above zero's (0).

    A developed flow renews its force network every step: on dry flows from 2 000 to 10^5
    grains the previous step's forces, matched by pair, were worse than zero in the objective
    on every step measured, and `apgd-jacobi` from zero took 8-20 % fewer iterations per step
    (docs/records/benchmarks.md); a warm start near the solution (a pile at rest; usually the
    fixed point's next inner solve, whose new shift may move the objective) has a negative
    objective and is kept. With UNION contacts K is not convex and the warm start also picks
    each contact's piece (pushed or pulled): it is always kept (from zero, `apgd` ended a
    step of a 12 000-grain gluey flow's relaxation at `max_iter`, where the warm start
    converged in 664 iterations). The fixed point on s fixes each UNION contact on a piece
    (convex cones), so its inner solves apply the test. The test costs one product ``W_it z``,
    counted in ``data.products``.

    Parameters
    ----------
    data : DualData
    warm_start : ndarray, shape (n_rows,), or None
        Forces of the normalised problem.
    cones : Cones
        The problem's cones.

    Returns
    -------
    ndarray, shape (n_rows,)
    """
    if warm_start is None:
        return np.zeros(cones.n_rows)
    z = data.project(np.asarray(warm_start, dtype=float) / data.scale)
    if cones.is_convex and 0.5 * (z @ data.product(z)) + data.offset @ z > 0.0:
        return np.zeros(cones.n_rows)
    return z


def largest_eigenvalue(data: DualData, n: int, iterations: int) -> float:
    """Largest eigenvalue of ``W_it`` by power iteration (deterministic start).

    Parameters
    ----------
    data : DualData
        Operator of shape (n, n).
    n : int
        Number of rows.
    iterations : int
        Power iterations (products ``W_it v``).

    Returns
    -------
    float
        The estimate (1.0 when a product vanishes).
    """
    vector = _uniform(0.5, 1.5, n)
    value = 1.0
    for _ in range(iterations):
        image = data.product(vector)
        value = float(np.linalg.norm(image))
        if value == 0.0:
            return 1.0
        vector = image / value
    return value


def initial_lipschitz(data: DualData, z: np.ndarray, product: np.ndarray | None = None) -> float:
    """Starting Lipschitz estimate of the APGD loops: ``|W d| / |d|`` for a
    deterministic random ``d`` (the loops' backtracking corrects it).

    Parameters
    ----------
    data : DualData
    z : ndarray, shape (n,)
        The starting iterate.
    product : ndarray, shape (n,), optional
        ``W_it z`` when already computed.

    Returns
    -------
    float
        The estimate, at least 1e-12.
    """
    product = data.product(z) if product is None else product
    probe = z + _uniform(-1.0, 1.0, z.size)
    return max(float(np.linalg.norm(data.product(probe) - product) /
                     np.linalg.norm(probe - z)), 1e-12)


@functools.lru_cache(maxsize=16)
def _uniform(low: float, high: float, n: int) -> np.ndarray:
    """``np.random.default_rng(0).uniform(low, high, n)``, read-only, drawn once per size
    (a generator costs more than a small solve's products)."""
    vector = np.random.default_rng(0).uniform(low, high, n)
    vector.flags.writeable = False
    return vector
