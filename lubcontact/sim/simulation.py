"""Time stepping: semi-implicit Euler with one contact problem per step (MODEL.md section 3).

Data flows one way: scene -> contacts -> step problem -> solver -> state update.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from .. import checks
from ..problem.cones import Cones
from ..model.contacts import Contacts, find_contacts, normal_jacobian, tangential_jacobian
from ..solvers.coulomb import solve_coulomb
from ..model.laws import Law, PairState
from ..problem.step import StepProblem
from ..model.scene import Scene
from ..solvers import SolveResult, check_status, solve
from ..solvers import methods as solver_methods

ON_FAILURE = ("raise", "warn", "ignore", "fallback")
#: options of :func:`~lubcontact.fixed_point.solve_coulomb` itself, not passed to frictionless solves
FIXED_POINT_OPTIONS = ("joint", "forcing", "anderson")


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
    outer_iterations: list = field(default_factory=list)
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


@dataclass
class PreviousStep:
    """What the next step's warm start needs, by pair key (keys sorted)."""

    keys: np.ndarray
    normal: np.ndarray
    tangential_contacts: np.ndarray
    tangential: np.ndarray
    shift: np.ndarray


def lookup_by_key(stored_keys: np.ndarray, values: np.ndarray, wanted: np.ndarray,
            width: int | None = None) -> np.ndarray:
    """Values of the wanted keys in ``stored_keys`` (sorted), 0 for keys not stored.

    ``values`` has one entry (``width`` is None) or one row of ``width``
    entries per stored key.
    """
    shape = (wanted.size,) if width is None else (wanted.size, width)
    out = np.zeros(shape)
    if stored_keys.size == 0 or wanted.size == 0:
        return out
    pos = np.clip(np.searchsorted(stored_keys, wanted), 0, stored_keys.size - 1)
    found = stored_keys[pos] == wanted
    out[found] = values[pos[found]]
    return out


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
        Extra keyword arguments for the solver; ``joint``, ``forcing`` and
        ``anderson`` go to the fixed point on s only (frictional steps).
    on_failure : {"raise", "warn", "ignore", "fallback"}
        Policy when a step's solve does not converge: ``raise`` stops with
        :class:`~lubcontact.solvers.SolverError` before the state is touched,
        so the scene still holds the last good state; ``warn`` applies the
        best iterate and warns; ``ignore`` applies it silently (the status is
        still in the trajectory); ``fallback`` re-solves the step once with
        ``fallback_solver`` (same warm start and shift, recorded in
        ``result.info["fallback_from"]``) and raises if that fails too.
    fallback_solver : str
        The solver used by ``on_failure="fallback"`` (default ``clarabel``).
    warm_start : bool
        Start each solve from the previous step's forces (normal and
        tangential) and shift, matched by pair.
    fixed_point : bool
        With a frictional law, solve exact Coulomb friction by the fixed point
        on s (:func:`~lubcontact.fixed_point.solve_coulomb`); False solves the
        convex relaxation once (sliding contacts then separate by
        ``mu dt |u_T|`` per step).
    tol_fp : float
        Tolerance of the fixed point on s (relative change, normalised units).
    max_outer : int
        Cap on the fixed point's outer iterations per step.
    """

    def __init__(self, scene: Scene, law: Law, dt: float, *, solver: str = "clarabel",
                 d_max: float | None = None, tol: float = 1e-9, solver_options: dict | None = None,
                 on_failure: str = "raise", warm_start: bool = True, fixed_point: bool = True,
                 tol_fp: float = 1e-8, max_outer: int = 50, fallback_solver: str = "clarabel"):
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
        checks.require(fallback_solver in solver_methods(), "fallback_solver",
                       f"must be a registered method ({', '.join(solver_methods())}), "
                       f"got {fallback_solver!r}")
        self.fallback_solver = fallback_solver
        self.warm_start = warm_start
        self.fixed_point = fixed_point
        self.tol_fp = checks.positive_scalar("tol_fp", tol_fp)
        self.max_outer = int(checks.positive("max_outer", max_outer, shape=()))
        self.state = PairState()
        self.start_time = self.scene.time
        self.steps_done = 0
        self.previous: PreviousStep | None = None
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

    def _warm_start(self, problem: StepProblem) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Previous forces (normal and tangential) and shift matched by pair key.

        Returns ``(forces (n_rows,), shift (nc,))``, or ``(None, None)`` without
        a previous step; pairs new to this step start at 0.
        """
        if not self.warm_start or self.previous is None or problem.n_contacts == 0:
            return None, None
        previous = self.previous
        cones = problem.cones
        normal = lookup_by_key(previous.keys, previous.normal, problem.keys)
        shift = lookup_by_key(previous.keys, previous.shift, problem.keys)
        tangential = lookup_by_key(previous.keys[previous.tangential_contacts], previous.tangential,
                                   problem.keys[cones.tangential], width=cones.tangent_dim)
        return cones.join(normal, tangential), shift

    # -- stepping --------------------------------------------------------------------------------
    def next_problem(self):
        """The coming step's problem and its warm start, without solving it.

        Returns
        -------
        (Contacts, ndarray, StepProblem, ndarray or None, ndarray or None)
            Contacts, their gamma, the step problem, and the previous step's
            forces and shift matched by pair key (None without a previous step
            or with ``warm_start=False``).
        """
        contacts = find_contacts(self.scene, self.d_max)
        gamma = self.state.lookup(contacts.keys)
        problem = self.build_problem(contacts, self.law.cones(contacts, gamma))
        return (contacts, gamma, problem, *self._warm_start(problem))

    def step(self) -> StepReport:
        """Advance one time step; returns what the step computed."""
        contacts, gamma, problem, guess, shift = self.next_problem()
        cones = problem.cones
        result = self._solve(problem, self.solver, guess, shift, self.solver_options)
        if not result.success and self.on_failure == "fallback" and self.fallback_solver != self.solver:
            failed = result
            result = self._solve(problem, self.fallback_solver, guess, shift, {})
            result.info["fallback_from"] = (failed.method, failed.status, failed.residual)
        check_status(result, "raise" if self.on_failure == "fallback" else self.on_failure)
        self._apply(problem, result)
        normal, tangential = cones.split(result.forces)
        new_gamma = self.law.update_gamma(contacts, gamma, normal, self.dt, result.force_scale)
        self.state = PairState.from_contacts(contacts.keys, new_gamma)
        used_shift = result.info.get("shift", np.zeros(problem.n_contacts))
        self.previous = PreviousStep(keys=contacts.keys, normal=normal.copy(),
                                     tangential_contacts=cones.tangential.copy(),
                                     tangential=tangential.copy(), shift=np.asarray(used_shift))
        report = StepReport(contacts=contacts, problem=problem, result=result, gamma=new_gamma,
                            gaps_after=problem.gaps_after(result.velocities))
        self._record(report)
        return report

    def _solve(self, problem: StepProblem, method: str, guess, shift, options: dict) -> SolveResult:
        """One step's solve: the fixed point on s with friction, else a single convex solve."""
        if problem.cones.has_friction and self.fixed_point:
            return solve_coulomb(problem, method, tol=self.tol, tol_fp=self.tol_fp,
                                 max_outer=self.max_outer, warm_start=guess, shift=shift, **options)
        convex_options = {k: v for k, v in options.items() if k not in FIXED_POINT_OPTIONS}
        return solve(problem, method, tol=self.tol, warm_start=guess, **convex_options)

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
        record.outer_iterations.append(int(report.result.info.get("outer_iterations", 1)))
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
