"""Reference methods: the symbolic cvxpy forms solved by Clarabel (and other conic solvers).

Registered names:

- ``clarabel``: the dual form (over forces) through cvxpy;
- ``clarabel-primal``: the primal form (over velocities) through cvxpy, forces
  read from the constraint multipliers.

Clarabel runs with ``direct_solve_method="qdldl"`` (the automatic choice picked a
slower multithreaded factorisation, MODEL.md section 9) and equal absolute and
relative gap/feasibility tolerances ``tol``.
"""
from __future__ import annotations

import time

import cvxpy as cp
import numpy as np

from .. import symbolic
from ..problem import StepProblem
from .base import CONVERGED, FAILED, INACCURATE, MAX_ITER, MethodOutput, register

_STATUS = {cp.OPTIMAL: CONVERGED, cp.OPTIMAL_INACCURATE: INACCURATE,
           cp.USER_LIMIT: MAX_ITER}


def clarabel_settings(tol: float, max_iter: int) -> dict:
    """Clarabel options for a target tolerance (as cvxpy keyword arguments)."""
    return dict(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, tol_ktratio=min(1e-6, tol),
                max_iter=max_iter, direct_solve_method="qdldl")


def _solve_symbolic(step: StepProblem, form: str, tol: float, max_iter: int,
                    polyhedral: bool) -> MethodOutput:
    start = time.perf_counter()
    if step.n_rows == 0:
        return MethodOutput(np.zeros(0), CONVERGED, 0, 0.0, 0.0)
    builder = symbolic.dual_form if form == "dual" else symbolic.primal_form
    symbolic_form = builder(step, polyhedral)
    built = time.perf_counter()
    try:
        symbolic_form.problem.solve(solver=cp.CLARABEL, **clarabel_settings(tol, max_iter))
    except cp.error.SolverError as exc:
        return MethodOutput(np.full(step.n_rows, np.nan), FAILED, 0, built - start,
                            time.perf_counter() - built, info={"error": str(exc)})
    stats = symbolic_form.problem.solver_stats
    status = _STATUS.get(symbolic_form.problem.status, FAILED)
    forces = (symbolic_form.forces(step) if status != FAILED else np.full(step.n_rows, np.nan))
    return MethodOutput(forces=forces, status=status, iterations=int(stats.num_iters or 0),
                        setup_time=built - start + (stats.setup_time or 0.0),
                        solve_time=float(stats.solve_time or 0.0),
                        info={"raw_status": symbolic_form.problem.status, "form": form},
                        velocities=symbolic_form.velocities(step) if status != FAILED else None)


@register("clarabel")
def clarabel_dual(step: StepProblem, *, tol: float = 1e-10, max_iter: int = 200,
                  warm_start=None, polyhedral: bool = False) -> MethodOutput:
    """Clarabel on the symbolic dual form (``warm_start`` is ignored)."""
    return _solve_symbolic(step, "dual", tol, max_iter, polyhedral)


@register("clarabel-primal")
def clarabel_primal(step: StepProblem, *, tol: float = 1e-10, max_iter: int = 200,
                    warm_start=None, polyhedral: bool = False) -> MethodOutput:
    """Clarabel on the symbolic primal form (``warm_start`` is ignored)."""
    return _solve_symbolic(step, "primal", tol, max_iter, polyhedral)
