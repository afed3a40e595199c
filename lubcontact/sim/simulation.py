"""Time stepping: semi-implicit Euler with one contact problem per step (docs/guide/model.md section 3).

Data flows one way::

    scene --find_contacts--> Contacts --law.cones--> Cones --assemble--> StepProblem
          --SolveSettings.solve--> CoulombResult --law.update_gamma + integrate--> next state

:class:`Simulation` only steps: the problem is assembled by
:func:`lubcontact.model.assemble.assemble`, solved as :class:`SolveSettings`
say, and the state a step takes and returns is a :class:`SimulationState`.
"""
from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import checks
from ..model.assemble import assemble
from ..model.contacts import Contacts, find_contacts, lookup_by_key
from ..model.laws import Law, PairState
from ..model.scene import Scene
from ..problem.cones import Cones
from ..problem.step import StepProblem
from ..solvers import SolverError, SolverWarning, SolveSettings, check_status, methods
from ..solvers.result import CoulombResult
from ..solvers.verify import verify
from .export import StepExporter
from .state import PreviousStep, SimulationState
from .trajectory import StepReport, Trajectory

ON_FAILURE = ("raise", "warn", "ignore", "fallback")
SEARCH_SAFETY = 1.5
"""Margin on the distance a pair can close in one step (:meth:`Simulation.search_distance`)."""


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
        Each step widens it to cover the step (:meth:`search_distance`): a
        pair that can close during the step is always a candidate contact.
    tol : float
        Solver tolerance.
    solver_options : dict, optional
        Extra keyword arguments for the solver; ``joint``, ``forcing`` and
        ``anderson`` go to the fixed point on s only (frictional steps; ``joint`` also to
        ``newton-ac``, which starts its Newton phases with it).
    on_failure : {"raise", "warn", "ignore", "fallback"}
        Policy when a step's solve does not converge: ``raise`` stops with
        :class:`~lubcontact.solvers.SolverError` before the state is touched,
        so the scene still holds the last good state; ``warn`` applies the
        best iterate and warns; ``ignore`` applies it silently (the status is
        still in the trajectory); ``fallback`` re-solves the step once with
        ``fallback_solver`` (same warm start and shift, recorded in
        ``result.info["fallback_from"]``) and raises if that fails too.
    fallback_solver : str
        The solver used by ``on_failure="fallback"`` and by the ``max_residual``
        re-solve (default ``clarabel``; no re-solve when it is the step's solver).
    max_residual : float, optional
        Whatever ``on_failure`` says, a solve that did not converge and ends
        with a residual per row (``SolveResult.residual_per_row``, the rms of
        the natural residual over the rows: a bound that does not tighten with
        the problem's size) above this (or NaN) is never applied. With ``warn``
        and ``ignore`` the step is first solved once more with
        ``fallback_solver`` (recorded as with ``fallback``; ``warn`` warns),
        and if that too ends above (or there is no other solver), it raises
        :class:`~lubcontact.solvers.SolverError` before the state is touched,
        naming both solves (default: no bound).
    warm_start : bool
        Start each solve from the previous step's forces (normal and
        tangential) and shift, matched by pair.
    fixed_point : bool
        With a frictional law, solve exact Coulomb friction by the fixed point
        on s (:func:`~lubcontact.solvers.solve_coulomb`); False solves the
        convex relaxation once (sliding contacts then separate by
        ``mu dt |u_T|`` per step).
    tol_fp : float
        Tolerance of the fixed point on s (relative change, normalised units).
    max_outer : int
        Cap on the fixed point's outer iterations per step.
    keep_trajectory : bool
        Record every step in :attr:`trajectory` (False keeps memory flat on
        long runs: the trajectory then holds the initial state only).
    verify_every : int
        Every ``verify_every`` steps (0: never), check the step's solution
        against ``verify_with`` (:func:`~lubcontact.solvers.verify.verify`,
        before the state moves on); each report is kept in
        ``trajectory.verifications`` as ``(step, report)`` (also when
        ``keep_trajectory`` is False), and a failed verdict issues a
        :class:`~lubcontact.solvers.SolverWarning`.
    verify_with : str
        The reference method of the verification (default ``clarabel``).
    verify_tol : float
        Tolerance of the verification verdict (normalised units).
    export_every : int
        Every ``export_every`` steps (0: never), write the step's problem with
        the applied solution, the reference solution and the scene to
        ``export_dir`` (:class:`~lubcontact.sim.export.StepExporter`: a
        ``.npz`` always, FCLIB HDF5 when no contact is glued), for other
        solvers and ``lubcontact verify``.
    export_dir : str or Path, optional
        Folder of the exported steps (required with ``export_every``).

    Attributes
    ----------
    state : SimulationState
        Scene, glue state by pair, previous step by pair, step count.
    settings : SolveSettings
        How each step is solved (from ``solver``, ``tol``, ``solver_options``,
        ``fixed_point``, ``tol_fp``, ``max_outer``).
    trajectory : Trajectory
    """

    def __init__(self, scene: Scene, law: Law, dt: float, *, solver: str = "clarabel",
                 d_max: float | None = None, tol: float = 1e-9, solver_options: dict | None = None,
                 on_failure: str = "raise", warm_start: bool = True, fixed_point: bool = True,
                 tol_fp: float = 1e-8, max_outer: int = 50, fallback_solver: str = "clarabel",
                 max_residual: float | None = None, keep_trajectory: bool = True,
                 verify_every: int = 0,
                 verify_with: str = "clarabel", verify_tol: float = 1e-6,
                 export_every: int = 0, export_dir: str | Path | None = None):
        checks.require(isinstance(law, Law), "law", "must be a Law (Inelastic(), "
                       f"GlueyLubrication(...), Coulomb(mu), GlueyCoulomb(mu, ...)), got {law!r}")
        self.law = law
        self.dt = checks.positive_scalar("dt", dt)
        radii = np.concatenate([scene.grains.radii, scene.fixed_radii])
        self.d_max = 0.1 * float(radii.min()) if d_max is None else \
            float(checks.nonnegative("d_max", d_max, shape=()))
        self.settings = SolveSettings(method=solver, tol=tol, exact_coulomb=fixed_point,
                                      tol_fp=tol_fp, max_outer=max_outer,
                                      options=dict(solver_options or {}))
        checks.require(on_failure in ON_FAILURE, "on_failure", f"must be one of {ON_FAILURE}", None)
        self.on_failure = on_failure
        checks.require(fallback_solver in methods(), "fallback_solver",
                       f"must be a registered method ({', '.join(methods())}), "
                       f"got {fallback_solver!r}")
        self.fallback_solver = fallback_solver
        self.max_residual = None if max_residual is None else \
            checks.positive_scalar("max_residual", max_residual)
        self.verify_every = checks.integer("verify_every", verify_every)
        checks.require(verify_with in methods(), "verify_with",
                       f"must be a registered method ({', '.join(methods())}), got {verify_with!r}")
        self.verify_with = verify_with
        self.verify_tol = checks.positive_scalar("verify_tol", verify_tol)
        self.export_every = checks.integer("export_every", export_every)
        checks.require(not self.export_every or export_dir is not None, "export_dir",
                       "required with export_every")
        self.exporter = None if not self.export_every else StepExporter(Path(export_dir))
        self.warm_start = warm_start
        self.keep_trajectory = keep_trajectory
        scene = scene.copy()
        self.state = SimulationState(scene=scene, start_time=scene.time)
        self._cones: Cones | None = None        # the last step's (_step_cones)
        self.trajectory = Trajectory()
        self.trajectory.record_state(scene)

    @property
    def scene(self) -> Scene:
        """The current scene (``state.scene``)."""
        return self.state.scene

    @property
    def steps_done(self) -> int:
        return self.state.steps_done

    # -- the coming step -------------------------------------------------------------------------
    def next_problem(self) -> tuple[Contacts, np.ndarray, StepProblem, np.ndarray | None,
                                    np.ndarray | None]:
        """The coming step's problem and its warm start, without solving it.

        Returns
        -------
        (Contacts, ndarray, StepProblem, ndarray or None, ndarray or None)
            Contacts, their gamma, the step problem, and the previous step's
            forces and shift matched by pair key (None without a previous step
            or with ``warm_start=False``).
        """
        return self._build_problem({}, self.search_distance())

    def _build_problem(self, timings: dict, searched: float
                       ) -> tuple[Contacts, np.ndarray, StepProblem, np.ndarray | None,
                                  np.ndarray | None]:
        """:meth:`next_problem` with the candidate distance ``searched`` (:meth:`search_distance`),
        the seconds of its phases put in ``timings`` (``contacts``, ``assembly``)."""
        scene = self.scene
        start = time.perf_counter()
        contacts = find_contacts(scene, searched)
        timings["contacts"] = time.perf_counter() - start
        gamma = self.state.pairs.lookup(contacts.keys)
        problem = assemble(scene, contacts, self._step_cones(self.law.cones(contacts, gamma)),
                           self.dt, rotations=self.law.needs_rotation)
        previous = self.state.previous
        guess = shift = None
        if self.warm_start and previous is not None and problem.n_contacts:
            guess, shift = previous.warm_start(problem)
        timings["assembly"] = time.perf_counter() - start - timings["contacts"]
        return contacts, gamma, problem, guess, shift

    def _step_cones(self, cones: Cones) -> Cones:
        """``cones``, or the last step's object where it holds the same force sets
        (:meth:`Cones.same_as`: a pile at rest, a small system between contact changes), so that
        what a solve derives from them (the projection's index arrays, the kinds present) is
        reused, not built again: 0.88-0.93 of an exact-Coulomb solve's time on settling piles of
        4 to 20 grains, 0.97-0.98 at 40 (docs/records/benchmarks.md, "small solves: the step's
        cones reused"). Not where the two share an array (a law that wrote into the last
        step's: the derived properties would be stale)."""
        last = self._cones
        if last is not None and cones.same_as(last) and not any(
                np.may_share_memory(mine, theirs) for mine, theirs in zip(cones.arrays, last.arrays)):
            return last
        self._cones = cones
        return cones

    def search_distance(self) -> float:
        """The candidate-contact distance of the coming step: ``d_max``, widened to cover the step.

        During a step two bodies approach each other by at most ``dt`` times
        the sum of their speeds; a speed after the step is bounded by the
        fastest grain now plus ``dt |g|`` (contacts do not add kinetic energy).
        The distance is ``max(d_max, SEARCH_SAFETY dt (2 v + v_obstacle))``,
        capped where a periodic scene allows no more (the missed-contact check
        after the step still warns if a pair was missed).
        """
        scene = self.scene
        speed = float(np.max(np.linalg.norm(scene.grains.velocities, axis=1), initial=0.0)) \
            + self.dt * float(np.linalg.norm(scene.gravity))
        obstacle = float(np.max(np.linalg.norm(scene.obstacle_velocities(), axis=1), initial=0.0))
        distance = max(self.d_max, SEARCH_SAFETY * self.dt * (2.0 * speed + obstacle))
        if scene.period is not None:             # the minimum image needs period > 2 (2 r_max + d)
            radii = np.concatenate([scene.grains.radii, scene.fixed_radii])
            distance = max(self.d_max, min(distance, 0.49 * scene.period - 2.0 * float(radii.max())))
        return distance

    def step(self, settings: SolveSettings | None = None) -> StepReport:
        """Advance one time step; returns what the step computed.

        Parameters
        ----------
        settings : SolveSettings, optional
            Solve this step with other settings (e.g. a robust solver while a
            pile collapses, a fast one once it settles); default :attr:`settings`.
        """
        settings = self.settings if settings is None else settings
        timings: dict[str, float] = {}
        start = time.perf_counter()
        searched = self.search_distance()
        searching = time.perf_counter() - start
        contacts, gamma, problem, guess, shift = self._build_problem(timings, searched)
        timings["contacts"] += searching          # the candidate distance: part of the search
        start = time.perf_counter()
        result = settings.solve(problem, guess, shift)
        unusable = self.max_residual is not None and not result.residual_per_row <= self.max_residual
        failed = None
        if not result.success and self.fallback_solver != settings.method and (
                self.on_failure == "fallback" or (unusable and self.on_failure != "raise")):
            failed = result
            fallback = replace(settings, method=self.fallback_solver, max_iter=None, options={})
            result = fallback.solve(problem, guess, shift)
            result.info["fallback_from"] = (failed.method, failed.status, failed.residual)
            if self.on_failure == "warn":
                warnings.warn(f"step {self.steps_done + 1}: {failed.method} ended {failed.status} "
                              f"at residual {failed.residual:.3e} ({failed.residual_per_row:.3e} "
                              f"per row), above max_residual; solved again by "
                              f"{self.fallback_solver} ({result.status}, residual "
                              f"{result.residual:.3e})", SolverWarning, stacklevel=2)
        timings["solve"] = time.perf_counter() - start
        start = time.perf_counter()
        try:
            check_status(result, "raise" if self.on_failure == "fallback" else self.on_failure,
                         self.max_residual)
        except SolverError as exc:
            if failed is None:
                raise
            raise SolverError(f"{failed.method}: status {failed.status}, residual "
                              f"{failed.residual:.3e} ({failed.residual_per_row:.3e} per row); "
                              f"solved again by {exc}") from None
        if self.verify_every and (self.steps_done + 1) % self.verify_every == 0:
            self._verify(problem, result)
        if self.export_every and (self.steps_done + 1) % self.export_every == 0:
            self.exporter.export(self.steps_done + 1, problem, result, self.scene)
        normal, _ = problem.cones.split(result.forces)
        gaps_after = problem.gaps_after(result.velocities)
        new_gamma = self.law.update_gamma(contacts, gamma, normal, self.dt, result.force_scale,
                                          gaps_after=gaps_after, length_scale=result.length_scale)
        speed = float(np.max(np.linalg.norm(self.scene.grains.velocities, axis=1), initial=0.0))
        self._advance(problem, result, PairState.from_contacts(contacts.keys, new_gamma))
        self._check_missed_contacts(contacts, speed, searched)
        report = StepReport(contacts=contacts, problem=problem, result=result, gamma=new_gamma,
                            gaps_after=gaps_after, timings=timings)
        if self.keep_trajectory:
            self.trajectory.record_state(self.scene)
            self.trajectory.record_step(report)
        timings["update"] = time.perf_counter() - start
        return report

    def _check_missed_contacts(self, contacts: Contacts, speed_before: float, searched: float) -> None:
        """Warn when the step let two bodies overlap that were not candidate contacts.

        A pair farther apart than ``searched`` is not a candidate; it can only
        overlap after the step if the two moved towards each other by more
        than ``searched``: by at most ``dt`` times the sum of their speeds. Below
        that bound (the usual case) nothing is searched; above it, the new
        positions are searched for overlaps the step could not see.
        """
        scene = self.scene
        grains = scene.grains
        speed = max(speed_before, float(np.max(np.linalg.norm(grains.velocities, axis=1),
                                               initial=0.0)))
        obstacle = float(np.max(np.linalg.norm(scene.obstacle_velocities(), axis=1), initial=0.0))
        if self.dt * (2.0 * speed + obstacle) < searched:
            return
        a, b, keys, gaps, smaller = scene.deep_overlaps()
        missed = ~np.isin(keys, contacts.keys)
        if missed.any():
            worst = int(np.argmin(np.where(missed, gaps, np.inf)))
            self.trajectory.missed_contacts.append(
                (self.steps_done, int(np.count_nonzero(missed)), float(-gaps[worst] / smaller[worst])))
            warnings.warn(       # one text, so that a long run warns once: details in the trajectory
                f"pairs overlapped that were not candidate contacts: grains moved more than the "
                f"search distance {searched:.3g} in one step (faster than their speed bound, e.g. "
                f"under an external force); lower dt (trajectory.missed_contacts lists the steps)",
                SolverWarning, stacklevel=3)

    def _verify(self, problem: StepProblem, result: CoulombResult) -> None:
        """Check the step's solution against the reference; keep the report, warn on failure."""
        report = verify(problem, result.forces, result.velocities, tol=self.verify_tol,
                        reference=self.verify_with)
        step = self.steps_done + 1
        self.trajectory.verifications.append((step, report))
        if not report.passed:
            warnings.warn(f"step {step}: {result.method} fails verification against "
                          f"{self.verify_with} ({', '.join(report.failed)}; FCLIB error "
                          f"{report.coulomb_error:.2e})", SolverWarning, stacklevel=3)

    def _advance(self, problem: StepProblem, result: CoulombResult, pairs: PairState) -> None:
        """Integrate positions with the new velocities and store the step's state."""
        state = self.state
        grains = state.scene.grains
        n_trans = grains.velocities.size
        velocity = result.velocities
        grains.velocities[:] = velocity[:n_trans].reshape(grains.velocities.shape)
        if problem.n_dof > n_trans:                  # rotations modelled (friction)
            grains.spins[:] = velocity[n_trans:].reshape(grains.spins.shape)
        # else: normal forces through the centres cannot change a spin: it is carried unchanged
        grains.positions += self.dt * grains.velocities
        state.scene.wrap_positions()
        state.scene.move_obstacles(self.dt)                 # with the velocity the step saw
        grains.angles += self.dt * grains.spins
        state.pairs = pairs
        state.previous = PreviousStep.of(problem, result.forces, result.shift)
        state.steps_done += 1
        state.scene.time = state.start_time + state.steps_done * self.dt   # no drift from summing dt

    def restore(self, state: SimulationState) -> None:
        """Continue from ``state`` (e.g. a checkpoint's :meth:`SimulationState.from_arrays`); the
        steps then move it on in place (restore ``state.copy()`` to keep ``state``)."""
        self.state = state

    def run(self, n_steps: int, callback: Callable[[Simulation, StepReport], None] | None = None
            ) -> Trajectory:
        """Advance ``n_steps`` steps, calling ``callback(sim, report)`` after each."""
        n_steps = checks.integer("n_steps", n_steps)
        for _ in range(n_steps):
            report = self.step()
            if callback is not None:
                callback(self, report)
        return self.trajectory

    def last_contacts(self, report: StepReport | None = None
                      ) -> tuple[Contacts, np.ndarray, np.ndarray] | None:
        """The last step's contacts with their glue state and normal impulse (for pictures, frames).

        Parameters
        ----------
        report : StepReport, optional
            The last step, when at hand. Without it (a run resumed from its
            checkpoint) the state answers: the candidate contacts of the current
            configuration (:meth:`search_distance`), their gamma and the last
            step's normal impulse matched by pair key (0 for a pair new to them).

        Returns
        -------
        (Contacts, ndarray, ndarray) or None
            Contacts, gamma (nc,) and normal impulse (nc,); None before the first step.
        """
        if report is not None:
            return report.contacts, report.gamma, report.result.forces[: report.contacts.count]
        previous = self.state.previous
        if previous is None:
            return None
        contacts = find_contacts(self.scene, self.search_distance())
        return (contacts, self.gamma_of(contacts.keys),
                lookup_by_key(previous.keys, previous.normal, contacts.keys))

    def gamma_of(self, keys: np.ndarray) -> np.ndarray:
        """Current gamma of the given pairs (0 if unglued or unknown)."""
        return self.state.pairs.lookup(np.asarray(keys, dtype=np.int64))
