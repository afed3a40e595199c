"""The step problem written symbolically with cvxpy (primal and dual forms).

Both builders take a :class:`~lubcontact.problem.StepProblem` (normally its
normalised form) and return the cvxpy problem and the handles needed to read
the solution back. The force sets come from :class:`~lubcontact.problem.cones.Cones`,
the single description also used by the projections and the residuals.
"""
from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from .conic import ConicProblem
from .global_form import convexified
from .step import StepProblem


@dataclass
class SymbolicForm:
    """A cvxpy problem plus what is needed to recover forces and velocities."""

    problem: cp.Problem
    variable: cp.Variable
    constraints: list
    form: str
    polyhedral: bool

    def forces(self, step: StepProblem) -> np.ndarray:
        if self.form == "dual":
            return np.asarray(self.variable.value, dtype=float)
        return step.cones.forces_from_duals(self.constraints, self.polyhedral)

    def velocities(self, step: StepProblem) -> np.ndarray:
        if self.form == "dual":
            return step.velocity(self.forces(step))
        return np.asarray(self.variable.value, dtype=float)


def _half_quadratic(step: ConicProblem, forces: cp.Variable) -> cp.Expression:
    """``1/2 lam^T W lam``: through the factor ``W = L^T L`` when the problem has one,
    else with ``W`` itself made symmetric positive semi-definite (a local problem read from a
    file: :func:`~lubcontact.problem.global_form.convexified`)."""
    factor = step.delassus_factor
    if factor is not None:
        return 0.5 * cp.sum_squares(factor @ forces)
    repaired, _ = convexified(step)           # a W read from a file: symmetric PSD part
    return 0.5 * cp.quad_form(forces, repaired.delassus, assume_PSD=True)


def dual_form(step: ConicProblem, polyhedral: bool = False) -> SymbolicForm:
    """``min 1/2 lam^T W lam + b^T lam  s.t. lam_c in K_c``.

    ``step`` is a :class:`~lubcontact.problem.StepProblem` (``W`` through its
    factor ``dt M^-1/2 H^T``) or a :class:`~lubcontact.problem.local.LocalProblem`.
    """
    forces = cp.Variable(step.n_rows, name="forces")
    nc = step.n_contacts
    tangential = forces[nc:] if step.n_rows > nc else None
    constraints = step.cones.cvxpy_force_constraints(forces[:nc], tangential, polyhedral)
    objective = cp.Minimize(_half_quadratic(step, forces) + step.offset @ forces)
    return SymbolicForm(cp.Problem(objective, constraints), forces, constraints, "dual", polyhedral)


def primal_form(step: StepProblem, polyhedral: bool = False) -> SymbolicForm:
    """``min 1/2 (v - U)^T M (v - U)  s.t. g_c(v) in K_c*``."""
    if not isinstance(step, StepProblem):
        raise ValueError(f"step: the primal form needs a StepProblem (velocities, masses), "
                         f"got {type(step).__name__}")
    velocity = cp.Variable(step.n_dof, name="velocity")
    g = step.constant_rows + step.dt * (step.jacobian @ velocity)
    nc = step.n_contacts
    tangential = g[nc:] if step.n_rows > nc else None
    constraints = step.cones.cvxpy_velocity_constraints(g[:nc], tangential, polyhedral)
    objective = cp.Minimize(0.5 * cp.sum_squares(cp.multiply(np.sqrt(step.mass),
                                                             velocity - step.free_velocity)))
    return SymbolicForm(cp.Problem(objective, constraints), velocity, constraints, "primal", polyhedral)
