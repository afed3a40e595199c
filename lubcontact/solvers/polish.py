"""Active-set polishing of an interior-point solution (frictionless problems).

An interior-point method stops on a duality gap ``eps``; for the strongly
convex primal this only bounds the velocity error by about ``sqrt(eps)``.
Once the active set is known, the solution is the projection of ``U`` onto
an affine subspace, which least squares gives to machine precision:

1. active rows ``A``: FREE contacts, and NONNEG (NONPOS) contacts whose force
   is positive (negative) beyond ``threshold x max |lam|``;
2. velocity correction ``dv``: the minimum-norm solution of
   ``L_A^T dv = -(W lam + b)_A`` (``W = L^T L``), so that every active
   constraint holds exactly;
3. force correction ``dlam``: the minimum-norm solution of ``L_A dlam = dv``.

The polished forces are accepted only if they stay in their cones, the
inactive constraints still hold, and the natural residual decreases.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from ..cones import ConeKind
from ..problem import StepProblem


def polish(problem: StepProblem, forces: np.ndarray, threshold: float = 1e-7,
           max_rounds: int = 5) -> tuple[np.ndarray, bool]:
    """Refine ``forces`` of a frictionless normalised problem on their active set.

    Parameters
    ----------
    problem : StepProblem
        Normalised problem without friction rows.
    forces : ndarray, shape (n_rows,)
        A near-optimal solution (scaled units).
    threshold : float
        Relative force level below which a one-sided contact counts as inactive.
    max_rounds : int
        Active-set corrections allowed: contacts whose polished force leaves
        its cone are released, violated inactive constraints are added.

    Returns
    -------
    (ndarray, bool)
        The polished forces and whether polishing was accepted (otherwise the
        input forces are returned unchanged).
    """
    cones = problem.cones
    if cones.has_friction or forces.size == 0:
        return forces, False
    scale = max(float(np.max(np.abs(forces))), 1e-300)
    kinds = cones.kinds
    one_sided = np.where(kinds == ConeKind.NONPOS, -1.0, np.where(kinds == ConeKind.NONNEG, 1.0, 0.0))
    active = (one_sided == 0) | (one_sided * forces > threshold * scale)
    before = problem.natural_residual(forces)
    for _ in range(max_rounds):
        candidate = _solve_on(problem, forces, active)
        wrong_sign = active & (one_sided * candidate < 0)
        violated = ~active & (one_sided * problem.gradient(candidate) < -1e-12 * (1 + np.abs(problem.offset)))
        if not (wrong_sign.any() or violated.any()):
            return (candidate, True) if problem.natural_residual(candidate) < before else (forces, False)
        active = (active & ~wrong_sign) | violated
    return forces, False


def _solve_on(problem: StepProblem, forces: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Forces that make every active constraint hold exactly, closest to ``forces``."""
    candidate = np.where(active, forces, 0.0)
    factor = problem.delassus_factor[:, active]              # L_A, n_dof x n_active
    residual = problem.gradient(candidate)[active]
    tight = dict(atol=1e-15, btol=1e-15, iter_lim=20 * (factor.shape[0] + factor.shape[1]))
    velocity_step = spla.lsqr(factor.T, -residual, **tight)[0]
    candidate[active] += spla.lsqr(factor, velocity_step, **tight)[0]
    return candidate
