"""The one benchmark harness: timed solves, the untimed warm-up, the reference and method families.

Every benchmark command (``lubcontact compare``, ``lubcontact bench solvers``,
``lubcontact bench friction``, ``lubcontact check-hard``) and the demo's
table solve through :func:`timed_solve`, which calls
:meth:`~lubcontact.solvers.SolveSettings.solve` (exact Coulomb by the fixed
point on s, or one convex solve, as the settings say) and turns an exception
into a result to report: its message, and ``rejected`` for a ``ValueError``
(a problem the method does not accept, a bad argument) as opposed to a crash.

:func:`warm_up` solves once, untimed, with each method, so that numba
compilation and imports are never timed. Method families and the reference
come from the solver registry (:func:`lubcontact.solvers.solver_info`,
:func:`lubcontact.solvers.reference_method`), never from lists of names.
"""
from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..problem.conic import ConicProblem
from ..problem.metrics import relative_error
from ..problem.step import StepProblem
from ..solvers import CONVERGED, FIRST_ORDER, CoulombResult, SolveSettings, reference_method, solver_info

WARM_UP_TOL = 1e-2
WARM_UP_ITERATIONS = 20
"""Tolerance and iteration cap of the untimed warm-up solve (:func:`warm_up`)."""


@dataclass
class TimedSolve:
    """One timed solve: its result, or why there is none.

    Attributes
    ----------
    result : CoulombResult or None
        None when the method raised.
    seconds : float
        Wall-clock time of the whole call (set-up, solve, fixed point).
    message : str
        ``"ExceptionType: first line"`` when the method raised, else empty.
    rejected : bool
        The method raised a ``ValueError``: it does not accept the problem
        (or an argument), as opposed to crashing.
    """

    result: CoulombResult | None
    seconds: float
    message: str = ""
    rejected: bool = False


def timed_solve(problem: ConicProblem, settings: SolveSettings,
                warm_start: np.ndarray | None = None,
                shift: np.ndarray | None = None) -> TimedSolve:
    """Solve ``problem`` as ``settings`` say, timed; an exception is a result, not an error.

    Parameters
    ----------
    problem : ConicProblem
        In physical (or file) units.
    settings : SolveSettings
        Method, tolerances and the exact-Coulomb choice.
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces.
    shift : ndarray, shape (nc,), optional
        Initial shift of the fixed point on s.

    Returns
    -------
    TimedSolve
        Warnings of the solve are silenced: its status is in the result.
    """
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = settings.solve(problem, warm_start, shift)
    except Exception as exc:  # noqa: BLE001  (a solver's failure is a result to report)
        text = str(exc).splitlines()[0] if str(exc) else ""
        return TimedSolve(None, time.perf_counter() - start, f"{type(exc).__name__}: {text}",
                          rejected=isinstance(exc, ValueError))
    return TimedSolve(result, time.perf_counter() - start)


def warm_up(problem: ConicProblem, names: Sequence[str]) -> None:
    """One short untimed solve with each method, so that compilation and imports are never timed.

    Parameters
    ----------
    problem : ConicProblem
        Any problem the methods accept (the smallest at hand); failures are ignored.
    names : sequence of str
        Registered methods.
    """
    for method in names:
        timed_solve(problem, SolveSettings(method=method, tol=WARM_UP_TOL,
                                           max_iter=WARM_UP_ITERATIONS, exact_coulomb=False))


def iterative(method: str) -> bool:
    """Whether ``method`` is of the first-order family (its accuracy is bought by iterations)."""
    return solver_info(method).kind == FIRST_ORDER


REFERENCE_TRUST = 1e-8
"""Largest residual (the natural-map residual of the normalised problem, ``result.residual``)
at which a reference solve is trusted as the answer others are measured against; above it
the "errors" are distances to an inaccurate point (:func:`reference_distrust`)."""


def reference_distrust(result: CoulombResult) -> str:
    """Why a reference solve is not trusted ("" when it is): not converged, or its own residual
    above :data:`REFERENCE_TRUST` (e.g. Clarabel's polishing failing on a 10^5-grain pile).

    Parameters
    ----------
    result : CoulombResult
        The reference's solve.
    """
    if result.status != CONVERGED:
        return f"reference status {result.status}"
    if not result.residual <= REFERENCE_TRUST:
        return f"reference residual {result.residual:.1e} above {REFERENCE_TRUST:g}"
    return ""


def solve_reference(problem: ConicProblem, settings_for: Callable[[str], SolveSettings],
                    warm_start: np.ndarray | None = None,
                    shift: np.ndarray | None = None) -> tuple[str, TimedSolve]:
    """The reference solve of ``problem``, timed: the registry's
    :func:`~lubcontact.solvers.reference_method` (``clarabel`` on a step problem,
    ``clarabel-dual`` on a local one) run as ``settings_for(method)`` says.

    Parameters
    ----------
    problem : ConicProblem
    settings_for : callable
        ``settings_for(method) -> SolveSettings``.
    warm_start, shift : ndarray, optional
        As for :func:`timed_solve`.

    Returns
    -------
    (str, TimedSolve)
        The method used and its solve.
    """
    method = reference_method(problem)
    return method, timed_solve(problem, settings_for(method), warm_start, shift)


@dataclass
class MethodRow:
    """One method on one problem (:func:`compare_methods`)."""

    method: str
    status: str
    iterations: int
    setup_s: float
    solve_s: float
    total_s: float
    velocity_error: float
    residual: float
    min_gap: float
    message: str = ""


def compare_methods(problem: StepProblem, names: Sequence[str], tol: float = 1e-6,
                    reference_velocities: np.ndarray | None = None) -> list[MethodRow]:
    """Solve a step problem once with each method (one convex solve each, after the warm-up).

    Parameters
    ----------
    problem : StepProblem
    names : sequence of str
        Registered methods.
    tol : float
        Tolerance given to every method.
    reference_velocities : ndarray, optional
        Reference velocities; default: the reference solve (:func:`solve_reference`)
        at tol 1e-10 (polished).

    Returns
    -------
    list of MethodRow
        One per method; a method that raised has status ``error``, NaN measures and its message.

    Raises
    ------
    RuntimeError
        When the default reference solve fails.
    """
    if reference_velocities is None:
        _, reference = solve_reference(problem, lambda m: SolveSettings(method=m, tol=1e-10,
                                                                        exact_coulomb=False))
        if reference.result is None:
            raise RuntimeError(f"reference solve failed: {reference.message}")
        reference_velocities = reference.result.velocities
    warm_up(problem, names)
    rows = []
    for method in names:
        timed = timed_solve(problem, SolveSettings(method=method, tol=tol, exact_coulomb=False))
        result, nan = timed.result, float("nan")
        if result is None:
            rows.append(MethodRow(method, "error", -1, nan, nan, timed.seconds, nan, nan, nan,
                                  timed.message))
            continue
        gaps = problem.gaps_after(result.velocities)
        rows.append(MethodRow(method, result.status, int(result.iterations), result.setup_time,
                              result.solve_time, timed.seconds,
                              relative_error(result.velocities, reference_velocities),
                              float(result.residual), float(gaps.min()) if gaps.size else 0.0))
    return rows
