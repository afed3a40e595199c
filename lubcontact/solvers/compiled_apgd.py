"""APGD in the compiled loops of :mod:`.kernels`: dispatch, the loops' drivers, and the joint
Coulomb phase.

The compiled loops need the assembled ``W_it`` (``S W S``) and numba; each
loader returns None when numba is unavailable, and the numpy loop of
:func:`.gradient_loops.run_apgd` is then used. :func:`run_apgd_box` covers boxes
(frictionless problems, with the active-set finish of :mod:`.active_set`),
:func:`run_apgd_cones` boxes and 2D friction cones (UNION contacts included),
evaluating its stopping measure (a second projection and three vector passes)
every :data:`CHECK_EVERY` iterations; the numpy loop evaluates it at every one. From
:data:`STREAMING_ROWS` rows on, the cone loop passes over each vector once per stage
(``streaming``: the same iterates, for problems whose vectors do not stay in the cache).

:func:`joint_coulomb_apgd` is the joint phase of the fixed point on ``s``
(``joint`` of :func:`lubcontact.solvers.solve_coulomb`): one Jacobi-scaled
APGD run in the 2D cone loop that solves Coulomb's problem itself, updating
the shift ``mu |g_T|`` from its iterate every ``every`` iterations;
:func:`joint_applies` says when it can run.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from ..problem.cones import Cones
from ..problem.conic import ConicProblem
from .active_set import ActiveSetFinish
from .dual_data import DIVERGENCE_FACTOR, DualData, ResidualTracker, initial_lipschitz, initial_point, prepare
from .result import CONVERGED, DIVERGED, MAX_ITER

_REQUEST_FINISH = 3                      # kernel status: the active set has settled
CHECK_EVERY = 4
"""Iterations between evaluations of the cone loop's stopping measure (:func:`run_apgd_cones`)."""
STREAMING_ROWS = 250_000
"""Rows from which the cone loop passes over each vector once per stage (``streaming`` of
:func:`.kernels.apgd_cone2d`): its dozen vectors and ``F`` then no longer stay in a 32 MB
cache. Measured per iteration, the two paths in one process (docs/records/benchmarks.md): 10 %
faster at 673 192 rows (10^5 grains), 7 % slower at 48 001 and 81 692 rows (12 000 grains),
where the vectorised passes through work vectors win."""
_KERNEL_STATUS = {0: CONVERGED, 1: MAX_ITER, 2: DIVERGED}


def box_kernel() -> Callable | None:
    """The compiled APGD loop of :mod:`.kernels`, or None when numba is unavailable."""
    try:
        from .kernels import apgd_box
    except ImportError:
        return None
    return apgd_box


def cone_kernel() -> Callable | None:
    """The compiled APGD loop with 2D friction (and UNION) cones, or None when numba is
    unavailable."""
    try:
        from .kernels import apgd_cone2d
    except ImportError:
        return None
    return apgd_cone2d


def positions(values: np.ndarray) -> np.ndarray:
    """``values`` (non-negative integers) as unsigned indices, the index type the compiled loops
    are compiled for: numba checks every signed index for a negative value (wrap-around), and on
    the developed 3200-grain flow that made the product ``W x`` 2.5x slower (589 against 230 us;
    docs/records/benchmarks.md). 32-bit (``np.uint32``, a view of scipy's ``int32`` indices)
    unless a value needs 64 bits (``np.uintp``): at 10^5 grains the product streams its
    indices from memory, and half their bytes made it 10 % faster."""
    values = np.asarray(values)
    if values.dtype in (np.int32, np.uint32):
        return values.view(np.uint32)
    if values.size and values.max() > np.iinfo(np.uint32).max:
        return values.astype(np.uintp, copy=False)
    return values.astype(np.uint32)


def csr_arrays(matrix: sp.csr_matrix | tuple[np.ndarray, np.ndarray, np.ndarray]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of a compressed sparse matrix, CSR (or CSC: the same arrays,
    by columns), or of such a triple, the index arrays as :func:`positions`."""
    indptr, indices, values = (matrix.indptr, matrix.indices, matrix.data) \
        if sp.issparse(matrix) else matrix
    return positions(indptr), positions(indices), values


def operator_arrays(matrix: sp.csr_matrix | tuple[np.ndarray, np.ndarray, np.ndarray],
                    transpose: sp.csr_matrix | None = None) -> tuple[np.ndarray, ...]:
    """The operator ``W x`` as the kernels take it (:func:`~.kernels.apply_operator`): ``W``'s
    CSR arrays (``matrix``, or their triple) with empty ones for the transpose; or, with
    ``transpose``, ``matrix`` as ``W``'s factor ``F`` (``W = F^T F``), the CSR arrays of ``F``
    and ``F^T`` and a work vector for ``F x``."""
    if transpose is None:
        empty = np.zeros(0, dtype=np.uint32)
        return (*csr_arrays(matrix), empty, empty, np.zeros(0), np.zeros(0))
    return (*csr_arrays(matrix), *csr_arrays(transpose), np.empty(matrix.shape[0]))


def is_box(cones: Cones) -> bool:
    """True when K is a box (no friction cone): the fused kernel applies."""
    return cones.projector.friction_normal.size == 0


def is_cone_2d(cones: Cones) -> bool:
    """True when K is a product of a box and 2D friction cones (Coulomb or UNION contacts)."""
    return cones.projector.friction_normal.size > 0 and cones.tangent_dim == 1


def run_apgd_cones(data: DualData, cones: Cones, z: np.ndarray, tol: float, max_iter: int,
                   base: np.ndarray | None = None, every: int = 0,
                   check_every: int = CHECK_EVERY, streaming: bool | None = None
                   ) -> tuple[ResidualTracker, str, int, np.ndarray]:
    """APGD in the compiled kernel :func:`.kernels.apgd_cone2d` (2D friction and UNION cones).

    With ``every > 0`` and ``base`` (the iteration offset without shift) it
    solves Coulomb's problem, updating the shift every ``every`` iterations
    (see the kernel).

    Parameters
    ----------
    data : DualData
        The problem: ``W_it z`` is applied as ``F^T (F z)`` where the data has the factor
        ``F = L S_it`` and no assembled ``W_it`` (``operator="auto"`` or ``"factor"`` on a step
        problem), from ``W_it`` otherwise (assembled here if it is not yet).
    cones : Cones
        Its cones (:func:`is_cone_2d`).
    z : ndarray, shape (n,)
        Starting iterate.
    tol : float
        Stopping tolerance on the residual.
    max_iter : int
        Iteration cap.
    base : ndarray, shape (n,), optional
        Iteration offset without shift (with ``every > 0``).
    every : int
        Shift update period (0: no update, the convex problem).
    check_every : int
        Iterations between evaluations of the stopping measure (besides the first and the
        last iteration), >= 1; the history has one residual per evaluation, and the best
        iterate is the best of the evaluated ones.
    streaming : bool, optional
        The kernel's ``streaming`` passes (the same iterates); default: from
        :data:`STREAMING_ROWS` rows on.

    Returns
    -------
    tracker : ResidualTracker
        Best iterate and residual history.
    status : str
    iterations : int
    offset : ndarray, shape (n,)
        The offset ``b_it`` of the last shift.
    """
    if check_every < 1:
        raise ValueError(f"check_every: must be >= 1, got {check_every}")
    kernel = cone_kernel()
    operator = operator_arrays(data.factor, data.factor_transpose) \
        if data.matrix is None and data.factor is not None else \
        operator_arrays(data.sparse_arrays())
    projector = cones.projector
    lipschitz = initial_lipschitz(data, z)
    streaming = z.size >= STREAMING_ROWS if streaming is None else streaming
    best, best_residual, history, code, iterations, products, _, offset = kernel(
        *operator, data.offset,
        data.offset if base is None else base, data.project.lower, data.project.upper,
        positions(projector.box_rows if streaming else np.zeros(0, dtype=np.uint32)),
        positions(projector.friction_normal), positions(projector.planar_tangent),
        projector.friction_mu, projector.friction_union, data.ratio, z, tol, max_iter, lipschitz,
        DIVERGENCE_FACTOR, every, check_every, streaming)
    data.products += products
    tracker = ResidualTracker(data, tol)
    tracker.history.extend(history)
    tracker.best, tracker.best_residual = best, best_residual
    return tracker, _KERNEL_STATUS.get(code, MAX_ITER), iterations, offset


def run_apgd_box(data: DualData, z: np.ndarray, tol: float, max_iter: int,
                 finish: ActiveSetFinish | None) -> tuple[ResidualTracker, str, int]:
    """APGD in the compiled kernel :func:`.kernels.apgd_box` (K a box, :func:`is_box`);
    returns to Python only for active-set attempts.

    The loop's state (iterate, extrapolated point, momentum, Lipschitz
    estimate, active set) lives here between kernel calls: after an attempt
    that does not give the exact solution the kernel continues exactly where
    it stopped, and once ``finish`` is :attr:`~.ActiveSetFinish.exhausted` it
    runs to its own stopping test, as without a finish.

    Parameters
    ----------
    data : DualData
        The problem, with ``W_it`` assembled (``data.matrix``, or ``data.dense`` when small).
    z : ndarray, shape (n,)
        Starting iterate.
    tol : float
        Stopping tolerance on the residual.
    max_iter : int
        Iteration cap.
    finish : ActiveSetFinish or None
        Exact finish attempted each time the kernel reports a settled active set,
        until it is exhausted.

    Returns
    -------
    tracker : ResidualTracker
        Best iterate and residual history.
    status : str
    iterations : int
    """
    kernel = box_kernel()
    arrays = csr_arrays(data.sparse_arrays())
    iterate, product = z.copy(), data.product(z)
    extrapolated, extrapolated_product = iterate.copy(), product.copy()
    active = np.zeros(z.size, dtype=bool)
    theta, lipschitz, unchanged, first = 1.0, initial_lipschitz(data, z, product), -1, -1.0
    sign = finish.sign if finish is not None else np.zeros(z.size)
    tracker = ResidualTracker(data, tol)
    done = 0
    while True:
        stable = finish.stable_iterations if finish is not None and not finish.exhausted else 0
        (best, best_residual, history, code, iterations, products, theta, lipschitz, unchanged,
         first) = kernel(*arrays, data.offset, data.project.lower,
                         data.project.upper, data.ratio, sign, iterate, product, extrapolated,
                         extrapolated_product, active, theta, lipschitz, unchanged, first, tol,
                         max_iter - done, stable, DIVERGENCE_FACTOR)
        done += iterations
        data.products += products
        tracker.history.extend(history)
        if best_residual < tracker.best_residual:
            tracker.best_residual, tracker.best = best_residual, best
        if code != _REQUEST_FINISH:
            return tracker, _KERNEL_STATUS.get(code, MAX_ITER), done
        exact = finish.solve(active)
        if exact is not None and tracker.record(exact, data.product(exact) + data.offset) == CONVERGED:
            return tracker, CONVERGED, done


def joint_coulomb_apgd(scaled: ConicProblem, warm_start: np.ndarray | None, tol: float,
                       max_iter: int, every: int) -> tuple[np.ndarray, int]:
    """Coulomb's problem by APGD with the shift updated inside (the joint phase of
    :func:`lubcontact.solvers.solve_coulomb` and of ``newton-ac``).

    Parameters
    ----------
    scaled : ConicProblem
        A normalised problem with 2D friction cones (:func:`joint_applies`; UNION contacts
        fixed on a piece for the fixed point) and the starting shift (the fixed point passes a
        copy of its normalised problem with that shift and the same cones, ``newton-ac`` its own
        problem: the matrices built here stay with it).
    warm_start : ndarray, shape (n_rows,), or None
        Starting forces (scaled units).
    tol : float
        Tolerance on the modified (De Saxce) natural map.
    max_iter : int
        Iteration cap.
    every : int
        Shift update period in iterations, > 0.

    Returns
    -------
    forces : ndarray, shape (n_rows,)
        The best iterate (scaled units); the caller checks it (the outer loop of the fixed
        point, the Newton method).
    iterations : int
        The iterations done.
    """
    data = prepare(scaled, scaling=True)
    z = initial_point(data, warm_start, scaled.cones)
    base = scaled.offset.copy()
    base[: scaled.n_contacts] -= scaled.shift
    tracker, _, iterations, _ = run_apgd_cones(data, scaled.cones, z, tol, max_iter,
                                               base=data.scale * base, every=every)
    return tracker.best * data.scale, iterations


def joint_applies(cones: Cones) -> bool:
    """The joint phase runs in the compiled 2D cone loop: 2D friction cones and numba."""
    return is_cone_2d(cones) and cone_kernel() is not None
