"""Time stepping: semi-implicit Euler with one contact problem per step (MODEL.md section 3).

Data flows one way: scene -> contacts -> step problem -> solver -> state update.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from . import checks
from .cones import Cones
from .contacts import Contacts, find_contacts, normal_jacobian, tangential_jacobian
from .laws import Law, PairState
from .problem import StepProblem
from .scene import Scene
from .solvers import SolveResult, check_status, solve

ON_FAILURE = ("raise", "warn", "ignore")


@dataclass
class Trajectory:
    """Per-step record of a run (lists while running, arrays via :meth:`arrays`).

    ``times[k]``, ``positions[k]`` and ``velocities[k]`` describe the state
    after step ``k`` (index 0 is the initial state); the other fields have one
    entry per step.
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
    min_gap: list = field(default_factory=list)

    def record_state(self, scene: Scene) -> None:
        self.times.append(scene.time)
        self.positions.append(scene.grains.positions.copy())
        self.velocities.append(scene.grains.velocities.copy())
        self.spins.append(scene.grains.spins.copy())

    def arrays(self) -> dict[str, np.ndarray]:
        """All fields as numpy arrays."""
        return {name: np.asarray(value) for name, value in vars(self).items()}


@dataclass
class StepReport:
    """What one step produced (for callbacks and tests)."""

    contacts: Contacts
    problem: StepProblem
    result: SolveResult
    gamma: np.ndarray
    gaps_after: np.ndarray


class Simulation:
    """Step a scene in time with a contact law and a solver.

    Parameters
    ----------
    scene : Scene
        Copied; the simulation owns its copy (``sim.scene``).
    law : Law
        Contact law (inelastic, gluey, ...).
    dt : float
        Time step (> 0).
    solver : str
        Registered method name (see :func:`lubcontact.solvers.methods`).
    d_max : float, optional
        Contact detection distance; default ``0.1 x`` the smallest radius.
    tol : float
        Solver tolerance.
    solver_options : dict, optional
        Extra keyword arguments for the solver.
    on_failure : {"raise", "warn", "ignore"}
        Policy when a step's solve does not converge: ``raise`` stops with
        :class:`~lubcontact.solvers.SolverError` before the state is touched,
        so the scene still holds the last good state; ``warn`` applies the
        best iterate and warns.
    warm_start : bool
        Start each solve from the previous step's forces, matched by pair.
    """

    def __init__(self, scene: Scene, law: Law, dt: float, *, solver: str = "clarabel",
                 d_max: float | None = None, tol: float = 1e-9, solver_options: dict | None = None,
                 on_failure: str = "raise", warm_start: bool = True):
        self.scene = scene.copy()
        self.law = law
        self.dt = checks.positive_scalar("dt", dt)
        radii = np.concatenate([scene.grains.radii, scene.fixed_radii])
        self.d_max = 0.1 * float(radii.min()) if d_max is None else \
            float(checks.nonnegative("d_max", d_max, shape=()))
        self.solver, self.tol = solver, checks.positive_scalar("tol", tol)
        self.solver_options = dict(solver_options or {})
        checks.require(on_failure in ON_FAILURE, "on_failure", f"must be one of {ON_FAILURE}", None)
        self.on_failure = on_failure
        self.warm_start = warm_start
        self.state = PairState()
        self.start_time = self.scene.time
        self.steps_done = 0
        self._previous: tuple[np.ndarray, np.ndarray] | None = None
        self.trajectory = Trajectory()
        self.trajectory.record_state(self.scene)

    # -- building the step problem -----------------------------------------------------------
    def mass_diagonal(self, rotations: bool) -> np.ndarray:
        g = self.scene.grains
        mass = np.repeat(g.masses, g.dim)
        if rotations:
            mass = np.concatenate([mass, np.repeat(g.inertias, g.spins.shape[1])])
        return mass

    def build_problem(self, contacts: Contacts, cones: Cones) -> StepProblem:
        """The step problem for the current state and the given contacts."""
        grains = self.scene.grains
        rotations = self.law.needs_rotation
        mass = self.mass_diagonal(rotations)
        velocity = grains.velocities.ravel()
        if rotations:
            velocity = np.concatenate([velocity, grains.spins.ravel()])
        force = self.scene.external_forces().ravel()
        free_velocity = velocity.copy()
        free_velocity[: force.size] += self.dt * force / mass[: force.size]
        jacobian = normal_jacobian(contacts, rotations)
        if cones.has_friction:
            jacobian = sp.vstack([jacobian, tangential_jacobian(contacts, cones.tangential)]).tocsr()
        return StepProblem(mass=mass, free_velocity=free_velocity, jacobian=jacobian,
                           gaps=contacts.gaps, cones=cones, dt=self.dt, keys=contacts.keys)

    def _warm_start(self, problem: StepProblem) -> np.ndarray | None:
        """Previous normal forces matched by pair key (tangential rows start at 0)."""
        if not self.warm_start or self._previous is None or problem.n_contacts == 0:
            return None
        keys, normal = self._previous
        guess = np.zeros(problem.n_rows)
        if keys.size:
            pos = np.clip(np.searchsorted(keys, problem.keys), 0, keys.size - 1)
            guess[: problem.n_contacts] = np.where(keys[pos] == problem.keys, normal[pos], 0.0)
        return guess

    # -- stepping --------------------------------------------------------------------------------
    def step(self) -> StepReport:
        """Advance one time step; returns what the step computed."""
        scene = self.scene
        contacts = find_contacts(scene, self.d_max)
        gamma = self.state.lookup(contacts.keys)
        cones = self.law.cones(contacts, gamma)
        problem = self.build_problem(contacts, cones)
        result = solve(problem, self.solver, tol=self.tol, warm_start=self._warm_start(problem),
                       **self.solver_options)
        check_status(result, self.on_failure)
        self._apply(problem, result)
        normal = result.forces[: problem.n_contacts]
        new_gamma = self.law.update_gamma(contacts, gamma, normal, self.dt, result.force_scale)
        self.state = PairState.from_contacts(contacts.keys, new_gamma)
        self._previous = (contacts.keys, normal.copy())
        report = StepReport(contacts=contacts, problem=problem, result=result, gamma=new_gamma,
                            gaps_after=problem.gaps_after(result.velocities))
        self._record(report)
        return report

    def _apply(self, problem: StepProblem, result: SolveResult) -> None:
        grains = self.scene.grains
        n_trans = grains.velocities.size
        velocity = result.velocities
        grains.velocities[:] = velocity[:n_trans].reshape(grains.velocities.shape)
        if problem.n_dof > n_trans:
            grains.spins[:] = velocity[n_trans:].reshape(grains.spins.shape)
        else:
            grains.spins[:] = 0.0
        grains.positions += self.dt * grains.velocities
        self.scene.wrap_positions()
        grains.angles += self.dt * grains.spins
        self.steps_done += 1
        self.scene.time = self.start_time + self.steps_done * self.dt   # no drift from summing dt

    def _record(self, report: StepReport) -> None:
        record = self.trajectory
        record.record_state(self.scene)
        gamma = report.gamma
        record.contact_count.append(report.contacts.count)
        record.glued_count.append(int(np.count_nonzero(gamma < 0)))
        record.gamma_min.append(float(gamma.min()) if gamma.size else 0.0)
        record.gamma_mean.append(float(gamma[gamma < 0].mean()) if np.any(gamma < 0) else 0.0)
        record.status.append(report.result.status)
        record.residual.append(report.result.residual)
        record.iterations.append(report.result.iterations)
        record.min_gap.append(float(report.gaps_after.min()) if report.gaps_after.size else np.inf)

    def run(self, n_steps: int, callback: Callable[["Simulation", StepReport], None] | None = None
            ) -> Trajectory:
        """Advance ``n_steps`` steps, calling ``callback(sim, report)`` after each."""
        n_steps = int(checks.nonnegative("n_steps", n_steps, shape=()))
        for _ in range(n_steps):
            report = self.step()
            if callback is not None:
                callback(self, report)
        return self.trajectory

    def gamma_of(self, keys: np.ndarray) -> np.ndarray:
        """Current gamma of the given pairs (0 if unglued or unknown)."""
        return self.state.lookup(np.asarray(keys, dtype=np.int64))
