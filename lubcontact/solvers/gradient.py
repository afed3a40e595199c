"""Projected-gradient methods on the dual problem ``min 1/2 x.Wx + b.x, x in K``.

Registered names:

- ``pgd``: projected gradient, fixed step ``1 / L`` (``L`` from power iteration);
- ``apgd``: accelerated projected gradient (Nesterov) with gradient-based
  adaptive restart and a backtracking Lipschitz estimate (Mazhar et al. 2015);
- ``bb``: spectral projected gradient (alternating Barzilai-Borwein steps,
  non-monotone line search, exact along the search direction since the
  objective is quadratic);
- ``apgd-jacobi``: ``apgd`` on the Jacobi-scaled problem;
- ``apgd-as``: ``apgd-jacobi`` plus an exact active-set finish (frictionless
  problems): once the active set settles, the equality-constrained system
  ``W_AA x_A = -b_A`` is solved by a sparse LDL^T factorisation (qdldl),
  checked, and corrected by primal-dual active-set rounds.

Iteration counts follow the condition number of ``W`` on the loaded rows
(``lubcontact bench solvers --condition``). On settled piles, where it is
1.6e4, 2.0e6 and 9.4e7 at 10^2, 10^3 and 10^4 grains, ``pgd`` needed 1.6e5
and 1.2e7 iterations (about 6-10 x cond; 10^4 would take days), ``bb`` 1.7e3,
7.9e4 and 8.3e5, ``apgd`` 1.4e3, 8.9e3 and 2.2e4, ``apgd-as`` 1 to 3
(docs/benchmarks.md). The default cap of 20 000 therefore stops ``pgd`` and
``bb`` with status ``max_iter`` on large jammed piles.

Every method only uses the problem protocol: ``delassus`` (sparse W),
``offset`` (b), ``cones``, ``n_rows`` and, when present, ``delassus_factor``
(L, ``W = L^T L``).

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
A stopping rule is not an accuracy: where ``W`` is badly conditioned
(mass ratio 1e6, a settled pile) ``r <= 1e-9`` still left velocity errors of
1e-6 to 1e-5. So on frictionless problems every ``converged`` result is
finished exactly (:func:`finish_exactly`): one sparse LDL^T solve on the active
set of the best iterate, accepted only when it passes the sign and
complementarity checks (``info["exact_finish"]``); the finish solves count
as iterations.

Operator
--------
``W x`` is applied either from the assembled sparse W (``operator="matrix"``)
or matrix-free as ``L^T (L x)`` (``operator="factor"``). Measured on the
10^4-grain pile (docs/benchmarks.md) both cost about the same per product
(0.25 ms vs 0.22 ms with a CSR copy of ``L^T``). With ``"auto"``:
frictionless problems and 2D friction cones (UNION contacts included)
assemble ``S W S`` (11 ms at 10^4, from ``L S``) for the compiled kernels of
:mod:`.kernels` and the active-set finish; problems with 3D friction cones use
the matrix-free product when the factor exists.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..problem.cones import ConeKind
from .registry import FIRST_ORDER, register
from .result import CONVERGED, DIVERGED, MAX_ITER, MethodOutput

_DIVERGENCE_FACTOR = 1e12
_REQUEST_FINISH = 3                      # kernel status: the active set has settled
_KERNEL_STATUS = {0: CONVERGED, 1: MAX_ITER, 2: DIVERGED}


def _box_kernel():
    """The compiled APGD loop of :mod:`.kernels`, or None when numba is unavailable."""
    try:
        from .kernels import apgd_box
    except ImportError:
        return None
    return apgd_box


def _cone_kernel():
    """The compiled APGD loop with 2D friction (and UNION) cones, or None when numba is
    unavailable."""
    try:
        from .kernels import apgd_cone2d
    except ImportError:
        return None
    return apgd_cone2d


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
    products: int = 0
    ratio: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.ratio = self.scale / self.jacobi
        self._rms = 1.0 / np.sqrt(max(self.offset.size, 1))

    def product(self, z: np.ndarray) -> np.ndarray:
        self.products += 1
        return self.apply(z)

    def residual(self, z: np.ndarray, gradient: np.ndarray) -> float:
        """The stopping measure ``r`` (module docstring) at ``z`` with gradient ``W_it z + b_it``."""
        y = z * self.ratio
        return float(np.linalg.norm(y - self.project(y - gradient / self.ratio)) * self._rms)

    def objective(self, z: np.ndarray, product: np.ndarray) -> float:
        return float(0.5 * z @ product + self.offset @ z)

    def assembled(self) -> sp.csr_matrix:
        """``W_it`` as a sparse matrix, assembled from the factor on first use."""
        if self.matrix is None:
            self.matrix = sp.csr_matrix(self.factor.T @ self.factor)
        return self.matrix


def jacobi_scale(problem) -> np.ndarray:
    """Per-row scale ``s``, constant over each contact's rows (see module docstring)."""
    cones = problem.cones
    factor = problem.delassus_factor
    diagonal = np.asarray(problem.delassus.diagonal()) if factor is None \
        else np.asarray(factor.multiply(factor).sum(axis=0)).ravel()
    nc = cones.count
    total = diagonal[:nc].copy()
    count = np.ones(nc)
    if cones.has_friction:
        tangent = diagonal[nc:].reshape(-1, cones.tangent_dim)
        np.add.at(total, cones.tangential, tangent.sum(axis=1))
        np.add.at(count, cones.tangential, cones.tangent_dim)
    mean = total / count
    per_contact = np.where(mean > 0, 1.0 / np.sqrt(np.where(mean > 0, mean, 1.0)), 1.0)
    scale = np.empty(problem.n_rows)
    scale[:nc] = per_contact
    if cones.has_friction:
        scale[nc:] = np.repeat(per_contact[cones.tangential], cones.tangent_dim)
    return scale


def prepare(problem, scaling: bool, operator: str = "auto") -> DualData:
    """Build the iteration data of a (normalised) problem.

    Parameters
    ----------
    scaling : bool
        Iterate on the Jacobi-scaled problem.
    operator : {"auto", "matrix", "factor"}
        How ``W z`` is applied (module docstring).
    """
    if operator not in ("auto", "matrix", "factor"):
        raise ValueError(f"operator: must be 'auto', 'matrix' or 'factor', got {operator!r}")
    has_factor = problem.delassus_factor is not None
    if operator == "factor" and not has_factor:
        raise ValueError("operator: 'factor' needs a problem with delassus_factor")
    use_factor = has_factor and operator != "matrix"
    jacobi = jacobi_scale(problem)
    scale = jacobi if scaling else np.ones(problem.n_rows)
    offset = scale * problem.offset
    if use_factor:
        factor = sp.csr_matrix(problem.delassus_factor @ sp.diags(scale))
        transposed = sp.csr_matrix(factor.T)
        return DualData(apply=lambda z: transposed @ (factor @ z), offset=offset, scale=scale,
                        jacobi=jacobi, project=problem.cones.projector, factor=factor)
    if has_factor:
        factor = sp.csr_matrix(problem.delassus_factor @ sp.diags(scale))
        matrix = sp.csr_matrix(factor.T @ factor)
    else:
        matrix = sp.csr_matrix(sp.diags(scale) @ problem.delassus @ sp.diags(scale))
    return DualData(apply=matrix.dot, offset=offset, scale=scale, jacobi=jacobi,
                    project=problem.cones.projector, matrix=matrix)


@dataclass
class _Tracker:
    """Best iterate, residual history and the stopping decision."""

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
        if not np.isfinite(residual) or residual > _DIVERGENCE_FACTOR * max(self.first, 1.0):
            return DIVERGED
        return None


def _initial(data: DualData, warm_start: np.ndarray | None, n: int) -> np.ndarray:
    if warm_start is None:
        return np.zeros(n)
    return data.project(np.asarray(warm_start, dtype=float) / data.scale)


def _lipschitz(data: DualData, n: int, iterations: int) -> float:
    """Largest eigenvalue of ``W_it`` by power iteration (deterministic start)."""
    vector = np.random.default_rng(0).uniform(0.5, 1.5, n)
    value = 1.0
    for _ in range(iterations):
        image = data.product(vector)
        value = float(np.linalg.norm(image))
        if value == 0.0:
            return 1.0
        vector = image / value
    return value


def _output(data: DualData, tracker: _Tracker, status: str, iterations: int, setup: float,
            start: float, info: dict | None = None) -> MethodOutput:
    best = tracker.best if tracker.best is not None else np.zeros_like(data.offset)
    if status != CONVERGED and status != DIVERGED:
        status = MAX_ITER
    if status == DIVERGED and not np.all(np.isfinite(best)):
        best = np.zeros_like(best)
    extra = {"products": data.products, "best_residual": tracker.best_residual}
    extra.update(info or {})
    return MethodOutput(forces=best * data.scale, status=status, iterations=iterations,
                        setup_time=setup, solve_time=time.perf_counter() - start,
                        residual_history=np.asarray(tracker.history), info=extra)


# -- iterations ------------------------------------------------------------------------------
def run_pgd(data: DualData, z: np.ndarray, tol: float, max_iter: int, power_iterations: int = 30):
    """Projected gradient with step ``1 / L``; returns (tracker, status, iterations)."""
    tracker = _Tracker(data, tol)
    step = 1.0 / (1.01 * _lipschitz(data, z.size, power_iterations))
    product = data.product(z)
    status = None
    for k in range(1, max_iter + 1):
        z = data.project(z - step * (product + data.offset))
        product = data.product(z)
        status = tracker.record(z, product + data.offset)
        if status:
            return tracker, status, k
    return tracker, MAX_ITER, max_iter


def run_apgd(data: DualData, z: np.ndarray, tol: float, max_iter: int,
             callback: Callable | None = None):
    """APGD with adaptive restart and backtracking (Mazhar et al. 2015).

    One product ``W z`` per iteration (plus one per backtracking step): the
    product at the extrapolated point is a combination of stored products.
    ``callback(k, z, gradient)`` may return a replacement iterate or
    ``"stop"``; returns (tracker, status, iterations, z).
    """
    tracker = _Tracker(data, tol)
    x_old = z.copy()
    wx_old = data.product(z)
    lipschitz = _probe_lipschitz(data, z, wx_old)
    y, wy = z.copy(), wx_old.copy()
    theta = 1.0
    for k in range(1, max_iter + 1):
        gradient_y = wy + data.offset
        while True:
            x = data.project(y - gradient_y / lipschitz)
            wx = data.product(x)
            d = x - y
            if d @ (wx - wy) <= lipschitz * (d @ d) * (1.0 + 1e-12):
                break
            lipschitz *= 2.0
        gradient_x = wx + data.offset
        status = tracker.record(x, gradient_x)
        if status:
            return tracker, status, k, x
        if callback is not None:
            replaced = callback(k, x, gradient_x)
            if isinstance(replaced, str):
                return tracker, replaced, k, x
            if replaced is not None:
                x = replaced
                wx = data.product(x)
                status = tracker.record(x, wx + data.offset)
                if status:
                    return tracker, status, k, x
                x_old, wx_old, y, wy, theta = x, wx, x.copy(), wx.copy(), 1.0
                continue
        theta_new = 0.5 * (-theta * theta + theta * np.sqrt(theta * theta + 4.0))
        beta = theta * (1.0 - theta) / (theta * theta + theta_new)
        if gradient_y @ (x - x_old) > 0.0:          # restart: momentum points uphill
            y, wy, theta_new = x.copy(), wx.copy(), 1.0
        else:
            y = x + beta * (x - x_old)
            wy = wx + beta * (wx - wx_old)
        x_old, wx_old, theta = x, wx, theta_new
        lipschitz *= 0.9
    return tracker, MAX_ITER, max_iter, x_old


def run_bb(data: DualData, z: np.ndarray, tol: float, max_iter: int, memory: int = 10,
           gamma: float = 1e-4):
    """Spectral projected gradient (SPG, alternating BB1/BB2 steps, non-monotone GLL search)."""
    tracker = _Tracker(data, tol)
    wz = data.product(z)
    gradient = wz + data.offset
    values = [data.objective(z, wz)]
    step = 1.0 / max(float(np.max(np.abs(data.product(np.ones_like(z))))), 1e-12)
    step_min, step_max = 1e-10, 1e10
    for k in range(1, max_iter + 1):
        d = data.project(z - step * gradient) - z
        wd = data.product(d)
        slope = float(gradient @ d)
        curvature = float(d @ wd)
        reference = max(values[-memory:])
        value = values[-1]
        length = 1.0
        if value + slope + 0.5 * curvature > reference + gamma * slope and curvature > 0:
            length = min(1.0, -slope / curvature)
        z = z + length * d
        wz = wz + length * wd
        gradient = wz + data.offset
        values.append(value + length * slope + 0.5 * length * length * curvature)
        status = tracker.record(z, gradient)
        if status:
            return tracker, status, k
        s_s = length * length * float(d @ d)
        s_y = length * length * curvature
        if s_y <= 0.0:
            step = step_max
        elif k % 2:
            step = s_s / s_y                                                   # BB1
        else:
            step = s_y / (length * length * float(wd @ wd))                    # BB2
        step = min(step_max, max(step_min, step))
    return tracker, MAX_ITER, max_iter


# -- active-set finish -----------------------------------------------------------------------
class ActiveSetFinish:
    """Exact solve on an identified active set (frictionless problems).

    Active rows: FREE contacts, and one-sided contacts whose force would stay
    off the bound after a gradient step (``sigma (z - g) > 0`` with ``sigma =
    +1`` for NONNEG, ``-1`` for NONPOS). On ``A`` the problem is the linear
    system ``W_AA z_A = -b_A`` (``z = 0`` off ``A``). It is solved by a sparse
    LDL^T factorisation (qdldl) of ``W`` with the inactive rows and columns
    replaced by the identity, so that every active set shares one sparsity
    pattern: the ordering and symbolic analysis are done once per solve and
    each new active set costs a numeric refactorisation only. ``delta`` =
    1e-12 x the largest diagonal is added on the active diagonal (singular
    hyperstatic blocks factor) and one step of iterative refinement removes it.

    A candidate that satisfies every sign and complementarity condition is
    returned (projected) and kept as ``exact``; otherwise primal-dual active-set rounds replace
    ``A`` by the candidate's active set, up to ``max_rounds``. When they do not
    settle, the projected last candidate is returned if its residual beats
    the current iterate's, as a new starting point for the iterations.

    Parameters
    ----------
    stable_iterations : int
        Attempt once the active set has not changed for this many iterations.
    period : int
        Also attempt every ``period`` iterations (0: never).
    max_rounds : int
        Factorisations per attempt.
    """

    def __init__(self, data: DualData, cones, stable_iterations: int = 5, period: int = 0,
                 max_rounds: int = 3):
        kinds = cones.kinds
        self.sign = np.where(kinds == ConeKind.NONNEG, 1.0, np.where(kinds == ConeKind.NONPOS, -1.0, 0.0))
        self.data = data
        self.stable_iterations = stable_iterations
        self.period = period
        self.max_rounds = max_rounds
        self.previous: np.ndarray | None = None
        self.unchanged = 0
        self.attempts = 0
        self.solves = 0
        self.tried: set[int] = set()
        self.exact: np.ndarray | None = None
        self._factor = None
        upper = sp.triu(data.assembled(), format="csc")
        delta = 1e-12 * max(float(upper.diagonal().max()), 1e-300) if upper.nnz else 1e-12
        upper = sp.csc_matrix(upper + delta * sp.identity(upper.shape[0], format="csc"))
        self._upper = upper
        self._rows = upper.indices
        self._cols = np.repeat(np.arange(upper.shape[1]), np.diff(upper.indptr))
        self._diagonal = self._rows == self._cols

    def active(self, z: np.ndarray, gradient: np.ndarray) -> np.ndarray:
        """Rows that stay off their bound after a gradient step from ``z``."""
        return (self.sign == 0.0) | (self.sign * (z - gradient) > 0.0)

    def closed_rows(self, threshold: float = 1e-6) -> np.ndarray:
        """Initial guess without a warm start: contacts closed or closing under free motion.

        A one-sided row is guessed active when its free-motion gap ``b_i``
        (gap plus one step of free relative motion) does not open beyond
        ``threshold x max |b|``.
        """
        offset = self.data.offset
        level = threshold * float(np.max(np.abs(offset))) if offset.size else 0.0
        return (self.sign == 0.0) | (self.sign * offset <= level)

    def __call__(self, k: int, z: np.ndarray, gradient: np.ndarray):
        """APGD callback: try the exact solve once the active set stays unchanged."""
        active = self.active(z, gradient)
        if self.previous is not None and np.array_equal(active, self.previous):
            self.unchanged += 1
        else:
            self.unchanged = 0
        self.previous = active
        periodic = self.period > 0 and k % self.period == 0
        if self.unchanged < self.stable_iterations and not periodic:
            return None
        return self.solve(active, self.data.residual(z, gradient))

    def solve(self, active: np.ndarray, current: float = np.inf) -> np.ndarray | None:
        """PDAS rounds from ``active`` (each set tried once); see the class docstring."""
        key = hash(active.tobytes())
        if key in self.tried:
            return None
        self.tried.add(key)
        self.attempts += 1
        data = self.data
        slack = 1e-12 * (1.0 + float(np.max(np.abs(data.offset))))
        candidate = None
        for _ in range(self.max_rounds):
            candidate = self._solve_on(active)
            self.solves += 1
            if candidate is None:
                return None
            gradient = data.product(candidate) + data.offset
            margin = 1e-12 * (1.0 + float(np.max(np.abs(candidate))))
            wrong_sign = active & (self.sign * candidate < -margin)
            violated = ~active & (self.sign * gradient < -slack)
            if not (wrong_sign.any() or violated.any()):
                self.exact = data.project(candidate)
                return self.exact
            active = (active & ~wrong_sign) | violated
        projected = data.project(candidate)
        residual = data.residual(projected, data.product(projected) + data.offset)
        return projected if residual < current else None

    def _solve_on(self, active: np.ndarray) -> np.ndarray | None:
        import qdldl

        upper = self._upper
        both = active[self._rows] & active[self._cols]
        values = np.where(both, upper.data, np.where(self._diagonal, 1.0, 0.0))
        matrix = sp.csc_matrix((values, upper.indices, upper.indptr), shape=upper.shape)
        try:
            if self._factor is None:
                self._factor = qdldl.Solver(matrix, upper=True)
            else:
                self._factor.update(matrix, upper=True)
        except ValueError:
            return None
        rhs = np.where(active, -self.data.offset, 0.0)
        solution = self._factor.solve(rhs)
        product = self.data.product(np.where(active, solution, 0.0))
        solution = solution + self._factor.solve(np.where(active, rhs - product, 0.0))
        if not np.all(np.isfinite(solution)):
            return None
        return np.where(active, solution, 0.0)


# -- registered methods ----------------------------------------------------------------------
def _common(problem, warm_start, scaling: bool, operator: str):
    start = time.perf_counter()
    data = prepare(problem, scaling, operator)
    z = _initial(data, warm_start, problem.n_rows)
    return data, z, time.perf_counter() - start, time.perf_counter()


def finish_exactly(data: DualData, cones, tracker: _Tracker, status: str,
                   finish: ActiveSetFinish | None = None) -> dict:
    """Replace a converged best iterate by the exact solution on its active set.

    The residual test does not bound the velocity error when ``W`` is badly
    conditioned (docs/hard_cases.md, finding 5): at ``r <= 1e-9`` the
    velocities were still 2e-6 off at a mass ratio of 1e6 and 6e-6 off on the
    settled 1000-grain pile. On frictionless problems the active set of a
    converged iterate is (almost always) the optimal one, so one
    :class:`ActiveSetFinish` solve from it gives the solution to rounding,
    checked by its sign and complementarity conditions. The tracker's best
    iterate is replaced only by such a checked solution; problems with friction
    cones, non-converged runs and best iterates that already are an exact
    solve are left as they are.

    Returns
    -------
    dict
        ``exact_finish`` (True when the returned forces are a checked exact
        solve, False when the attempt failed the checks; absent when not
        attempted), ``finish_solves`` (LDL^T solves of this call).
    """
    if status != CONVERGED or cones.has_friction or tracker.best is None:
        return {}
    finish = finish if finish is not None else ActiveSetFinish(data, cones)
    if finish.exact is not None and np.array_equal(finish.exact, tracker.best):
        return {"exact_finish": True, "finish_solves": 0}
    solves = finish.solves
    finish.exact = None
    best = tracker.best
    finish.solve(finish.active(best, data.product(best) + data.offset))
    if finish.exact is not None:
        residual = data.residual(finish.exact, data.product(finish.exact) + data.offset)
        tracker.history.append(residual)
        tracker.best, tracker.best_residual = finish.exact, residual
    return {"exact_finish": finish.exact is not None, "finish_solves": finish.solves - solves}


def _finalise(problem, data: DualData, tracker: _Tracker, status: str, iterations: int,
              setup: float, start: float, info: dict | None = None,
              finish: ActiveSetFinish | None = None) -> MethodOutput:
    """:func:`finish_exactly`, then the method's output (finish solves count as iterations)."""
    info = dict(info or {})
    info.update(finish_exactly(data, problem.cones, tracker, status, finish))
    return _output(data, tracker, status, iterations + info.get("finish_solves", 0), setup,
                   start, info)


def _accept_warm_start(problem, data: DualData, z: np.ndarray, tol: float, warm_start,
                       setup: float, start: float) -> MethodOutput | None:
    """Converged output without gradient iterations when the (projected) warm start meets ``tol``."""
    if warm_start is None:
        return None
    tracker = _Tracker(data, tol)
    if tracker.record(z, data.product(z) + data.offset) != CONVERGED:
        return None
    return _finalise(problem, data, tracker, CONVERGED, 0, setup, start)


def _empty(problem) -> MethodOutput | None:
    if problem.n_rows == 0:
        return MethodOutput(np.zeros(0), CONVERGED, 0, 0.0, 0.0)
    return None


def _plain(run, problem, tol, max_iter, warm_start, scaling, operator) -> MethodOutput:
    """A method without finish callback: set-up, warm-start test, then ``run(data, z, tol,
    max_iter)`` (returning tracker, status, iterations), then :func:`_finalise`."""
    if (out := _empty(problem)) is not None:
        return out
    data, z, setup, start = _common(problem, warm_start, scaling, operator)
    if (out := _accept_warm_start(problem, data, z, tol, warm_start, setup, start)) is not None:
        return out
    tracker, status, iterations = run(data, z, tol, max_iter)
    return _finalise(problem, data, tracker, status, iterations, setup, start)


@register("pgd", kind=FIRST_ORDER)
def pgd(problem, *, tol: float = 1e-8, max_iter: int = 20000, warm_start=None,
        scaling: bool = False, operator: str = "auto") -> MethodOutput:
    """Projected gradient descent, step ``1/L`` (see module docstring)."""
    return _plain(run_pgd, problem, tol, max_iter, warm_start, scaling, operator)


def _apgd(problem, tol, max_iter, warm_start, scaling, operator, active_set) -> MethodOutput:
    if (out := _empty(problem)) is not None:
        return out
    box = _is_box(problem.cones) and _box_kernel() is not None
    cones_2d = _is_cone_2d(problem.cones) and _cone_kernel() is not None
    fused = (box or cones_2d) and operator != "factor"
    finishing = active_set and not problem.cones.has_friction
    data, z, setup, start = _common(problem, warm_start, scaling,
                                    "matrix" if fused or finishing else operator)
    if (out := _accept_warm_start(problem, data, z, tol, warm_start, setup, start)) is not None:
        return out
    finish = None
    if finishing:
        finish = ActiveSetFinish(data, problem.cones)
        guess = finish.active(z, data.product(z) + data.offset) if warm_start is not None \
            else finish.closed_rows()
        candidate = finish.solve(guess)
        if candidate is not None:
            tracker = _Tracker(data, tol)
            if tracker.record(candidate, data.product(candidate) + data.offset) == CONVERGED:
                info = {"fused_kernel": fused, "active_set_attempts": finish.attempts,
                        "active_set_solves": finish.solves}
                return _finalise(problem, data, tracker, CONVERGED, finish.solves, setup, start,
                                 info, finish)
            z = candidate
    if fused and cones_2d:
        tracker, status, iterations, _ = run_apgd_cones(data, problem.cones, z, tol, max_iter)
    elif fused:
        tracker, status, iterations = _run_apgd_fused(data, z, tol, max_iter, finish)
    else:
        tracker, status, iterations, _ = run_apgd(data, z, tol, max_iter, callback=finish)
    info = {"fused_kernel": fused}
    if finish is not None:
        info.update(active_set_attempts=finish.attempts, active_set_solves=finish.solves)
        iterations += finish.solves
    return _finalise(problem, data, tracker, status, iterations, setup, start, info, finish)


def _is_box(cones) -> bool:
    """True when K is a box (no friction cone): the fused kernel applies."""
    return all(piece[0].size == 0 for piece in cones.projector.pieces)


def _is_cone_2d(cones) -> bool:
    """True when K is a product of a box and 2D friction cones (Coulomb or UNION contacts)."""
    coulomb, union = cones.projector.pieces
    return coulomb[0].size + union[0].size > 0 and cones.tangent_dim == 1


def _probe_lipschitz(data: DualData, z: np.ndarray, product: np.ndarray | None = None) -> float:
    """Starting Lipschitz estimate of the APGD loops: ``|W d| / |d|`` for a
    deterministic random ``d`` (the loops' backtracking corrects it); ``product``
    is ``W z`` when already computed."""
    product = data.product(z) if product is None else product
    probe = z + np.random.default_rng(0).uniform(-1.0, 1.0, z.size)
    return max(float(np.linalg.norm(data.product(probe) - product) /
                     np.linalg.norm(probe - z)), 1e-12)


def run_apgd_cones(data: DualData, cones, z: np.ndarray, tol: float, max_iter: int,
                   base: np.ndarray | None = None, every: int = 0):
    """APGD in the compiled kernel :func:`.kernels.apgd_cone2d` (2D friction and UNION cones).

    With ``every > 0`` and ``base`` (the iteration offset without shift) it
    solves Coulomb's problem, updating the shift every ``every`` iterations
    (see the kernel). Returns (tracker, status, iterations, offset): the offset
    ``b_it`` of the last shift.
    """
    kernel = _cone_kernel()
    matrix = data.assembled()
    (cone_n, cone_t, cone_mu), (union_n, union_t, union_mu) = cones.projector.pieces
    union = np.repeat([False, True], [cone_n.size, union_n.size])
    lipschitz = _probe_lipschitz(data, z)
    best, best_residual, history, code, iterations, products, _, _, offset = kernel(
        matrix.indptr, matrix.indices, matrix.data, data.offset,
        data.offset if base is None else base, data.project.lower, data.project.upper,
        np.concatenate([cone_n, union_n]), np.concatenate([cone_t[:, 0], union_t[:, 0]]),
        np.concatenate([cone_mu, union_mu]), union, data.ratio, z, tol, max_iter, lipschitz,
        _DIVERGENCE_FACTOR, every)
    data.products += products
    tracker = _Tracker(data, tol)
    tracker.history.extend(history)
    tracker.best, tracker.best_residual = best, best_residual
    return tracker, _KERNEL_STATUS.get(code, MAX_ITER), iterations, offset


def _run_apgd_fused(data: DualData, z: np.ndarray, tol: float, max_iter: int,
                    finish: ActiveSetFinish | None):
    """APGD in the compiled kernel; returns to Python only for active-set solves."""
    kernel = _box_kernel()
    matrix = data.matrix
    lipschitz = _probe_lipschitz(data, z)
    sign = finish.sign if finish is not None else np.zeros(z.size)
    stable = finish.stable_iterations if finish is not None else 0
    chunk = finish.period if finish is not None and finish.period > 0 else max_iter
    tracker = _Tracker(data, tol)
    done = 0
    while True:
        best, best_residual, history, code, iterations, products, last, lipschitz = kernel(
            matrix.indptr, matrix.indices, matrix.data, data.offset, data.project.lower,
            data.project.upper, data.ratio, sign, z, tol, min(chunk, max_iter - done), lipschitz,
            stable, _DIVERGENCE_FACTOR)
        done += iterations
        data.products += products
        tracker.history.extend(history)
        if best_residual < tracker.best_residual:
            tracker.best_residual, tracker.best = best_residual, best
        if code not in (_REQUEST_FINISH, 1) or done >= max_iter or finish is None:
            return tracker, _KERNEL_STATUS.get(code, MAX_ITER), done
        z = last
        gradient = data.product(last) + data.offset
        candidate = finish.solve(finish.active(last, gradient), data.residual(last, gradient))
        if candidate is not None:
            status = tracker.record(candidate, data.product(candidate) + data.offset)
            if status:
                return tracker, status, done
            z = candidate
        if done >= max_iter:
            return tracker, MAX_ITER, done


@register("apgd", kind=FIRST_ORDER)
def apgd(problem, *, tol: float = 1e-8, max_iter: int = 20000, warm_start=None,
         scaling: bool = False, operator: str = "auto") -> MethodOutput:
    """Accelerated projected gradient with restart and backtracking (Mazhar et al. 2015)."""
    return _apgd(problem, tol, max_iter, warm_start, scaling, operator, active_set=False)


@register("apgd-jacobi", kind=FIRST_ORDER)
def apgd_jacobi(problem, *, tol: float = 1e-8, max_iter: int = 20000, warm_start=None,
                operator: str = "auto") -> MethodOutput:
    """``apgd`` on the Jacobi-scaled problem."""
    return _apgd(problem, tol, max_iter, warm_start, True, operator, active_set=False)


@register("apgd-as", kind=FIRST_ORDER, polishing=True)
def apgd_active_set(problem, *, tol: float = 1e-8, max_iter: int = 20000, warm_start=None,
                    operator: str = "auto") -> MethodOutput:
    """Jacobi-scaled APGD with an exact active-set finish (:class:`ActiveSetFinish`).

    ``iterations`` counts gradient iterations plus LDL^T solves. With friction
    rows the finish is skipped and this is ``apgd-jacobi``.
    """
    return _apgd(problem, tol, max_iter, warm_start, True, operator, active_set=True)


@register("bb", kind=FIRST_ORDER)
def bb(problem, *, tol: float = 1e-8, max_iter: int = 20000, warm_start=None,
       scaling: bool = False, operator: str = "auto") -> MethodOutput:
    """Spectral (Barzilai-Borwein) projected gradient with a non-monotone line search."""
    return _plain(run_bb, problem, tol, max_iter, warm_start, scaling, operator)

