"""``newton-ac``'s first try: a small 2D exact-Coulomb step solved without the general layers.

A small system's step (a 2D problem on the compiled lane with friction cones, warm-started from
the previous step) is the common case of exact Coulomb by ``newton-ac``:
its first strategy (the proximal loop at :data:`~.newton.WARM_DENSE_WEIGHT` from the warm start)
converges in its first compiled call on almost every step. Around that call the general path
(:func:`~lubcontact.solvers.coulomb.solve_native_coulomb`, :func:`~.newton.newton_alart_curnier`,
:func:`~.newton._strategies`, :func:`~.newton._proximal_newton`, the registry's check) spent more
than the call itself: on steps of a settling 4-grain pile (6 contacts) 250-290 us a solve, of
which the Newton phase took 25 us; the first try takes 0.58-0.69 of that time at 6-66 contacts
(docs/records/benchmarks.md, "newton-ac's first try on small steps").

:func:`first_try` runs that call on arrays prepared by the same functions as the general path
(the normalised problem's dense ``W``, built at once: ``StepProblem.normalized(dense=True)``,
its ``b``, :func:`~.newton.contact_steps`, :func:`~.newton.box_rows`,
:func:`~.newton.dense_elimination`), so where it converges its forces, iterations and record are
the general path's. It checks them as the general path does, at their
own shift ``s* = mu |u_T|`` (:func:`~lubcontact.problem.metrics.coulomb_shift`), each UNION
contact on the piece of its force: the natural residual from the forces, and the same test of a
suspicious residual. Where the call does not
converge, or the check would change the status, it returns None and the general path solves the
step from the start (its first call then repeats this one). It reads :mod:`.newton`'s rules
(its constants) at each call, as the general path does, and applies only where the general path
chains the solved subproblems in that call (``CHAINED_SUBPROBLEMS``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..problem.conic import ConicProblem
from ..problem.metrics import coulomb_shift
from ..problem.step import StepProblem
from . import newton
from .compiled_modules import kernels
from .newton import _Phase
from .registry import compiled_projection, register_first_try
from .result import CONVERGED, SUSPICIOUS_RESIDUAL, CoulombResult, residual_per_row


@dataclass
class _CompiledLane:
    """The arrays of :class:`~.newton.AlartCurnier` that a compiled Newton phase reads
    (:func:`~.newton._compiled_phase`), of one normalised problem, at one proximal weight."""

    W: np.ndarray
    w_arrays: tuple
    q: np.ndarray
    rho: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    box: np.ndarray
    cone_n: np.ndarray
    tangent_rows: np.ndarray
    cone_mu: np.ndarray
    unilateral: np.ndarray
    sigma: float
    center: np.ndarray
    q_scale: float
    elimination_places: np.ndarray
    typical: float


@register_first_try("newton-ac")
def first_try(problem: ConicProblem, *, tol: float, max_iter: int | None = None,
              warm_start: np.ndarray | None = None, fallback: str | None = "auto",
              joint: int = 0) -> CoulombResult | None:
    """Exact Coulomb by ``newton-ac`` on a small warm-started 2D step, or None (module docstring).

    Parameters
    ----------
    problem : ConicProblem
        In physical units, with friction; its shift is ignored, as by the general path.
    tol : float
        The FCLIB error to reach, > 0.
    max_iter : int, optional
        The cap on Newton iterations (:data:`~.newton.MAX_ITERATIONS` when None).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (physical units); without one (or with zero forces) there is no first try.
    fallback, joint
        ``newton-ac``'s options (:func:`~.newton.newton_alart_curnier`), accepted as it accepts
        them; neither acts where the first call converges.

    Returns
    -------
    CoulombResult or None
        ``converged``, with the general path's forces, iterations and ``info``; None where the
        problem is not such a step (a local problem, 3D cones, no friction cone, more rows than
        the small compiled lane takes, no warm start), where the first compiled call did not
        converge, or where its forces would not pass the check as ``converged``. UNION contacts
        are solved natively, as by the general path, and checked on the piece of their force
        (``pulled`` lists those pulled).
    """
    cones = problem.cones
    if warm_start is None or not newton.CHAINED_SUBPROBLEMS or not isinstance(problem, StepProblem) \
            or not cones.has_friction or not all(newton.lanes(problem)):
        return None
    max_iter = newton.MAX_ITERATIONS if max_iter is None else max_iter
    clock = time.perf_counter()
    unshifted = problem if not problem.shift.any() else problem.with_shift(np.zeros(cones.count))
    scaled = unshifted.normalized(dense=True)  # as the general path's copy: no cache on the caller's
    forces = warm_start / scaled.scaling.force
    if not forces.any():
        return None
    lane = _prepared(scaled, forces)
    velocity = lane.W @ forces + lane.q
    error = float(kernels().coulomb_error_2d(forces, velocity, lane.lower, lane.upper, lane.cone_n,
                                             lane.tangent_rows, lane.cone_mu, lane.unilateral,
                                             lane.q_scale))
    setup_time = time.perf_counter() - clock
    phase = _first_call(lane, forces, error, tol, max_iter)
    if phase.status != CONVERGED:
        return None
    solve_time = time.perf_counter() - clock - setup_time
    return _checked(problem, scaled, phase, setup_time, solve_time)


def _prepared(scaled: StepProblem, forces: np.ndarray) -> _CompiledLane:
    """The compiled lane's arrays of ``scaled`` (as :class:`~.newton.AlartCurnier` builds them),
    at the first strategy's weight, centred at ``forces``."""
    cones = scaled.cones
    projector = cones.projector
    W = np.ascontiguousarray(scaled.dense_delassus)
    rho, typical = newton.contact_steps(W.diagonal()[:cones.count], cones)
    q = scaled.offset.copy()
    w_arrays, places = newton.dense_elimination(W)
    return _CompiledLane(W=W, w_arrays=w_arrays, q=q, rho=rho, lower=projector.lower.copy(),
                         upper=projector.upper.copy(), box=newton.box_rows(cones),
                         cone_n=projector.friction_normal, tangent_rows=projector.planar_tangent,
                         cone_mu=projector.friction_mu, unilateral=~projector.friction_union,
                         sigma=newton.WARM_DENSE_WEIGHT * typical, center=forces,
                         q_scale=newton.fclib_scale(q), elimination_places=places, typical=typical)


def _first_call(lane: _CompiledLane, forces: np.ndarray, error: float, tol: float,
                max_iter: int) -> _Phase:
    """The first strategy's first compiled call from ``forces`` (FCLIB ``error``), as
    :func:`~.newton._proximal_newton` makes it; ``converged`` where its best iterate is within
    ``tol`` (none where ``forces`` are)."""
    if error <= tol:
        return _Phase(forces=forces, status=CONVERGED, iterations=0, error=error,
                      history=np.array([error]), gradient_steps=0,
                      strategies=[(newton.WARM_DENSE_WEIGHT, "warm")])
    inner = newton._compiled_phase(lane, forces, tol, min(newton.INNER_CAP, max_iter),
                                   newton.INNER_REDUCTION * error * lane.q_scale,
                                   chain=(max_iter, newton.STALL_WINDOW, newton.SIGMA_DECREASE))
    best_error, best = min((error, forces), inner.chained.best, key=lambda pair: pair[0])
    return _Phase(forces=best, status=CONVERGED if best_error <= tol else inner.status,
                  iterations=inner.iterations, error=best_error,
                  history=np.concatenate([[error], inner.history[1:]]),
                  gradient_steps=inner.gradient_steps, proximal_steps=inner.chained.subproblems,
                  strategies=[(newton.WARM_DENSE_WEIGHT, "warm")])


def _checked(problem: StepProblem, scaled: StepProblem, phase: _Phase, setup_time: float,
             solve_time: float) -> CoulombResult | None:
    """``phase``'s forces checked at their own shift and mapped back (the general path's
    check, :func:`~lubcontact.solvers.registry.checked`), or None where the check would not
    keep them ``converged`` (a suspicious residual). Their FCLIB error, from them and their
    velocity ``W r + b``, is within ``tol``: both are finite, and so is their shift."""
    forces = phase.forces
    cones = scaled.cones
    pulled = cones.pulled(forces)             # each UNION contact on the piece of its force
    prepared = scaled if cones.is_convex else scaled.with_cones(cones.with_branches(pulled))
    gradient = scaled.dense_delassus @ forces + scaled.offset
    shift = coulomb_shift(prepared, forces, gradient)       # none on a pulled piece
    gradient[:problem.n_contacts] += shift            # g at the shift: W r + b + [s, 0]
    residual = prepared.cones.natural_residual(forces, gradient, project=compiled_projection)
    if residual_per_row(residual, forces.size) > SUSPICIOUS_RESIDUAL:
        return None
    scale = scaled.scaling
    # the compiled lane keeps no factorisations, local sweeps or corrected steps
    info = dict(newton.phase_info(phase, 0), reused_factorisations=0, carried_orderings=0,
                pivoted_factorisations=0, local_sweeps=0, corrected_steps=0)
    return CoulombResult(x=forces * scale.force, velocities=scaled.velocity(forces) * scale.velocity,
                         status=CONVERGED, iterations=phase.iterations, residual=residual,
                         method="newton-ac", force_scale=scale.force, length_scale=scale.length,
                         setup_time=setup_time, solve_time=solve_time,
                         residual_history=phase.history, info=info, shift=shift * scale.length,
                         outer_iterations=1, shift_change=0.0, inner_status=CONVERGED,
                         fixed_point_converged=True, shift_history=np.zeros(1),
                         pulled=np.zeros(0, dtype=int) if cones.is_convex else np.flatnonzero(pulled),
                         branch_flips=[], joint_iterations=0)
