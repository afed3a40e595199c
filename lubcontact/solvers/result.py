"""What a solve returns: statuses, :class:`SolveResult`, and the non-convergence policy.

Every method returns a :class:`MethodOutput` in the normalised problem's
units; :func:`lubcontact.solvers.solve` checks it (finite forces, natural
residual) and maps it back to a :class:`SolveResult` in physical units.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

CONVERGED = "converged"
MAX_ITER = "max_iter"
DIVERGED = "diverged"
INACCURATE = "inaccurate"
FAILED = "failed"
STATUSES = (CONVERGED, MAX_ITER, DIVERGED, INACCURATE, FAILED)

SUSPICIOUS_RESIDUAL = 1e-3
"""A ``converged`` claim whose natural residual per row (:func:`residual_per_row`)
exceeds this is downgraded to ``inaccurate``: solutions this far from optimal
are wrong, whatever the method says (e.g. an interior point drifting along an
unbounded optimal face of the dual)."""


def residual_per_row(residual: float, n_rows: int) -> float:
    """A natural residual's 2-norm divided by ``sqrt(n_rows)`` (an rms over the rows): the
    figure that does not grow with the problem's size, which the result checks compare
    (:data:`SUSPICIOUS_RESIDUAL`, ``max_residual`` of :func:`check_status`)."""
    return residual / np.sqrt(max(n_rows, 1))


class SolverError(RuntimeError):
    """Raised when a solve fails and the policy says to stop."""


class SolverWarning(RuntimeWarning):
    """Issued when a solve did not converge and the policy says to go on."""


@dataclass
class MethodOutput:
    """What a registered method returns, in the normalised problem's units.

    Attributes
    ----------
    forces : ndarray, shape (n_rows,)
        Scaled contact forces.
    status : str
        One of :data:`STATUSES`.
    iterations : int
        Iterations of the method.
    setup_time, solve_time : float, optional
        Seconds spent building the method's data and iterating (both None: see :meth:`times`).
    residual_history : ndarray
        The residuals the method recorded, in order (may be empty): one per iteration, or one
        per check where a method tests its stop less often (``nsgs``; ``apgd`` and its
        variants on 2D friction cones, every :data:`.compiled_apgd.CHECK_EVERY` iterations).
    info : dict
        Method-specific extras.
    velocities : ndarray, shape (n_dof,), optional
        Scaled velocities, for a method that computes them directly (a
        primal form); otherwise they are derived from the forces.
    """

    forces: np.ndarray
    status: str
    iterations: int
    setup_time: float | None = None
    solve_time: float | None = None
    residual_history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    info: dict = field(default_factory=dict)
    velocities: np.ndarray | None = None

    def times(self, call_time: float) -> tuple[float, float]:
        """``(setup, solve)`` seconds: the method's own, or ``call_time`` (the whole call's, s)
        as solve time when it left both at None."""
        if self.setup_time is None and self.solve_time is None:
            return 0.0, call_time
        return self.setup_time or 0.0, self.solve_time or 0.0


@dataclass
class SolveResult:
    """Outcome of one solve, in physical units.

    Attributes
    ----------
    x : ndarray, shape (n_rows,)
        Contact forces ``lam`` (also available as ``forces``).
    velocities : ndarray, shape (n_dof,)
        ``v = U + dt M^-1 H^T lam`` (local velocities ``W r + q`` for a local problem).
    status : str
        One of ``converged``, ``max_iter``, ``diverged``, ``inaccurate``, ``failed``.
    iterations : int
        Iterations of the method (interior-point or gradient steps).
    residual : float
        Natural-map residual of the returned forces on the normalised problem.
    method : str
        Registered name of the method.
    force_scale : float
        The force unit of the normalised problem (``m_ref V / dt``): forces
        below ``tol x force_scale`` are numerically zero.
    length_scale : float
        The length unit of the normalised problem (``dt V``), that of gaps.
    setup_time, solve_time : float
        Seconds spent normalising and building the method's data, and iterating.
    residual_history : ndarray
        The residuals the method recorded, in order (may be empty): one per iteration, or one
        per check where a method tests its stop less often (``nsgs``; ``apgd`` and its
        variants on 2D friction cones, every :data:`.compiled_apgd.CHECK_EVERY` iterations).
    info : dict
        Method-specific extras (e.g. the raw solver status).
    shift : ndarray, shape (nc,)
        The shift ``s`` the problem was solved with (physical length units).
    """

    x: np.ndarray
    velocities: np.ndarray
    status: str
    iterations: int
    residual: float
    method: str
    force_scale: float = 1.0
    length_scale: float = 1.0
    setup_time: float = 0.0
    solve_time: float = 0.0
    residual_history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    info: dict = field(default_factory=dict)
    shift: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def forces(self) -> np.ndarray:
        return self.x

    @property
    def success(self) -> bool:
        return self.status == CONVERGED

    @property
    def residual_per_row(self) -> float:
        """``residual / sqrt(n_rows)`` (:func:`residual_per_row`)."""
        return residual_per_row(self.residual, self.x.size)


@dataclass
class CoulombResult(SolveResult):
    """A solve of exact Coulomb friction by the fixed point on s (:func:`~lubcontact.solvers.solve_coulomb`).

    The inherited fields describe the last inner solve (solved with ``shift``
    frozen), except ``status`` (``converged`` only if the fixed point and the
    last inner solve converged), ``iterations`` (all inner iterations, the
    joint phase's included), and ``setup_time`` and ``solve_time`` (summed over
    the inner solves, normalising in ``setup_time``, the joint phase's time in
    ``solve_time``; the rest of the call, the fixed point's own work and the
    checks, a native method's included, is in neither). A problem
    without friction, or the convex relaxation, is one inner solve:
    ``outer_iterations = 1``.

    Attributes
    ----------
    outer_iterations : int
        Inner solves done.
    shift_change : float
        Last relative change of ``s`` (the stopping measure).
    force_change : float
        Last relative change of the forces (rms norm; inf after one solve).
    inner_status : str
        Status of the last inner solve.
    fixed_point_converged : bool
        Whether the fixed point met its tolerance.
    shift_history : ndarray
        ``shift_change`` after each outer iteration.
    pulled : ndarray of int
        UNION contacts on their pulled piece at the end.
    branch_flips : list of int
        UNION contacts that changed piece after each outer iteration.
    joint_iterations : int
        APGD iterations of the joint phase (0 without one).
    """

    outer_iterations: int = 1
    shift_change: float = 0.0
    force_change: float = np.inf
    inner_status: str = CONVERGED
    fixed_point_converged: bool = True
    shift_history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pulled: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    branch_flips: list = field(default_factory=list)
    joint_iterations: int = 0

    @classmethod
    def single(cls, result: SolveResult) -> CoulombResult:
        """One convex solve (no friction, or the relaxation), its shift frozen."""
        return cls(**vars(result), inner_status=result.status)


def check_status(result: SolveResult, policy: str, max_residual: float | None = None) -> None:
    """Apply a non-convergence policy: ``"raise"``, ``"warn"`` or ``"ignore"``.

    Parameters
    ----------
    result : SolveResult
    policy : str
        What a status other than ``converged`` does.
    max_residual : float, optional
        A result that did not converge with a residual per row
        (:attr:`SolveResult.residual_per_row`) above this (or NaN) is not a
        solution whatever the policy: it raises.

    Raises
    ------
    SolverError
        When the status is not ``converged`` and ``policy == "raise"``, or its
        residual per row is above ``max_residual``.
    """
    if result.success:
        return
    message = (f"{result.method}: status {result.status} after {result.iterations} iterations, "
               f"residual {result.residual:.3e}")
    if max_residual is not None and not result.residual_per_row <= max_residual:
        raise SolverError(f"{message} ({result.residual_per_row:.3e} per row), above the largest "
                          f"accepted {max_residual:g}")
    if policy == "ignore":
        return
    if policy == "raise":
        raise SolverError(message)
    warnings.warn(message, SolverWarning, stacklevel=3)
