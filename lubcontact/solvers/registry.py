"""Solver interface shared by every method: a registry, ``solve`` and ``SolveResult``.

Every method receives the *normalised* problem (``StepProblem.normalized``:
``M = I``, ``dt = 1``, velocities O(1)) and returns scaled forces; ``solve``
maps them back to physical units. Residuals in results are in scaled units
and therefore comparable across scenes.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..problem.step import StepProblem

CONVERGED = "converged"
MAX_ITER = "max_iter"
DIVERGED = "diverged"
INACCURATE = "inaccurate"
FAILED = "failed"
STATUSES = (CONVERGED, MAX_ITER, DIVERGED, INACCURATE, FAILED)


SUSPICIOUS_RESIDUAL = 1e-3
"""A ``converged`` claim whose natural residual (normalised units, per sqrt(row))
exceeds this is downgraded to ``inaccurate``: solutions this far from optimal
are wrong, whatever the method says (e.g. an interior point drifting along an
unbounded optimal face of the dual)."""


class SolverError(RuntimeError):
    """Raised when a solve fails and the policy says to stop."""


class SolverWarning(RuntimeWarning):
    """Issued when a solve did not converge and the policy says to go on."""


@dataclass
class SolveResult:
    """Outcome of one solve, in physical units.

    Attributes
    ----------
    x : ndarray, shape (n_rows,)
        Contact forces ``lam`` (also available as ``forces``).
    velocities : ndarray, shape (n_dof,)
        ``v = U + dt M^-1 H^T lam``.
    status : str
        One of ``converged``, ``max_iter``, ``diverged``, ``inaccurate``, ``failed``.
    iterations : int
        Iterations of the method (interior-point or gradient steps).
    residual : float
        Natural-map residual of the returned forces on the normalised problem.
    residual_history : ndarray
        Residual per iteration where the method records it (may be empty).
    setup_time, solve_time : float
        Seconds spent building the method's data, and iterating.
    method : str
        Registered name of the method.
    force_scale : float
        The force unit of the normalised problem (``m_ref V / dt``): forces
        below ``tol x force_scale`` are numerically zero.
    info : dict
        Method-specific extras (e.g. the raw solver status).
    """

    x: np.ndarray
    velocities: np.ndarray
    status: str
    iterations: int
    residual: float
    method: str
    force_scale: float = 1.0
    setup_time: float = 0.0
    solve_time: float = 0.0
    residual_history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    info: dict = field(default_factory=dict)

    @property
    def forces(self) -> np.ndarray:
        return self.x

    @property
    def success(self) -> bool:
        return self.status == CONVERGED


@dataclass
class MethodOutput:
    """What a registered method returns, in the normalised problem's units.

    ``velocities`` is optional: a method that computes them directly (a primal
    form) returns them; otherwise they are derived from the forces.
    """

    forces: np.ndarray
    status: str
    iterations: int
    setup_time: float
    solve_time: float
    residual_history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    info: dict = field(default_factory=dict)
    velocities: np.ndarray | None = None


Method = Callable[..., MethodOutput]
_METHODS: dict[str, Method] = {}


def register(name: str):
    """Decorator registering ``fn(problem, *, tol, max_iter, warm_start, **options)``."""

    def wrap(fn: Method) -> Method:
        _METHODS[name] = fn
        return fn

    return wrap


def methods() -> list[str]:
    """Names of the registered methods."""
    return sorted(_METHODS)


def solve(problem: StepProblem, method: str = "clarabel", *, tol: float = 1e-9,
          max_iter: int | None = None, warm_start: np.ndarray | None = None,
          **options) -> SolveResult:
    """Solve a step problem with a registered method.

    Parameters
    ----------
    problem : StepProblem
        In physical units; it is normalised here.
    method : str
        A name from :func:`methods`.
    tol : float
        Stopping tolerance (scaled natural-map residual for iterative methods,
        gap and feasibility tolerance for interior-point methods).
    max_iter : int, optional
        Iteration cap (method default when None).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces in physical units.
    **options
        Passed to the method.
    """
    if method not in _METHODS:
        raise ValueError(f"method: unknown solver {method!r}; registered: {', '.join(methods())}")
    if not tol > 0:
        raise ValueError(f"tol: must be > 0, got {tol}")
    start = time.perf_counter()
    scaled = problem.normalized()
    scale = scaled.scaling
    normalise_time = time.perf_counter() - start
    if warm_start is not None:
        warm_start = np.asarray(warm_start, dtype=float) / scale.force
        if warm_start.shape != (problem.n_rows,):
            raise ValueError(f"warm_start: expected shape ({problem.n_rows},), got {warm_start.shape}")
        if not np.all(np.isfinite(warm_start)):
            raise ValueError("warm_start: non-finite value")
    kwargs = dict(tol=tol, warm_start=warm_start, **options)
    if max_iter is not None:
        kwargs["max_iter"] = int(max_iter)
    out = _METHODS[method](scaled, **kwargs)
    status = out.status
    forces = out.forces
    if not np.all(np.isfinite(forces)):
        status = FAILED if status == FAILED else DIVERGED
        forces = np.zeros_like(forces)
    residual = scaled.natural_residual(forces) if forces.size else 0.0
    if status == CONVERGED and residual > SUSPICIOUS_RESIDUAL * np.sqrt(max(forces.size, 1)):
        status = INACCURATE          # the method's claim does not survive an independent check
        out.info["claimed_status"] = CONVERGED
    physical = forces * scale.force
    if out.velocities is not None and status != DIVERGED and np.all(np.isfinite(out.velocities)):
        velocities = out.velocities * scale.velocity
    else:
        velocities = problem.velocity(physical)
    return SolveResult(x=physical, velocities=velocities, status=status,
                       iterations=out.iterations, residual=residual, method=method,
                       force_scale=scale.force,
                       setup_time=out.setup_time + normalise_time, solve_time=out.solve_time,
                       residual_history=out.residual_history, info=out.info)


def check_status(result: SolveResult, policy: str) -> None:
    """Apply a non-convergence policy: ``"raise"``, ``"warn"`` or ``"ignore"``.

    Raises
    ------
    SolverError
        When the status is not ``converged`` and ``policy == "raise"``.
    """
    if result.success or policy == "ignore":
        return
    message = (f"{result.method}: status {result.status} after {result.iterations} iterations, "
               f"residual {result.residual:.3e}")
    if policy == "raise":
        raise SolverError(message)
    warnings.warn(message, SolverWarning, stacklevel=3)
