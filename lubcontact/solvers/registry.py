"""The solver registry: :func:`register`, :func:`methods`, :func:`solver_info` and :func:`solve`.

Each method is registered with what it can do (its :class:`SolverInfo`), in the
style of qpsolvers and cvxpy: ``solve`` dispatches by name, rejects a problem
the method does not accept with one message before any work, normalises the
problem (``problem.normalized()``: ``M = I``, ``dt = 1``, velocities O(1)),
calls the method, re-checks what it returns (finite forces, natural residual)
and maps the forces back to physical units. Residuals in results are in scaled
units and therefore comparable across scenes.

Methods never see a problem without contacts (``solve`` answers it: zero
forces, ``converged``, 0 iterations).

Adding a solver (see ``docs/guide/adding-a-solver.md``)::

    from lubcontact.solvers import CONVERGED, MethodOutput, register

    @register("my-pgd", kind="first-order")
    def my_pgd(problem, *, tol, max_iter=10000, warm_start=None):
        ...                               # problem: a normalised ConicProblem
        return MethodOutput(forces, CONVERGED, iterations)
"""
from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np

from .. import checks
from ..problem.cones import ConeKind, Cones
from ..problem.conic import ConicProblem
from ..problem.step import StepProblem
from .compiled_modules import kernels
from .result import (
    CONVERGED,
    DIVERGED,
    FAILED,
    INACCURATE,
    SUSPICIOUS_RESIDUAL,
    MethodOutput,
    SolveResult,
    residual_per_row,
)

FIRST_ORDER = "first-order"
INTERIOR_POINT = "interior-point"
QP = "qp"
NEWTON = "newton"
KINDS = (FIRST_ORDER, INTERIOR_POINT, QP, NEWTON)
"""Solver families: first-order (projected gradient, ADMM), interior point, QP-only,
semismooth Newton (a sparse factorisation per iteration)."""

ALL_CONES = frozenset(ConeKind)
CONVEX_CONES = frozenset(ConeKind) - {ConeKind.UNION}

Method = Callable[..., MethodOutput]
FirstTry = Callable[..., tuple[ConicProblem, MethodOutput] | None]


@dataclass(frozen=True)
class SolverInfo:
    """A registered method and what it can do.

    Attributes
    ----------
    name : str
        Registered name.
    function : callable
        ``function(problem, *, tol, max_iter, warm_start, **options) -> MethodOutput``,
        called on the normalised problem.
    kind : str
        One of :data:`KINDS`.
    cones : frozenset of ConeKind
        Force sets it accepts (``UNION``: the non-convex gluey + friction set).
    second_order : bool
        Whether it accepts genuine second-order friction cones (3D contacts).
    warm_start : bool
        Whether it uses a warm start (others ignore it).
    polishing : bool
        Whether its result is polished on its active set.
    step_only : bool
        Whether it needs a :class:`~lubcontact.problem.StepProblem` (a primal
        form over velocities and masses; a local problem has neither).
    native_coulomb : bool
        Whether it solves exact Coulomb friction itself (reading its input as
        the Coulomb problem with ``q = b - [s, 0]``, e.g. Siconos):
        :func:`~lubcontact.solvers.solve_coulomb` then runs it once and checks
        its forces at their own shift instead of iterating on ``s``
        (:func:`~lubcontact.solvers.coulomb.solve_native_coulomb`).
    description : str
        One line for tables and ``--help``.
    parameters : frozenset of str
        The keyword parameters of ``function`` (read once, at registration).
    first_try : callable or None
        A native Coulomb method's quick answer to its common case, the normalised problem and
        the method's output on it (:func:`register_first_try`), which
        :func:`~lubcontact.solvers.coulomb.solve_native_coulomb` tries first; None: none.
    """

    name: str
    function: Method
    kind: str
    cones: frozenset
    second_order: bool
    warm_start: bool
    polishing: bool
    step_only: bool
    native_coulomb: bool
    description: str
    parameters: frozenset = frozenset()
    first_try: FirstTry | None = None

    def rejection(self, problem: ConicProblem) -> str | None:
        """Why this method cannot solve ``problem``, or None when it can."""
        if self.step_only and not isinstance(problem, StepProblem):
            return "it needs a step problem (velocities and masses), not a local problem"
        cones = problem.cones
        unsupported = [] if self.cones == ALL_CONES else \
            sorted(kind.name for kind in cones.present_kinds - self.cones)
        if unsupported:
            return f"{' and '.join(unsupported)} contacts are not supported"
        if cones.has_friction and cones.tangent_dim > 1 and not self.second_order:
            return "second-order (3D) friction cones are not supported"
        return None


_REGISTRY: dict[str, SolverInfo] = {}


def register(name: str, *, kind: str = FIRST_ORDER, cones: Iterable[ConeKind] = ALL_CONES,
             second_order: bool = True, warm_start: bool = True, polishing: bool = False,
             step_only: bool = False, native_coulomb: bool = False,
             description: str = "") -> Callable[[Method], Method]:
    """Decorator registering a method under ``name`` with its capabilities.

    Parameters
    ----------
    name : str
        The name :func:`solve` and the command line use; must be new.
    kind : str
        One of :data:`KINDS`.
    cones : iterable of ConeKind
        Force sets the method accepts (default: all, the non-convex union included).
    second_order, warm_start, polishing, step_only, native_coulomb, description
        See :class:`SolverInfo`.

    Raises
    ------
    ValueError
        For a name already registered or an unknown kind.
    """
    if name in _REGISTRY:
        raise ValueError(f"name: solver {name!r} is already registered")
    if kind not in KINDS:
        raise ValueError(f"kind: must be one of {KINDS}, got {kind!r}")

    def wrap(function: Method) -> Method:
        doc = (function.__doc__ or "").strip().splitlines()
        _REGISTRY[name] = SolverInfo(name=name, function=function, kind=kind,
                                     cones=frozenset(ConeKind(k) for k in cones),
                                     second_order=second_order, warm_start=warm_start,
                                     polishing=polishing, step_only=step_only,
                                     native_coulomb=native_coulomb,
                                     description=description or (doc[0] if doc else ""),
                                     parameters=frozenset(inspect.signature(function).parameters))
        return function

    return wrap


def register_first_try(name: str) -> Callable[[FirstTry], FirstTry]:
    """Decorator giving the registered native Coulomb method ``name`` a first try.

    :func:`~lubcontact.solvers.coulomb.solve_native_coulomb` calls
    ``first_try(problem, *, tol, max_iter, warm_start, **options)`` on the physical problem,
    with the arguments checked and the method's options, before it normalises the problem. The
    first try answers the method's common case quickly: the normalised problem without shift
    (its ``scaling`` maps back) and the method's output on it, exactly what the method called on
    that problem would return (the general path then takes them as its first pass's, and the
    shift, the pieces and the check that follow are the same); or None, and the general path
    solves the problem from the start.

    Parameters
    ----------
    name : str
        A registered method with ``native_coulomb`` and no first try yet.

    Raises
    ------
    ValueError
        For a method that is not registered, one that does not solve exact Coulomb itself, or
        one that has a first try already.
    """
    info = solver_info(name)
    if not info.native_coulomb:
        raise ValueError(f"name: {name!r} does not solve exact Coulomb itself (native_coulomb)")
    if info.first_try is not None:
        raise ValueError(f"name: {name!r} has a first try already")

    def wrap(function: FirstTry) -> FirstTry:
        _REGISTRY[name] = replace(info, first_try=function)
        return function

    return wrap


def unregister(name: str) -> None:
    """Remove a registered method (for tests and interactive sessions)."""
    _REGISTRY.pop(name)


def methods(kind: str | None = None) -> list[str]:
    """Names of the registered methods, all or those of one ``kind`` (see :data:`KINDS`)."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"kind: must be one of {KINDS}, got {kind!r}")
    return sorted(name for name, info in _REGISTRY.items() if kind in (None, info.kind))


def solver_info(name: str) -> SolverInfo:
    """The :class:`SolverInfo` of a registered method."""
    if name not in _REGISTRY:
        raise ValueError(f"method: unknown solver {name!r}; registered: {', '.join(methods())}")
    return _REGISTRY[name]


def accepting_solver(name: str, problem: ConicProblem) -> SolverInfo:
    """The :class:`SolverInfo` of a registered method that can solve ``problem``.

    Raises
    ------
    ValueError
        For an unknown method, or one that cannot solve ``problem`` (the reason, and the
        methods that can).
    """
    info = solver_info(name)
    if (reason := info.rejection(problem)) is not None:
        raise ValueError(f"method: {name!r} cannot solve this problem: {reason}; "
                         f"methods that can: {', '.join(capable_methods(problem))}")
    return info


def solve(problem: ConicProblem, method: str = "clarabel", *, tol: float = 1e-9,
          max_iter: int | None = None, warm_start: np.ndarray | None = None,
          normalized: ConicProblem | None = None, **options) -> SolveResult:
    """Solve a step (or local) problem with a registered method.

    Parameters
    ----------
    problem : ConicProblem
        A :class:`~lubcontact.problem.StepProblem` or
        :class:`~lubcontact.problem.LocalProblem`, in physical units; it is
        normalised here.
    method : str
        A name from :func:`methods`.
    tol : float
        Stopping tolerance (scaled natural-map residual for iterative methods,
        gap and feasibility tolerance for interior-point methods).
    max_iter : int, optional
        Iteration cap, > 0 (method default when None).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces in physical units.
    normalized : ConicProblem, optional
        ``problem.normalized()`` when the caller holds it already: a caller
        that re-solves with another shift (the fixed point on s) prepares the
        normalised problem once and passes ``prepared.with_shift(s / length)``,
        which shares ``W`` instead of rebuilding it.
    **options
        Passed to the method.

    Raises
    ------
    ValueError
        For an unknown method, a problem it does not accept, or bad ``tol``,
        ``max_iter`` or ``warm_start``.
    """
    info = accepting_solver(method, problem)
    if not tol > 0:
        raise ValueError(f"tol: must be > 0, got {tol}")
    if max_iter is not None:
        max_iter = checks.integer("max_iter", max_iter, minimum=1)
    start = time.perf_counter()
    scaled = problem.normalized() if normalized is None else normalized
    checks.require(scaled.scaling is not None and scaled.n_rows == problem.n_rows, "normalized",
                   "must be the problem's normalized() form")
    scale = scaled.scaling
    normalise_time = time.perf_counter() - start
    if warm_start is not None:
        warm_start = np.asarray(warm_start, dtype=float) / scale.force
        if warm_start.shape != (problem.n_rows,):
            raise ValueError(f"warm_start: expected shape ({problem.n_rows},), got {warm_start.shape}")
        if not np.isfinite(warm_start).all():
            raise ValueError("warm_start: non-finite value")
    kwargs = dict(tol=tol, warm_start=warm_start, **options)
    if max_iter is not None:
        kwargs["max_iter"] = max_iter
    called = time.perf_counter()
    if problem.n_rows == 0:                  # no contact: nothing to solve, for every method
        out = MethodOutput(np.zeros(0), CONVERGED, 0)
    else:
        out = info.function(scaled, **kwargs)
    call_time = time.perf_counter() - called
    return checked(out, scaled, method, problem.shift, call_time, normalise_time)


def checked(out: MethodOutput, scaled: ConicProblem, method: str, shift: np.ndarray,
            call_time: float, normalise_time: float,
            constraint: np.ndarray | None = None) -> SolveResult:
    """A method's output checked on the problem it solved and mapped back to physical units.

    The check every result goes through (:func:`solve`, and
    :func:`~lubcontact.solvers.coulomb.solve_native_coulomb` on the forces of a method that solves
    exact Coulomb itself, at their own shift): non-finite forces are ``diverged`` (``failed``
    kept) and set to zero; the natural residual is computed from the forces, not taken from the
    method; a ``converged`` claim whose residual per row is above :data:`SUSPICIOUS_RESIDUAL`
    becomes ``inaccurate`` (``info["claimed_status"]`` keeps the claim).

    Parameters
    ----------
    out : MethodOutput
        In the units of ``scaled``.
    scaled : ConicProblem
        The normalised problem the forces are checked on (its ``scaling`` maps back).
    method : str
        The method's name, for the result.
    shift : ndarray, shape (nc,)
        The shift of the problem in physical units, for the result.
    call_time, normalise_time : float
        Seconds of the method's call (its own split where it gives one: :meth:`MethodOutput.times`)
        and of normalising, counted as set-up.
    constraint : ndarray, shape (n_rows,), optional
        ``g`` at the forces on ``scaled``, where the caller has computed it from them (``W r + b``
        through a dense ``W``, :func:`~lubcontact.solvers.coulomb.solve_native_coulomb`; its
        shift may differ from ``scaled``'s, which it then replaces); by default, and where the
        forces are not finite (replaced by zeros), ``g(v(r))`` from the velocities.
    """
    scale = scaled.scaling
    status = out.status
    forces = out.forces
    if not np.isfinite(forces).all():
        status = FAILED if status == FAILED else DIVERGED
        forces = np.zeros_like(forces)
    scaled_velocities = scaled.velocity(forces)      # the residual's and the result's
    if constraint is None or forces is not out.forces:
        constraint = scaled.constraint_values(scaled_velocities)
    residual = scaled.cones.natural_residual(forces, constraint, project=compiled_projection) \
        if forces.size else 0.0
    if status == CONVERGED and residual_per_row(residual, forces.size) > SUSPICIOUS_RESIDUAL:
        status = INACCURATE          # the method's claim does not survive an independent check
        out.info["claimed_status"] = CONVERGED
    physical = forces * scale.force
    if out.velocities is not None and status != DIVERGED and np.isfinite(out.velocities).all():
        scaled_velocities = out.velocities
    velocities = scaled_velocities * scale.velocity
    setup_time, solve_time = out.times(call_time)
    return SolveResult(x=physical, velocities=velocities, status=status,
                       iterations=out.iterations, residual=residual, method=method,
                       force_scale=scale.force, length_scale=scale.length,
                       setup_time=setup_time + normalise_time,
                       solve_time=solve_time, residual_history=out.residual_history,
                       info=out.info, shift=np.array(shift, dtype=float))


def compiled_projection(cones: Cones, x: np.ndarray) -> np.ndarray:
    """``P_K(x)`` for convex ``cones``: compiled on 2D cones once the compiled kernels are loaded
    (:func:`~lubcontact.solvers.kernels.project_cones`, the floating-point operations of
    :class:`~lubcontact.problem.cones.ConeProjector`), else ``cones.project(x)`` (a solve by a
    method without compiled loops does not import numba for its check). :func:`solve`'s check of a
    result: on small 2D problems the numpy projection's dozen array operations were about 5 % of
    a solve (docs/records/benchmarks.md, "small solves: the shift and the check's projection")."""
    if cones.tangent_dim != 1 or not kernels.cache_info().currsize:
        return cones.project(x)
    projector = cones.projector
    out = np.empty_like(x)
    kernels().project_cones(x, projector.lower, projector.upper, projector.friction_normal,
                            projector.planar_tangent, projector.friction_mu,
                            projector.friction_union, out)
    return out


def capable_methods(problem: ConicProblem, kind: str | None = None) -> list[str]:
    """Registered methods (of one ``kind``) that accept ``problem``."""
    return [name for name in methods(kind) if _REGISTRY[name].rejection(problem) is None]


def reference_method(problem: ConicProblem) -> str:
    """The symbolic reference for ``problem``: Clarabel on the primal form (``clarabel``) where
    velocities exist (a step problem), on the dual form (``clarabel-dual``) otherwise."""
    return "clarabel" if isinstance(problem, StepProblem) else "clarabel-dual"
