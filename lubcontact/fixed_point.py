"""Exact Coulomb friction: the fixed point on the shift ``s`` (MODEL.md section 5).

The convex relaxation of Coulomb's law (a second-order cone on the forces, its
dual cone on ``g = W lam + b``) makes a sliding contact separate at the rate
``mu |u_T|`` (dilatancy). Shifting the normal rows by ``s_c = mu_c |g_T,c|``
(De Saxce's change of variable) removes it: at a fixed point
``s = mu |g_T(s)|`` the relaxed optimality conditions are exactly Coulomb's
law. This module iterates

    solve the convex problem with s frozen  ->  s <- mu |g_T(s)|

around any registered solver (through :func:`lubcontact.solvers.solve`), each
inner solve warm-started from the previous one.

Which contacts get a shift: every COULOMB contact; a UNION contact (gluey +
friction at gamma_min) only on its pushed piece (``lam_n >= 0``): on the
pulled piece it is frictionless and bilateral, and a shift would move it.

Stopping rule, with ``L`` the length unit of the normalised problem
(``problem.normalized().scaling.length``, i.e. ``dt V``) and the max norm
over contacts::

    change = |s_new - s_old|_inf / L / (1 + |s_new|_inf / L)  <  tol_fp

The tangential rows of ``g`` are ``dt u_T`` for a step problem and ``u_T`` for
a local (FCLIB) problem, so the same formula covers both.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import checks
from .cones import ConeKind
from .solvers import CONVERGED, MAX_ITER, SolveResult, solve


def coulomb_shift(problem, forces: np.ndarray) -> np.ndarray:
    """``s_c = mu_c |g_T,c(forces)|`` on frictional contacts, 0 elsewhere.

    Parameters
    ----------
    problem : StepProblem or LocalProblem
        Anything with ``cones`` and ``gradient(forces)`` (``g = W lam + b``).
    forces : ndarray, shape (n_rows,)

    Returns
    -------
    ndarray, shape (nc,)
        In the problem's length unit (``mu dt |u_T|`` for a step problem).
    """
    cones = problem.cones
    shift = np.zeros(cones.count)
    if not cones.has_friction:
        return shift
    _, g_tangential = cones.split(problem.gradient(forces))
    idx = cones.tangential
    slip = cones.mu[idx] * np.linalg.norm(g_tangential, axis=1)
    pulled = (cones.kinds[idx] == ConeKind.UNION) & (forces[idx] < 0)
    shift[idx] = np.where(pulled, 0.0, slip)
    return shift


def coulomb_error(problem, forces: np.ndarray) -> float:
    """The FCLIB/Siconos error of a Coulomb problem (MODEL.md section 6).

    ``sqrt(sum_c |lam_c - P_Kc(lam_c - (w_c + mu_c |w_T,c| e_n))|^2) / (1 + |q|)``
    with ``w = W lam + q`` and ``q`` the offset ``b`` without the shift ``s``.
    Computed in the units of the problem given (pass ``problem.normalized()``
    and scaled forces for a unit-free figure on a step problem).

    Parameters
    ----------
    problem : StepProblem or LocalProblem
    forces : ndarray, shape (n_rows,)
    """
    nc = problem.cones.count
    unshifted = problem.gradient(forces)
    unshifted[:nc] -= problem.shift
    corrected = unshifted.copy()
    corrected[:nc] += coulomb_shift(problem, forces)
    q = problem.offset.copy()
    q[:nc] -= problem.shift
    residual = problem.cones.natural_residual(forces, corrected)
    return float(residual / (1.0 + np.linalg.norm(q)))


def solve_coulomb(problem, method: str = "clarabel", *, tol: float = 1e-9, tol_fp: float = 1e-8,
                  max_outer: int = 50, warm_start: np.ndarray | None = None,
                  shift: np.ndarray | None = None, max_iter: int | None = None,
                  **options) -> SolveResult:
    """Solve a frictional problem exactly by the fixed point on ``s``.

    Parameters
    ----------
    problem : StepProblem or LocalProblem
        In physical units; its own ``shift`` is ignored (replaced by ``shift``).
    method : str
        Any registered solver (see :func:`lubcontact.solvers.methods`).
    tol : float
        Tolerance of each inner solve.
    tol_fp : float
        Tolerance on the relative change of ``s`` (see the module docstring).
    max_outer : int
        Cap on the outer iterations (inner solves).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (physical units) for the first inner solve.
    shift : ndarray, shape (nc,), optional
        Initial shift (e.g. the previous step's, matched by pair); default 0
        (the first inner solve is then the convex relaxation).
    max_iter : int, optional
        Iteration cap of each inner solve.
    **options
        Passed to the inner solver.

    Returns
    -------
    SolveResult
        The last inner solve (solved with the shift stored in
        ``info["shift"]``), with ``iterations`` the total inner iterations and
        ``status`` ``converged`` only if the fixed point and the last inner
        solve converged (``max_iter`` when the outer loop ran out, the inner
        status when an inner solve failed). ``info`` adds ``outer_iterations``,
        ``shift_change`` (the last relative change of s), ``force_change``
        (last relative change of the forces, max norm), ``inner_status``,
        ``fp_converged`` and ``shift_history``.
    """
    tol_fp = checks.positive_scalar("tol_fp", tol_fp)
    max_outer = int(checks.positive("max_outer", max_outer, shape=()))
    nc = problem.cones.count
    current = np.zeros(nc) if shift is None else checks.as_array("shift", shift, shape=(nc,)).copy()
    if not problem.cones.has_friction:
        return solve(problem.with_shift(current), method, tol=tol, max_iter=max_iter,
                     warm_start=warm_start, **options)
    scaling = problem.normalized().scaling
    length, force_unit = scaling.length, scaling.force
    forces, inner, history = warm_start, 0, []
    shift_change = force_change = np.inf
    converged = False
    for outer in range(1, max_outer + 1):
        used = current
        result = solve(problem.with_shift(used), method, tol=tol, max_iter=max_iter,
                       warm_start=forces, **options)
        inner += result.iterations
        if forces is not None:
            force_change = _relative_change(result.forces / force_unit, forces / force_unit)
        forces = result.forces
        if not result.success:
            break
        current = coulomb_shift(problem, forces)
        shift_change = _relative_change(current / length, used / length)
        history.append(shift_change)
        if shift_change < tol_fp:
            converged = True
            break
    status = CONVERGED if converged else (result.status if not result.success else MAX_ITER)
    info = dict(result.info, outer_iterations=outer, shift_change=shift_change,
                force_change=force_change, inner_status=result.status, fp_converged=converged,
                shift=used, shift_history=np.asarray(history))
    return replace(result, status=status, iterations=inner, info=info)


def _relative_change(new: np.ndarray, old: np.ndarray) -> float:
    """``|new - old|_inf / (1 + |new|_inf)`` (0 for empty vectors)."""
    if new.size == 0:
        return 0.0
    return float(np.max(np.abs(new - old)) / (1.0 + np.max(np.abs(new))))
