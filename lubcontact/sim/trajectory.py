"""What a run records: :class:`StepReport` per step and the :class:`Trajectory` of a run."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.contacts import Contacts
from ..model.scene import Scene
from ..problem.step import StepProblem
from ..solvers.result import CoulombResult


@dataclass
class StepReport:
    """What one step produced (for callbacks and tests).

    Attributes
    ----------
    contacts : Contacts
    problem : StepProblem
        As solved (zero shift; the fixed point's shift is ``result.shift``).
    result : CoulombResult
    gamma : ndarray, shape (nc,)
        Glue state of each contact after the step.
    gaps_after : ndarray, shape (nc,)
        ``D + dt u_n`` after the step.
    timings : dict
        Wall-clock seconds of the step's phases: ``contacts`` (the candidate
        search, its distance included), ``assembly`` (the step problem and its
        warm start), ``solve`` (set-up, iterations, finish, fixed point) and
        ``update`` (glue states, integration, checks, records).
    """

    contacts: Contacts
    problem: StepProblem
    result: CoulombResult
    gamma: np.ndarray
    gaps_after: np.ndarray
    timings: dict = field(default_factory=dict)


@dataclass
class Trajectory:
    """Per-step record of a run (lists while running, arrays via :meth:`arrays`).

    ``times[k]``, ``positions[k]`` and ``velocities[k]`` describe the state
    after step ``k`` (index 0 is the initial state); the other fields have one
    entry per step, except ``verifications``: ``(step, VerificationReport)``
    for each verified step (``Simulation(verify_every=k)``), and
    ``missed_contacts``: ``(step, count, worst overlap / smaller radius)``
    for each step that let bodies overlap that were not candidate contacts
    (a warning was issued).
    """

    times: list = field(default_factory=list)
    positions: list = field(default_factory=list)
    velocities: list = field(default_factory=list)
    spins: list = field(default_factory=list)
    contact_count: list = field(default_factory=list)
    glued_count: list = field(default_factory=list)
    gamma_min: list = field(default_factory=list)
    gamma_mean: list = field(default_factory=list)
    status: list = field(default_factory=list)
    residual: list = field(default_factory=list)
    iterations: list = field(default_factory=list)
    outer_iterations: list = field(default_factory=list)
    min_gap: list = field(default_factory=list)
    verifications: list = field(default_factory=list)
    missed_contacts: list = field(default_factory=list)

    def record_state(self, scene: Scene) -> None:
        """Append the scene's time, positions, velocities and spins."""
        self.times.append(scene.time)
        self.positions.append(scene.grains.positions.copy())
        self.velocities.append(scene.grains.velocities.copy())
        self.spins.append(scene.grains.spins.copy())

    def record_step(self, report: StepReport) -> None:
        """Append the contact, glue and solver figures of one step."""
        gamma = report.gamma
        glued = gamma < 0
        self.contact_count.append(report.contacts.count)
        self.glued_count.append(int(np.count_nonzero(glued)))
        self.gamma_min.append(float(gamma.min()) if gamma.size else 0.0)
        self.gamma_mean.append(float(gamma[glued].mean()) if np.any(glued) else 0.0)
        self.status.append(report.result.status)
        self.residual.append(report.result.residual)
        self.iterations.append(report.result.iterations)
        self.outer_iterations.append(int(report.result.outer_iterations))
        self.min_gap.append(float(report.gaps_after.min()) if report.gaps_after.size else np.inf)

    def arrays(self) -> dict[str, np.ndarray]:
        """All fields as numpy arrays."""
        return {name: np.asarray(value) for name, value in vars(self).items()
                if name not in ("verifications", "missed_contacts")}
