"""Verify a solution from anywhere (our solvers, Siconos, Scopi, your own code) against the problem.

:func:`verify` takes a problem and a candidate solution (forces, or velocities
from which forces are recovered) and returns a :class:`VerificationReport`:
the FCLIB/Siconos error, the velocity distance to the Clarabel reference where
the solution is unique, the most negative gap, cone violation,
complementarity, and the worst contacts with the condition each fails.

Every measure is taken on the normalised problem (forces in ``m_ref V / dt``,
lengths in ``dt V``, velocities in ``V``: docs/guide/model.md section 9), so
one tolerance serves every scene. Frictional contacts are judged on exact
Coulomb friction (De Saxce's correction ``w + mu |w_T| e_n``, the FCLIB
measure): a solution of the convex relaxation fails there by its dilatancy.

Which conditions decide the verdict, at tolerance ``tol``:

- ``coulomb_error`` (FCLIB/Siconos error) <= tol;
- ``penetration`` (most negative gap, or the violated bilateral gap of a glued
  contact), ``cone`` (distance of a force to its cone) and
  ``complementarity`` (``|lam_c . w_c|``) <= tol at every contact;
- the velocity distance to the reference <= tol where the solution is unique
  (no friction: the primal problem is strongly convex) and the reference is
  trusted (its own FCLIB error <= tol); otherwise it is reported only.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from ..problem.cones import ConeKind, Cones
from ..problem.conic import ConicProblem
from ..problem.metrics import coulomb_error, coulomb_shift, relative_error
from ..problem.step import StepProblem
from .registry import reference_method, solve
from .settings import SolveSettings

CONDITIONS = ("penetration", "cone", "complementarity", "residual")
"""Per-contact conditions, in the order they are reported."""


@dataclass
class ContactViolation:
    """One contact's worst condition.

    Attributes
    ----------
    index : int
        Contact index in the problem.
    kind : str
        Force set (``NONNEG``, ``FREE``, ``COULOMB``, ``UNION``, ...).
    condition : str
        The condition it fails most (one of :data:`CONDITIONS`).
    amount : float
        By how much, in the normalised problem's units.
    amounts : dict
        Every condition's violation at this contact (name -> amount).
    """

    index: int
    kind: str
    condition: str
    amount: float
    amounts: dict = field(default_factory=dict)


@dataclass
class VerificationReport:
    """The verdict on a candidate solution (normalised units throughout).

    Attributes
    ----------
    passed : bool
        Every deciding condition within ``tol`` (module docstring).
    tol : float
    coulomb_error : float
        FCLIB/Siconos error of the candidate.
    penetration, cone, complementarity : float
        Largest violation over the contacts.
    velocity_error : float or None
        ``|v - v_ref| / |v_ref|`` (None without a reference).
    velocity_error_decides : bool
        Whether ``velocity_error`` entered the verdict (unique solution, trusted reference).
    consistency : float
        ``|v(lam) - v| / |v|`` when both forces and velocities were given
        (forces recovered from velocities: the least-squares misfit); 0 otherwise.
    reference : dict
        Method, status and FCLIB error of the reference solve (empty without one).
    worst : list of ContactViolation
        The contacts with the largest violations, worst first.
    n_contacts : int
    failed : list of str
        The deciding conditions that failed.
    forces_recovered : bool
        Only velocities were given: forces were recovered by a cone-constrained least-squares
        fit (not unique where ``H^T`` has a kernel, e.g. a jammed pile), so the force-based
        measures are reported only, and the velocities decide (penetration, velocity error).
    """

    passed: bool
    tol: float
    coulomb_error: float
    penetration: float
    cone: float
    complementarity: float
    velocity_error: float | None
    velocity_error_decides: bool
    consistency: float
    reference: dict
    worst: list[ContactViolation]
    n_contacts: int
    failed: list[str] = field(default_factory=list)
    forces_recovered: bool = False

    def to_json(self) -> str:
        """The report as JSON (no NaN: non-finite numbers become null)."""
        def clean(value: object) -> object:          # any part of the asdict tree
            if isinstance(value, float) and not np.isfinite(value):
                return None
            if isinstance(value, dict):
                return {k: clean(v) for k, v in value.items()}
            if isinstance(value, list):
                return [clean(v) for v in value]
            return value
        return json.dumps(clean(asdict(self)), indent=2)

    def text(self) -> str:
        """A readable verdict, one measure per line, then the worst contacts."""
        verdict = "PASS" if self.passed else "FAIL (" + ", ".join(self.failed) + ")"
        velocity = "n/a" if self.velocity_error is None else f"{self.velocity_error:.3e}" + (
            "" if self.velocity_error_decides else "  (reported only: not unique or reference "
                                                   "not trusted)")
        lines = [f"verdict: {verdict} at tol {self.tol:.1e}, {self.n_contacts} contacts",
                 f"FCLIB/Siconos error   {self.coulomb_error:.3e}",
                 f"velocity error        {velocity}",
                 f"most negative gap     {-self.penetration:.3e}",
                 f"cone violation        {self.cone:.3e}",
                 f"complementarity       {self.complementarity:.3e}",
                 f"forces/velocities     {self.consistency:.3e}"]
        if self.reference:
            lines.append(f"reference             {self.reference['method']}: "
                         f"{self.reference['status']}, FCLIB error "
                         f"{self.reference['coulomb_error']:.3e}")
        if self.worst:
            lines += ["worst contacts (normalised units):",
                      "  contact  kind      worst condition  " + "  ".join(
                          f"{name:>15}" for name in CONDITIONS)]
            lines += [f"  {c.index:7d}  {c.kind:<8}  {c.condition:<15}  " + "  ".join(
                f"{c.amounts[name]:15.3e}" for name in CONDITIONS) for c in self.worst]
        return "\n".join(lines)


def verify(problem: ConicProblem, forces: np.ndarray | None = None,
           velocities: np.ndarray | None = None, *, tol: float = 1e-8,
           reference: str | None = "auto", reference_tol: float = 1e-10,
           worst: int = 5) -> VerificationReport:
    """Judge a candidate solution of ``problem``.

    Parameters
    ----------
    problem : ConicProblem
        In physical units; its ``shift`` is ignored for frictional contacts
        (exact Coulomb is checked, whatever shift the candidate used).
    forces : ndarray, shape (n_rows,), optional
        Contact forces in physical units, in the problem's row layout.
    velocities : ndarray, optional
        Velocities (shape (n_dof,) for a step problem, (n_rows,) local
        velocities ``W r + q`` for a local problem). With ``forces`` they are
        checked for consistency; alone, forces are recovered by least squares.
    tol : float
        Tolerance of the verdict, in normalised units.
    reference : str or None
        Registered method computing the reference (exact Coulomb when
        frictional); ``"auto"``: :func:`~lubcontact.solvers.registry.reference_method`;
        None skips it.
    reference_tol : float
        Tolerance of the reference solve.
    worst : int
        How many contacts to list.

    Raises
    ------
    ValueError
        Without forces and velocities, or for arrays of the wrong shape or with non-finite values.
    """
    recovered = forces is None
    forces, consistency = _candidate(problem, forces, velocities)
    scaled = problem.normalized()
    unit = scaled.scaling
    lam = forces / unit.force
    exact = scaled.with_shift(np.zeros(scaled.n_contacts))
    corrected = exact.gradient(lam)
    corrected[: exact.n_contacts] += coulomb_shift(exact, lam)
    per_contact = _per_contact(exact.cones, lam, corrected)
    if recovered:             # the velocities themselves decide admissibility
        per_contact["penetration"] = _velocity_violation(problem, exact, velocities / unit.velocity
                                                         if isinstance(problem, StepProblem)
                                                         else velocities / unit.length, lam)
    error = coulomb_error(exact, lam)
    summary = {name: float(values.max(initial=0.0)) for name, values in per_contact.items()}
    velocity_error, decides, reference_record = None, False, {}
    if reference == "auto":
        reference = reference_method(problem)
    if reference is not None:
        settings = SolveSettings(method=reference, tol=reference_tol, tol_fp=reference_tol)
        solved = settings.solve(problem.with_shift(np.zeros(problem.n_contacts)))
        reference_error = coulomb_error(exact, solved.forces / unit.force)
        reference_record = dict(method=reference, status=solved.status,
                                coulomb_error=reference_error)
        candidate = problem.velocity(forces) if velocities is None else velocities
        velocity_error = relative_error(candidate, solved.velocities)
        decides = (not problem.cones.has_friction and solved.success
                   and reference_error <= tol)
    deciding = (("penetration", summary["penetration"]),) if recovered else (
        ("coulomb_error", error), ("penetration", summary["penetration"]),
        ("cone", summary["cone"]), ("complementarity", summary["complementarity"]))
    failed = [name for name, value in deciding if not value <= tol]
    if decides and not velocity_error <= tol:
        failed.append("velocity_error")
    return VerificationReport(
        passed=not failed, tol=tol, coulomb_error=error, penetration=summary["penetration"],
        cone=summary["cone"], complementarity=summary["complementarity"],
        velocity_error=velocity_error, velocity_error_decides=decides, consistency=consistency,
        reference=reference_record, worst=_worst(exact.cones, per_contact, worst),
        n_contacts=problem.n_contacts, failed=failed, forces_recovered=recovered)


def _candidate(problem: ConicProblem, forces: np.ndarray | None,
               velocities: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Forces (given, or recovered from velocities) and the forces/velocities misfit."""
    if forces is None and velocities is None:
        raise ValueError("forces, velocities: give at least one")
    if velocities is not None:
        velocities = np.asarray(velocities, dtype=float)
        expected = (problem.n_dof,) if isinstance(problem, StepProblem) else (problem.n_rows,)
        if velocities.shape != expected:
            raise ValueError(f"velocities: expected shape {expected}, got {velocities.shape}")
        if not np.all(np.isfinite(velocities)):
            raise ValueError("velocities: non-finite value")
    if forces is None:
        forces = _forces_from_velocities(problem, velocities)
    forces = np.asarray(forces, dtype=float)
    if forces.shape != (problem.n_rows,):
        raise ValueError(f"forces: expected shape ({problem.n_rows},), got {forces.shape}")
    if not np.all(np.isfinite(forces)):
        raise ValueError("forces: non-finite value")
    if velocities is None:
        return forces, 0.0
    return forces, relative_error(problem.velocity(forces), velocities)


def _forces_from_velocities(problem: ConicProblem, velocities: np.ndarray) -> np.ndarray:
    """Forces in their cones that produce ``velocities`` best, in the least-squares sense.

    For a step problem, ``min |U + dt M^-1 H^T lam - v|_M^2`` over ``lam in K`` is the dual
    of the step problem with free velocity ``U - v`` and zero gaps (same ``W``); for a local
    problem, ``min |W r + q - u|^2`` over ``r in K`` has the matrix ``W^T W``. Both are
    solved by the reference; the forces are unique only where ``H^T`` (``W``) has no kernel.
    """
    if problem.n_rows == 0:
        return np.zeros(0)
    if isinstance(problem, StepProblem):
        fit = replace(problem, free_velocity=problem.free_velocity - velocities,
                      gaps=np.zeros(problem.n_contacts), shift=np.zeros(problem.n_contacts))
    else:
        residual = problem.free_velocity - velocities
        fit = replace(problem, delassus=sp.csr_matrix(problem.delassus.T @ problem.delassus),
                      free_velocity=problem.delassus.T @ residual,
                      shift=np.zeros(problem.n_contacts))
    return solve(fit, reference_method(fit), tol=1e-10).forces


def _velocity_violation(problem: ConicProblem, scaled: ConicProblem, velocities: np.ndarray,
                        forces: np.ndarray) -> np.ndarray:
    """Each contact's gap violation read from (scaled) velocities alone, shape (nc,).

    ``g`` is ``[D, 0] + dt H v`` for a step problem and ``u`` for a local one; frictional
    contacts are judged on exact Coulomb (``g_n + mu |g_T| >= mu |g_T|``, i.e. ``g_n >= 0``).
    """
    cones = scaled.cones
    if isinstance(problem, StepProblem):
        g = scaled.constraint_values(velocities)
    else:
        g = velocities.copy()
    pieces = cones if cones.is_convex else cones.with_branches(cones.pulled(forces))
    if pieces.has_friction:
        _, g_t = pieces.split(g)
        idx = pieces.tangential
        frictional = pieces.mask(ConeKind.COULOMB)[idx]
        g[idx[frictional]] += pieces.mu[idx[frictional]] * np.linalg.norm(g_t[frictional], axis=1)
    return pieces.velocity_violation(g)


def _per_contact(cones: Cones, forces: np.ndarray, corrected: np.ndarray) -> dict[str, np.ndarray]:
    """Each condition's violation at each contact, shape (nc,) each."""
    pieces = cones if cones.is_convex else cones.with_branches(cones.pulled(forces))
    gap = pieces.velocity_violation(corrected)
    cone = _contact_norms(pieces, forces - pieces.project(forces))
    normal_f, tangential_f = pieces.split(forces)
    normal_w, tangential_w = pieces.split(corrected)
    dot = normal_f * normal_w
    if pieces.has_friction:
        dot[pieces.tangential] += np.sum(tangential_f * tangential_w, axis=1)
    dot[pieces.mask(ConeKind.FREE)] = 0.0           # bilateral: its gap condition is the test
    residual = _contact_norms(pieces, forces - pieces.project(forces - corrected))
    return dict(penetration=gap, cone=cone, complementarity=np.abs(dot), residual=residual)


def _contact_norms(cones: Cones, vector: np.ndarray) -> np.ndarray:
    """Euclidean norm of each contact's rows (normal and tangential), shape (nc,)."""
    normal, tangential = cones.split(vector)
    squares = normal**2
    if cones.has_friction:
        squares[cones.tangential] += np.sum(tangential**2, axis=1)
    return np.sqrt(squares)


def _worst(cones: Cones, per_contact: dict[str, np.ndarray], count: int) -> list[ContactViolation]:
    """The ``count`` contacts with the largest violation, each with its worst condition."""
    if cones.count == 0 or count <= 0:
        return []
    table = np.stack([per_contact[name] for name in CONDITIONS])       # (conditions, nc)
    amount = table.max(axis=0)
    order = np.argsort(-amount, kind="stable")[:count]
    return [ContactViolation(index=int(c), kind=ConeKind(cones.kinds[c]).name,
                             condition=CONDITIONS[int(np.argmax(table[:, c]))],
                             amount=float(amount[c]),
                             amounts={name: float(table[k, c]) for k, name in enumerate(CONDITIONS)})
            for c in order if amount[c] > 0]
