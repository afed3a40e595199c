"""Reference methods: the symbolic cvxpy forms solved by Clarabel (and other conic solvers).

Registered names:

- ``clarabel``: the primal form (over velocities) through cvxpy, forces read
  from the constraint multipliers: the reference. The primal is strongly
  convex with a unique solution; the dual's optimal set is unbounded when
  the packing has self-stress states (a null space of W inside the cones),
  and there the interior point drifts to huge forces and wrong velocities
  while reporting success (docs/records/hard_cases.md, finding 2).
- ``clarabel-dual``: the dual form (over forces) through cvxpy.

Non-convex (UNION) contacts, gluey + friction at gamma_min, are solved by the
branch rule of :func:`solve_branches`: fix each UNION contact on one piece
(pushed: Coulomb cone; pulled: ``lam_n <= 0``), starting from the sign of the
warm start's normal force (pushed when none), solve the convex problem, flip
every contact that violates the optimality condition of the union, re-solve;
at most ``max_branch_rounds`` rounds.

Clarabel runs with ``direct_solve_method="qdldl"`` (the automatic choice picked a
slower multithreaded factorisation, docs/guide/model.md section 9) and equal absolute and
relative gap/feasibility tolerances ``tol``. An interior-point gap ``tol`` only
bounds velocities to about ``sqrt(tol)`` (worse at the friction-cone apex), so
solutions are then polished on their active set
(:mod:`lubcontact.solvers.polish`: frictionless, frictional, mixed and 3D
problems, 3D sliding directions by Newton's method; a result whose active set
does not settle is left as it is) to reach velocities accurate to about 1e-12 (natural
residuals of 1e-14 to 6e-10 on 10 000-grain gluey steps, whose dependent contacts need the
polish's second proximal weight: ``polish.PROXIMAL_WEIGHTS``).
``info["polished"]`` says whether it was. An interior point that stopped short of ``tol``
(``inaccurate`` or ``max_iter``) but whose polish is accepted is ``converged`` where the polished
natural residual per row (rms) meets ``tol`` (:func:`~lubcontact.solvers.polish.polished_status`,
for ``clarabel``, ``clarabel-dual`` and ``clarabel-direct``).
"""
from __future__ import annotations

import time
import warnings

import cvxpy as cp
import numpy as np

from ..problem import symbolic
from ..problem.cones import ConeKind
from ..problem.step import StepProblem
from .polish import polish as polish_active_set
from .polish import polished_status
from .registry import INTERIOR_POINT, register
from .result import CONVERGED, FAILED, INACCURATE, MAX_ITER, MethodOutput

_STATUS = {cp.OPTIMAL: CONVERGED, cp.OPTIMAL_INACCURATE: INACCURATE,
           cp.USER_LIMIT: MAX_ITER}


def clarabel_settings(tol: float, max_iter: int) -> dict:
    """Clarabel options for a target tolerance (as cvxpy keyword arguments)."""
    return dict(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, tol_ktratio=min(1e-6, tol),
                max_iter=max_iter, direct_solve_method="qdldl")


def _solve_symbolic(step: StepProblem, form: str, tol: float, max_iter: int,
                    polyhedral: bool, polish: bool = True) -> MethodOutput:
    start = time.perf_counter()
    builder = symbolic.dual_form if form == "dual" else symbolic.primal_form
    symbolic_form = builder(step, polyhedral)
    built = time.perf_counter()
    try:
        with warnings.catch_warnings():      # "Solution may be inaccurate": the status says it
            warnings.filterwarnings("ignore", message="Solution may be inaccurate",
                                    category=UserWarning)
            symbolic_form.problem.solve(solver=cp.CLARABEL, **clarabel_settings(tol, max_iter))
    except cp.error.SolverError as exc:
        return MethodOutput(np.full(step.n_rows, np.nan), FAILED, 0, built - start,
                            time.perf_counter() - built, info={"error": str(exc)})
    stats = symbolic_form.problem.solver_stats
    # cvxpy's canonicalisation happens inside solve(): count it as set-up
    canonicalise = time.perf_counter() - built - float(stats.solve_time or 0.0)
    status = _STATUS.get(symbolic_form.problem.status, FAILED)
    if status == FAILED:
        return MethodOutput(np.full(step.n_rows, np.nan), FAILED, int(stats.num_iters or 0),
                            built - start + canonicalise, float(stats.solve_time or 0.0),
                            info={"raw_status": symbolic_form.problem.status, "form": form})
    forces, velocities = symbolic_form.forces(step), symbolic_form.velocities(step)
    polished, polish_start = False, time.perf_counter()
    if polish:
        forces, polished = polish_active_set(step, forces)
        velocities = step.velocity(forces) if polished else velocities
        status = polished_status(status, step, forces, polished, tol)
    return MethodOutput(forces=forces, status=status, iterations=int(stats.num_iters or 0),
                        setup_time=built - start + canonicalise,
                        solve_time=float(stats.solve_time or 0.0) + time.perf_counter() - polish_start,
                        info={"raw_status": symbolic_form.problem.status, "form": form,
                              "polished": polished},
                        velocities=velocities)


def union_violation(step: StepProblem, forces: np.ndarray) -> np.ndarray:
    """Per contact, ``|lam_c - P_Kc(lam_c - g_c)|`` with ``K_c`` the (possibly non-convex) set.

    Zero (up to solver accuracy) on every contact at a stationary point of the
    original problem; for a UNION contact, the projection is onto the union.

    Returns
    -------
    ndarray, shape (nc,)
    """
    cones = step.cones
    difference = forces - cones.project(forces - step.gradient(forces))
    normal, tangential = cones.split(difference)
    violation = normal**2
    if cones.has_friction:
        violation[cones.tangential] += np.sum(tangential**2, axis=1)
    return np.sqrt(violation)


def solve_branches(step: StepProblem, form: str, tol: float, max_iter: int, polyhedral: bool,
                   warm_start: np.ndarray | None, max_branch_rounds: int) -> MethodOutput:
    """The branch rule for UNION contacts (module docstring).

    A contact is flipped when its union violation exceeds
    ``max(1e3 tol, 1e-7)`` (normalised units). ``info`` reports the rounds,
    the flips per round and the pulled branches; the status is
    ``inaccurate`` if contacts were still inconsistent after the last round.
    """
    union = step.cones.mask(ConeKind.UNION)
    pulled = np.zeros(step.n_contacts, dtype=bool)
    if warm_start is not None:
        pulled = step.cones.pulled(warm_start)
    threshold = max(1e3 * tol, 1e-7)
    flips, setup, solve_time, iterations = [], 0.0, 0.0, 0
    for _ in range(max_branch_rounds):
        branch = step.with_cones(step.cones.with_branches(pulled))
        out = _solve_symbolic(branch, form, tol, max_iter, polyhedral)
        setup, solve_time = setup + out.setup_time, solve_time + out.solve_time
        iterations += out.iterations
        if out.status == FAILED:
            break
        inconsistent = union & (union_violation(step, out.forces) > threshold)
        flips.append(int(np.count_nonzero(inconsistent)))
        if not inconsistent.any():
            break
        pulled = pulled ^ inconsistent
    status = out.status
    if flips and flips[-1] > 0 and status == CONVERGED:
        status = INACCURATE
    info = dict(out.info, branch_rounds=len(flips), branch_flips=flips,
                pulled=np.flatnonzero(union & pulled))
    return MethodOutput(forces=out.forces, status=status, iterations=iterations, setup_time=setup,
                        solve_time=solve_time, info=info, velocities=out.velocities)


def _solve(step: StepProblem, form: str, tol: float, max_iter: int, polyhedral: bool,
           warm_start: np.ndarray | None, max_branch_rounds: int) -> MethodOutput:
    if step.cones.is_convex:
        return _solve_symbolic(step, form, tol, max_iter, polyhedral)
    return solve_branches(step, form, tol, max_iter, polyhedral, warm_start, max_branch_rounds)


@register("clarabel-dual", kind=INTERIOR_POINT, warm_start=False, polishing=True)
def clarabel_dual(step: StepProblem, *, tol: float = 1e-10, max_iter: int = 200,
                  warm_start: np.ndarray | None = None, polyhedral: bool = False,
                  max_branch_rounds: int = 8) -> MethodOutput:
    """Clarabel on the symbolic dual form.

    ``warm_start`` only chooses the initial branch of UNION contacts.
    """
    return _solve(step, "dual", tol, max_iter, polyhedral, warm_start, max_branch_rounds)


@register("clarabel", kind=INTERIOR_POINT, warm_start=False, polishing=True, step_only=True)
def clarabel_primal(step: StepProblem, *, tol: float = 1e-10, max_iter: int = 200,
                    warm_start: np.ndarray | None = None, polyhedral: bool = False,
                    max_branch_rounds: int = 8) -> MethodOutput:
    """Clarabel on the symbolic primal form (``warm_start`` as for ``clarabel-dual``)."""
    return _solve(step, "primal", tol, max_iter, polyhedral, warm_start, max_branch_rounds)
