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
  checked, and corrected by primal-dual active-set rounds (:mod:`.active_set`).

Iteration counts follow the condition number of ``W`` on the loaded rows
(``lubcontact bench solvers --condition``). On settled piles, where it is
1.6e4, 2.0e6 and 9.4e7 at 10^2, 10^3 and 10^4 grains, ``pgd`` needed 1.6e5
and 1.2e7 iterations (about 6-10 x cond; 10^4 would take days), ``bb`` 1.7e3,
7.9e4 and 8.3e5, ``apgd`` 1.4e3, 8.9e3 and 2.2e4, ``apgd-as`` 1 to 3
(docs/records/benchmarks.md). The default cap of 20 000 therefore stops ``pgd`` and
``bb`` with status ``max_iter`` on large jammed piles.

Every method only uses the problem protocol: ``delassus`` (sparse W),
``offset`` (b), ``cones``, ``n_rows`` and, when present, ``delassus_factor``
(L, ``W = L^T L``). This module sets a method up, picks its loop and
finishes its result: the data they iterate on, the Jacobi scaling and the
stopping rule common to all of them are in :mod:`.dual_data`, the numpy loops
in :mod:`.gradient_loops`, the compiled APGD loops in :mod:`.compiled_apgd`;
every ``converged`` result on a frictionless problem is finished exactly
(:func:`.active_set.finish_exactly`).

Options of the registered methods: ``tol`` (stopping tolerance on the
residual of :mod:`.dual_data`), ``max_iter`` (iteration cap), ``warm_start``
(forces of the normalised problem, shape (n_rows,), or None), ``scaling``
(iterate on the Jacobi-scaled problem; always on for ``apgd-jacobi`` and
``apgd-as``) and ``operator`` (``"auto"``, ``"matrix"`` or ``"factor"``: how
``W x`` is applied, :func:`.dual_data.prepare`).

With ``operator="auto"`` the ``apgd`` methods assemble ``S W S`` (11 ms at
10^4 grains, from ``L S``) on frictionless problems, for the compiled box loop
of :mod:`.compiled_apgd` and the active-set finish; on 2D friction cones
(UNION contacts included) the compiled cone loop applies the factor, ``(L
S)^T ((L S) z)``, where it exists (a step problem): on a developed 3200-grain
flow ``L`` has 102 000 entries where ``W`` has 468 000, and an APGD step took
0.140 s instead of 0.259 s (docs/records/benchmarks.md); ``operator="matrix"``
assembles ``S W S`` for it instead. On 3D friction cones, and for ``pgd`` and
``bb``, the numpy loops use the matrix-free product when the factor exists.
Problems of at most :data:`.dual_data.DENSE_OPERATOR_LIMIT` rows get a dense
``S W S`` with ``operator="auto"`` (:func:`.dual_data.prepare`).
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..problem.conic import ConicProblem
from .active_set import ActiveSetFinish, finish_exactly
from .compiled_apgd import box_kernel, cone_kernel, is_box, is_cone_2d, run_apgd_box, run_apgd_cones
from .dual_data import DualData, ResidualTracker, initial_point, prepare
from .gradient_loops import run_apgd, run_bb, run_pgd
from .registry import FIRST_ORDER, register
from .result import CONVERGED, DIVERGED, MAX_ITER, MethodOutput


def _common(problem: ConicProblem, warm_start: np.ndarray | None, scaling: bool,
            operator: str, assembled: bool = False) -> tuple[DualData, np.ndarray, float, float]:
    start = time.perf_counter()
    data = prepare(problem, scaling, operator, assembled)
    z = initial_point(data, warm_start, problem.cones)
    return data, z, time.perf_counter() - start, time.perf_counter()


def _output(data: DualData, tracker: ResidualTracker, status: str, iterations: int, setup: float,
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


def _finalise(problem: ConicProblem, data: DualData, tracker: ResidualTracker, status: str, iterations: int,
              setup: float, start: float, info: dict | None = None,
              finish: ActiveSetFinish | None = None) -> MethodOutput:
    """:func:`finish_exactly`, then the method's output (finish solves count as iterations)."""
    info = dict(info or {})
    info.update(finish_exactly(data, problem.cones, tracker, status, finish))
    return _output(data, tracker, status, iterations + info.get("finish_solves", 0), setup,
                   start, info)


def _accept_warm_start(problem: ConicProblem, data: DualData, z: np.ndarray, tol: float,
                       warm_start: np.ndarray | None, setup: float, start: float) -> MethodOutput | None:
    """Converged output without gradient iterations when the (projected) warm start meets ``tol``."""
    if warm_start is None:
        return None
    tracker = ResidualTracker(data, tol)
    if tracker.record(z, data.product(z) + data.offset) != CONVERGED:
        return None
    return _finalise(problem, data, tracker, CONVERGED, 0, setup, start)


def _plain(run: Callable, problem: ConicProblem, tol: float, max_iter: int,
           warm_start: np.ndarray | None, scaling: bool, operator: str) -> MethodOutput:
    """A method without finish callback: set-up, warm-start test, then ``run(data, z, tol,
    max_iter)`` (returning tracker, status, iterations), then :func:`_finalise`."""
    data, z, setup, start = _common(problem, warm_start, scaling, operator)
    if (out := _accept_warm_start(problem, data, z, tol, warm_start, setup, start)) is not None:
        return out
    tracker, status, iterations = run(data, z, tol, max_iter)
    return _finalise(problem, data, tracker, status, iterations, setup, start)


@register("pgd", kind=FIRST_ORDER)
def pgd(problem: ConicProblem, *, tol: float = 1e-8, max_iter: int = 20000,
        warm_start: np.ndarray | None = None, scaling: bool = False,
        operator: str = "auto") -> MethodOutput:
    """Projected gradient descent, step ``1/L`` (see module docstring).

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem with ``n_rows > 0`` rows.
    tol, max_iter, warm_start, scaling, operator
        See the module docstring.

    Returns
    -------
    MethodOutput
        Forces of shape (n_rows,); ``info`` holds ``products`` and ``best_residual``.
    """
    return _plain(run_pgd, problem, tol, max_iter, warm_start, scaling, operator)


def _apgd(problem: ConicProblem, tol: float, max_iter: int, warm_start: np.ndarray | None,
          scaling: bool, operator: str, active_set: bool) -> MethodOutput:
    box = is_box(problem.cones) and box_kernel() is not None and operator != "factor"
    cones_2d = is_cone_2d(problem.cones) and cone_kernel() is not None
    fused = box or cones_2d
    finishing = active_set and not problem.cones.has_friction
    data, z, setup, start = _common(problem, warm_start, scaling, operator,
                                    assembled=box or finishing)
    if (out := _accept_warm_start(problem, data, z, tol, warm_start, setup, start)) is not None:
        return out
    finish = None
    if finishing:
        finish = ActiveSetFinish(data, problem.cones)
        guess = finish.active(z, data.product(z) + data.offset) if warm_start is not None \
            else finish.closed_rows()
        exact = finish.solve(guess)
        if exact is not None:
            tracker = ResidualTracker(data, tol)
            if tracker.record(exact, data.product(exact) + data.offset) == CONVERGED:
                info = {"fused_kernel": fused, "active_set_attempts": finish.attempts,
                        "active_set_solves": finish.solves}
                return _finalise(problem, data, tracker, CONVERGED, finish.solves, setup, start,
                                 info, finish)
            z = exact
    if cones_2d:
        tracker, status, iterations, _ = run_apgd_cones(data, problem.cones, z, tol, max_iter)
    elif box:
        tracker, status, iterations = run_apgd_box(data, z, tol, max_iter, finish)
    else:
        tracker, status, iterations, _ = run_apgd(data, z, tol, max_iter, callback=finish)
    info = {"fused_kernel": fused}
    if finish is not None:
        info.update(active_set_attempts=finish.attempts, active_set_solves=finish.solves)
        iterations += finish.solves
    return _finalise(problem, data, tracker, status, iterations, setup, start, info, finish)


@register("apgd", kind=FIRST_ORDER)
def apgd(problem: ConicProblem, *, tol: float = 1e-8, max_iter: int = 20000,
         warm_start: np.ndarray | None = None, scaling: bool = False,
         operator: str = "auto") -> MethodOutput:
    """Accelerated projected gradient with restart and backtracking (Mazhar et al. 2015).

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem with ``n_rows > 0`` rows.
    tol, max_iter, warm_start, scaling, operator
        See the module docstring.

    Returns
    -------
    MethodOutput
        Forces of shape (n_rows,); ``info`` holds ``products`` and ``best_residual``.
    """
    return _apgd(problem, tol, max_iter, warm_start, scaling, operator, active_set=False)


@register("apgd-jacobi", kind=FIRST_ORDER)
def apgd_jacobi(problem: ConicProblem, *, tol: float = 1e-8, max_iter: int = 20000,
                warm_start: np.ndarray | None = None, operator: str = "auto") -> MethodOutput:
    """``apgd`` on the Jacobi-scaled problem.

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem with ``n_rows > 0`` rows.
    tol, max_iter, warm_start, operator
        See the module docstring.

    Returns
    -------
    MethodOutput
        Forces of shape (n_rows,); ``info`` holds ``products`` and ``best_residual``.
    """
    return _apgd(problem, tol, max_iter, warm_start, True, operator, active_set=False)


@register("apgd-as", kind=FIRST_ORDER, polishing=True)
def apgd_active_set(problem: ConicProblem, *, tol: float = 1e-8, max_iter: int = 20000,
                    warm_start: np.ndarray | None = None,
                    operator: str = "auto") -> MethodOutput:
    """Jacobi-scaled APGD with an exact active-set finish (:class:`ActiveSetFinish`).

    ``iterations`` counts gradient iterations plus LDL^T solves. With friction
    rows the finish is skipped and this is ``apgd-jacobi``.

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem with ``n_rows > 0`` rows.
    tol, max_iter, warm_start, operator
        See the module docstring.

    Returns
    -------
    MethodOutput
        Forces of shape (n_rows,); ``info`` holds ``products`` and ``best_residual``.
    """
    return _apgd(problem, tol, max_iter, warm_start, True, operator, active_set=True)


@register("bb", kind=FIRST_ORDER)
def bb(problem: ConicProblem, *, tol: float = 1e-8, max_iter: int = 20000,
       warm_start: np.ndarray | None = None, scaling: bool = False,
       operator: str = "auto") -> MethodOutput:
    """Spectral (Barzilai-Borwein) projected gradient with a non-monotone line search.

    Parameters
    ----------
    problem : ConicProblem
        A normalised problem with ``n_rows > 0`` rows.
    tol, max_iter, warm_start, scaling, operator
        See the module docstring.

    Returns
    -------
    MethodOutput
        Forces of shape (n_rows,); ``info`` holds ``products`` and ``best_residual``.
    """
    return _plain(run_bb, problem, tol, max_iter, warm_start, scaling, operator)
