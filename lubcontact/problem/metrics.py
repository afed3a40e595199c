"""Every error measure of a solution, defined once (docs/guide/model.md section 6).

Tests, benchmarks, reports and the hard-case suite all measure with these:

- :func:`coulomb_error` — the FCLIB/Siconos error of a Coulomb problem, in the
  problem's units; :func:`scaled_coulomb_error` the same on the normalised problem;
- :func:`velocity_error` — ``|v - v_ref|_M / |U|_M`` (mass-weighted, relative);
- :func:`relative_error` — ``|x - x_ref| / |x_ref|`` of any two arrays;
- :func:`scaled_velocity_error` — the max-norm error of velocities and of the
  constraint values ``g``, each in the normalised problem's units;
- :func:`most_negative_gap` — penetration after the step, in ``dt V``;
- :func:`solution_properties` — penetration, cone violation, complementarity,
  energy gain (invariants every solution must satisfy);
- :func:`active_condition` — ``cond(W_AA)``, which sets how fast a gradient method can be.

The natural-map residual is a member of the problem
(``problem.natural_residual``, from :meth:`~lubcontact.problem.Cones.natural_residual`).
For frictional problems the velocity distance to a reference is not an error
(Coulomb fixed points need not be unique): use :func:`coulomb_error`.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .cones import Cones, tangent_norms
from .conic import ConicProblem
from .step import StepProblem

PROPERTY_TOL = 1e-6
"""Scaled level below which a constraint violation counts as rounding (:func:`solution_properties`)."""


def coulomb_shift(problem: ConicProblem, forces: np.ndarray,
                  gradient: np.ndarray | None = None) -> np.ndarray:
    """``s_c = mu_c |g_T,c(forces)|`` on frictional contacts, 0 elsewhere.

    A UNION contact (gluey + friction at gamma_min) is frictional only on its
    pushed piece (``lam_n >= 0``).

    Parameters
    ----------
    problem : ConicProblem
    forces : ndarray, shape (n_rows,)
    gradient : ndarray, shape (n_rows,), optional
        ``problem.gradient(forces)`` when the caller has it (only its tangential rows are read,
        which the shift does not enter).

    Returns
    -------
    ndarray, shape (nc,)
        In the problem's length unit (``mu dt |u_T|`` for a step problem).
    """
    cones = problem.cones
    shift = np.zeros(cones.count)
    if not cones.has_friction:
        return shift
    if gradient is None:
        gradient = problem.gradient(forces)
    (coulomb_n, coulomb_t, coulomb_mu), (union_n, union_t, union_mu) = cones.projector.pieces
    shift[coulomb_n] = coulomb_mu * tangent_norms(gradient[coulomb_t])
    if union_n.size:
        pushed = forces[union_n] >= 0
        shift[union_n] = np.where(pushed, union_mu * tangent_norms(gradient[union_t]), 0.0)
    return shift


def coulomb_error(problem: ConicProblem, forces: np.ndarray,
                  gradient: np.ndarray | None = None) -> float:
    """The FCLIB/Siconos error of a Coulomb problem.

    ``sqrt(sum_c |lam_c - P_Kc(lam_c - (w_c + mu_c |w_T,c| e_n))|^2) / (1 + |q|)``
    with ``w = W lam + q`` and ``q`` the offset ``b`` without the shift ``s``,
    in the units of the problem given (:func:`scaled_coulomb_error` for a
    unit-free figure on a step problem).

    Parameters
    ----------
    problem : ConicProblem
    forces : ndarray, shape (n_rows,)
    gradient : ndarray, shape (n_rows,), optional
        ``problem.gradient(forces)`` when the caller has it.
    """
    nc = problem.cones.count
    if gradient is None:
        gradient = problem.gradient(forces)
    corrected = gradient.copy()
    corrected[:nc] += coulomb_shift(problem, forces, gradient) - problem.shift
    q = problem.offset.copy()
    q[:nc] -= problem.shift
    residual = problem.cones.natural_residual(forces, corrected)
    return float(residual / (1.0 + np.linalg.norm(q)))


def scaled_coulomb_error(problem: ConicProblem, forces: np.ndarray) -> float:
    """:func:`coulomb_error` of physical ``forces`` measured on the normalised problem."""
    scaled = problem.normalized()
    return coulomb_error(scaled, forces / scaled.scaling.force)


def relative_error(value: np.ndarray, reference: np.ndarray) -> float:
    """``|value - reference| / |reference|`` (absolute when the reference is zero)."""
    norm = float(np.linalg.norm(reference))
    return float(np.linalg.norm(value - reference)) / (norm if norm > 0 else 1.0)


def velocity_error(problem: StepProblem, velocities: np.ndarray, reference: np.ndarray) -> float:
    """``|v - v_ref|_M / |U|_M``: mass-weighted velocity error relative to the free velocity.

    Parameters
    ----------
    problem : StepProblem
    velocities, reference : ndarray, shape (n_dof,)
    """
    mass = problem.mass
    scale = np.sqrt(np.sum(mass * problem.free_velocity**2))
    return float(np.sqrt(np.sum(mass * (velocities - reference) ** 2)) / scale)


def scaled_velocity_error(problem: StepProblem, velocities: np.ndarray,
                          expected: np.ndarray) -> float:
    """Max-norm error of velocities and of ``g = [D + s, 0] + dt H v``, in scaled units.

    Each degree of freedom is measured in its velocity unit of the normalised
    problem (``StepProblem.normalized``), ``g`` (gaps after the step and
    tangential displacements) in ``dt V``; the larger of the two is returned.
    """
    scaling = problem.normalized().scaling
    difference = velocities - expected
    velocity = np.max(np.abs(difference) / scaling.velocity) if difference.size else 0.0
    constraint = problem.dt * (problem.jacobian @ difference) / scaling.length
    constraint_error = np.max(np.abs(constraint)) if constraint.size else 0.0
    return float(max(velocity, constraint_error))


def most_negative_gap(problem: ConicProblem, velocities: np.ndarray) -> float:
    """Most negative gap after the step in units of ``dt V`` (0 without contacts).

    For a local problem, the most negative normal velocity ``u_n / V``.
    """
    if problem.n_contacts == 0:
        return 0.0
    scaling = problem.normalized().scaling
    if isinstance(problem, StepProblem):
        return float(problem.gaps_after(velocities).min() / scaling.length)
    return float(velocities[: problem.n_contacts].min() / scaling.length)


def solution_properties(problem: StepProblem, forces: np.ndarray,
                        velocities: np.ndarray) -> dict[str, float]:
    """Invariants of a solution, in the normalised problem's units.

    Parameters
    ----------
    problem : StepProblem
        With the shift the solution was computed with.
    forces : ndarray, shape (n_rows,)
    velocities : ndarray, shape (n_dof,)
        Physical units.

    Returns
    -------
    dict
        ``penetration`` (``-min gap`` after the step, in ``dt V``, >= 0),
        ``cone`` (distance of the forces to their cones, relative to the
        largest force, at least 1), ``complementarity`` (max ``|lam_c . g_c|``,
        same relative measure) and ``energy`` (relative kinetic-energy gain;
        0 when zero velocity is not admissible, where contacts may do work).
    """
    scaled = problem.normalized()
    scaling = scaled.scaling
    forces = forces / scaling.force
    velocities = velocities / scaling.velocity
    cones = scaled.cones
    force_size = max(1.0, float(np.max(np.abs(forces)))) if forces.size else 1.0
    out = dict(penetration=0.0, cone=0.0, complementarity=0.0, energy=0.0)
    if forces.size:
        gaps = scaled.gaps_after(velocities)
        out["penetration"] = float(max(0.0, -gaps.min())) if gaps.size else 0.0
        out["cone"] = float(np.max(np.abs(forces - cones.project(forces)))) / force_size
        g = scaled.constraint_values(velocities)
        out["complementarity"] = float(np.max(np.abs(_per_contact_dot(cones, forces, g)))) / force_size
    if _zero_admissible(scaled, forces):
        free = float(scaled.free_velocity @ scaled.free_velocity)
        gain = float(velocities @ velocities) - free
        out["energy"] = max(0.0, gain) / max(free, 1e-300)
    return out


def _per_contact_dot(cones: Cones, forces: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``lam_c . g_c`` per contact (normal plus tangential components), shape (nc,)."""
    normal_f, tangential_f = cones.split(forces)
    normal_g, tangential_g = cones.split(g)
    dot = normal_f * normal_g
    if cones.has_friction:
        dot[cones.tangential] += np.sum(tangential_f * tangential_g, axis=1)
    return dot


def _zero_admissible(scaled: StepProblem, forces: np.ndarray) -> bool:
    """Whether ``v = 0`` satisfies every constraint to ``PROPERTY_TOL`` (scaled lengths), UNION
    contacts on the branch of their force; rounding-level overlaps of touching grains pass."""
    cones = scaled.cones
    if cones.count == 0:
        return True
    if not cones.is_convex:
        cones = cones.with_branches(forces[: cones.count] < 0)
    return bool(np.all(cones.velocity_violation(scaled.constant_rows) <= PROPERTY_TOL))


def active_condition(problem: ConicProblem, forces: np.ndarray) -> tuple[float, int]:
    """Condition number of ``W_AA``, the Delassus matrix on the rows that carry force.

    Near the solution of a pile at rest the dual problem is the linear system
    ``W_AA x_A = -b_A`` on these rows, and a gradient method converges at a
    rate set by ``cond(W_AA)``: about ``1 - 1/cond`` per iteration for PGD,
    ``1 - 1/sqrt(cond)`` for APGD. The extreme eigenvalues come from Lanczos
    (``scipy.sparse.linalg.eigsh``), the smallest in shift-invert mode at 0
    (a sparse LU of ``W_AA``).

    Parameters
    ----------
    problem : ConicProblem
    forces : ndarray, shape (n_rows,)
        A solution; rows with ``|x_i| > 1e-12 max |x|`` are the loaded ones.

    Returns
    -------
    (float, int)
        ``cond(W_AA)`` (inf when ``W_AA`` is singular) and the number of loaded rows.
    """
    from scipy.sparse.linalg import eigsh

    loaded = np.abs(forces) > 1e-12 * float(np.max(np.abs(forces), initial=0.0))
    count = int(np.count_nonzero(loaded))
    if count == 0:
        return np.nan, 0
    matrix = sp.csc_matrix(sp.csr_matrix(problem.delassus)[loaded][:, loaded])
    if count <= 2:
        eigenvalues = np.linalg.eigvalsh(matrix.toarray())
        return float(eigenvalues[-1] / eigenvalues[0]) if eigenvalues[0] > 0 else np.inf, count
    largest = eigsh(matrix, k=1, which="LA", return_eigenvectors=False)[0]
    try:
        smallest = eigsh(matrix, k=1, sigma=0.0, which="LM", return_eigenvectors=False)[0]
    except RuntimeError:                                    # exactly singular
        return np.inf, count
    return float(largest / smallest) if smallest > 0 else np.inf, count
