"""One run of the flow experiment: :class:`FlowRun` steps a simulation, measures it, writes files.

In its output folder a run writes:

- ``checkpoint.npz``: the full simulation state every ``checkpoint_every``
  steps (:meth:`SimulationState.to_arrays <lubcontact.sim.SimulationState.to_arrays>`:
  scene arrays, gluey state and warm start by pair key, step count) with the
  measurement accumulators; :meth:`FlowRun.resume` continues from it and
  reaches the same final state as an uninterrupted run;
- ``measurements.npz``: time series (kinetic energy, flow rate in units of
  ``d sqrt(g' d)``, contact states, solver residuals and iterations, Clarabel
  cross-checks), the time-averaged profiles and the gamma histogram;
- ``frames/frame_<step>.npz``: positions, velocities, spins and the contacts
  with their gamma (:func:`frame_arrays`), every ``frame_every`` steps;
- ``summary.json`` (:meth:`FlowRun.finish`): means over the averaging window
  (strict JSON: a quantity without a value is ``null``, never ``NaN``).

Every file is written atomically (:mod:`lubcontact.io.files`), so an
interruption never leaves a half-written file and loses nothing already saved.
On Ctrl-C or SIGTERM a run stops between two steps with a checkpoint
(:class:`~lubcontact.flow.interrupt.Interrupted`), from the command line and
from a script alike (:meth:`FlowRun.advance` handles both signals while it steps).

Timings (``wall_time``, ``cpu_time`` and the steps per second) count the steps
only: before its first step a run solves small problems of each cone family
its law can produce, untimed (:meth:`FlowRun.warm_up`), so that numba
compilation and first imports land in ``warm_up_time`` instead.
"""
from __future__ import annotations

import json
import math
import pathlib
import time
import zipfile
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..io.files import save_npz, save_text
from ..model.assemble import assemble
from ..model.contacts import find_contacts
from ..model.scene import Scene
from ..problem.step import StepProblem
from ..scenes import inclined
from ..sim import Simulation, SimulationState, StepReport
from ..solvers import CONVERGED, SolverError, solve
from ..solvers.result import SUSPICIOUS_RESIDUAL
from . import interrupt, measure
from .config import DEFINING_FIELDS, DT_UNIT, Q_UNIT, RunConfig, flow_rate_unit

if TYPE_CHECKING:
    from tqdm import tqdm

SERIES = ("step", "time", "kinetic_energy", "flow_rate", "contacts", "unglued", "glued",
          "frictional", "residual", "iterations", "converged", "angle", "mean_velocity",
          "coordination_unglued", "coordination_glued", "coordination_frictional")
"""Time series sampled every ``sample_every`` steps (``measurements.npz``: ``series.<name>``):
``flow_rate`` in units of ``d sqrt(g' d)``, ``mean_velocity`` (downhill, mass-weighted) in
``sqrt(g' d)``, ``angle`` in degrees, the contact counts per state and the contacts per free
grain per state (``coordination_<state>``). Checkpoints written before a series existed give
it NaN samples."""
GAMMA_BINS = 20
"""Bins of the gamma / gamma_min histogram over [0, 1]."""
STEP_FAILURE_RESIDUAL = SUSPICIOUS_RESIDUAL
"""A step whose solve did not converge and ends with a residual per row above this (1e-3, the
figure above which the solvers call a converged claim wrong) is not a solution: it is solved
once more by Clarabel (the simulation's ``fallback_solver``; not when the run's solver is
Clarabel), and when that too ends above, the run stops before applying it
(:attr:`FlowRun.failure`, ``state = "failed"`` in its summary).
Steps that end below it, though not converged, are applied and counted (``unconverged_steps``).
Measured: applying steps at residuals per row of 0.05 to 1.3 (no method solved them) drove a
gluey run at 28 degrees from Q = 5 to 114 d sqrt(g' d) in 40 steps; the bound was 1e-2 on the
residual's 2-norm until 2026-11-28, which tightens with the size (1e-4 per row at 4 500
contacts) and stopped two 2000-grain beds at rest on steps Newton had brought to 1.2e-4 and
6.3e-4 per row (docs/records/benchmarks.md). Between the run's tolerance and this bound a step
is applied and counted, not re-solved: at 2000 grains the bound is about 1e-4 in FCLIB error,
and what steps that far from the tolerance do to a run is not measured."""
WARM_UP_TOL = 1e-2
WARM_UP_ITERATIONS = 20
"""Tolerance and iteration cap of the untimed warm-up solves (:meth:`FlowRun.warm_up`)."""


class FlowRun:
    """A simulation with its measurements, checkpoints and frames.

    Parameters
    ----------
    config : RunConfig
    scene : Scene
        Initial scene (periodic); copied by the simulation.
    out_dir : pathlib.Path or None
        Where files go (None: nothing is written).

    Attributes
    ----------
    config : RunConfig
    params : FlowParameters
        ``config.params``.
    sim : Simulation
        Steps the scene (no trajectory kept: memory stays flat).
    series : dict of str to list
        The :data:`SERIES`, one entry per sample (``flow_rate`` in units of
        ``d sqrt(g' d)``, :data:`~lubcontact.flow.config.Q_UNIT`).
    profiles : ProfileAccumulator
        Depth profiles summed over the samples of the averaging window.
    gamma_counts : ndarray of int64, shape (GAMMA_BINS,)
        Histogram of ``gamma / gamma_min`` of glued contacts over that window.
    cross_checks : list of (int, float)
        Step and relative velocity difference of each Clarabel cross-check.
    statuses : dict of str to int, or None
        Steps per solver status (None: unknown, a checkpoint predating it).
    rescued : int or None
        Steps whose solve ended above :data:`STEP_FAILURE_RESIDUAL` (per row) and were solved again by
        Clarabel (their status is Clarabel's; None: unknown, a checkpoint predating it).
    wall_time, cpu_time : float
        Stepping time (seconds), wall clock and processor.
    warm_up_time : float
        Wall-clock time (seconds) of the untimed warm-ups (:meth:`warm_up`;
        one per process that stepped the run).
    last_report : StepReport or None
        What the last step computed.
    failure : str or None
        Why the run stopped early: a step whose solve, and Clarabel's re-solve,
        failed beyond :data:`STEP_FAILURE_RESIDUAL` (not applied; the scene holds
        the last good state). None while the run is sound.
    """

    def __init__(self, config: RunConfig, scene: Scene, out_dir: pathlib.Path | None = None):
        self.config = config
        self.params = config.params
        self.out_dir = None if out_dir is None else pathlib.Path(out_dir)
        self.sim = Simulation(scene, self.params.law(config.model),
                              inclined.time_step(self.params, config.dt_fraction),
                              solver=config.solver, tol=config.tol, on_failure="ignore",
                              fixed_point=config.fixed_point, tol_fp=config.tol_fp,
                              max_outer=config.max_outer,
                              solver_options={"joint": config.joint} if config.joint else None,
                              max_residual=STEP_FAILURE_RESIDUAL, keep_trajectory=False)
        r = self.params.radius
        top = float(scene.grains.positions[:, 1].max() + 2 * r)
        self.profiles = measure.ProfileAccumulator(
            np.arange(0.0, top + r / config.bins_per_radius, r / config.bins_per_radius),
            scene.period)
        self.series: dict[str, list] = {name: [] for name in SERIES}
        self.gamma_counts = np.zeros(GAMMA_BINS, dtype=np.int64)
        self.cross_checks: list[tuple[int, float]] = []
        self.statuses: dict[str, int] | None = {}
        self.rescued: int | None = 0
        self.wall_time = 0.0
        self.cpu_time = 0.0
        self.warm_up_time = 0.0
        self._warmed = False
        self.last_report: StepReport | None = None
        self.failure: str | None = None

    @property
    def steps_done(self) -> int:
        """Steps taken since the run started (across resumes)."""
        return self.sim.steps_done

    @property
    def averaging(self) -> bool:
        """Whether the run is past ``average_from`` of its steps (samples enter the averages)."""
        return self.steps_done > self.config.average_from * self.config.steps

    # -- stepping ---------------------------------------------------------------------------
    def advance(self, n_steps: int, progress: bool = False) -> None:
        """Step ``n_steps`` times (not beyond ``config.steps``), measuring and checkpointing.

        Parameters
        ----------
        n_steps : int
            Steps to take.
        progress : bool
            Show a progress bar (tqdm).

        A step whose solve, and Clarabel's re-solve, fail beyond
        :data:`STEP_FAILURE_RESIDUAL` ends the run there (:attr:`failure`; with an
        output folder, a checkpoint of the last good state and the failed step's
        problem in ``failed_step.npz`` are written); later calls step no more.

        Raises
        ------
        Interrupted
            On Ctrl-C or SIGTERM (handled for the call's duration by
            :func:`~lubcontact.flow.interrupt.stop_on_signals`, in the main
            thread): the step under way is finished, a checkpoint written (with
            an output folder), then this is raised.
        """
        end = min(self.config.steps, self.steps_done + n_steps)
        if end <= self.steps_done or self.failure is not None:
            return
        if not self._warmed:
            self.warm_up()
        shown = self._angle()                   # the angle the progress bar names
        bar = _progress_bar(end - self.steps_done, progress, describe(self.config, shown))
        try:
            with interrupt.stop_on_signals():     # Ctrl-C / SIGTERM: stop after this step
                while self.steps_done < end:
                    if interrupt.requested():
                        raise self._interrupted()
                    if self.config.ramp_stages:
                        angle = self._tilt()
                        if bar is not None and angle != shown:
                            shown = angle
                            bar.set_description(describe(self.config, shown))
                    start, start_cpu = time.perf_counter(), time.process_time()
                    try:
                        report = self.sim.step()
                    except SolverError as exc:
                        self.failure = f"step {self.steps_done + 1}: {exc}"
                    finally:                           # a failed step's time was spent too
                        self.wall_time += time.perf_counter() - start
                        self.cpu_time += time.process_time() - start_cpu
                    if self.failure is not None:
                        self._keep_failed_step()
                        break
                    if self.statuses is not None:
                        status = report.result.status
                        self.statuses[status] = self.statuses.get(status, 0) + 1
                    if self.rescued is not None and "fallback_from" in report.result.info:
                        self.rescued += 1
                    self.last_report = report
                    self._measure(report)
                    if bar is not None:
                        bar.update(1)
                else:                       # a request during the last step: the block's end
                    if interrupt.requested():       # would forget it
                        raise self._interrupted()
        finally:
            if bar is not None:
                bar.close()

    def _keep_failed_step(self) -> None:
        """With an output folder, what a failed step leaves: the checkpoint of the last good
        state (the steps since the last checkpoint are not lost) and the failed step's problem in
        ``failed_step.npz`` (:meth:`StepProblem.to_arrays`, plus ``warm_start`` and
        ``warm_shift``, the run's warm start, when there is one; ``step``, the failed step's
        number, and ``failure``, :attr:`failure`), to reproduce the solve alone. A run continued
        past that step leaves the file as it was (its ``step`` then lies behind the run's)."""
        if self.out_dir is None:
            return
        self.save_checkpoint()
        _, _, problem, guess, shift = self.sim.next_problem()
        warm = {} if guess is None else {"warm_start": guess, "warm_shift": shift}
        save_npz(self._file("failed_step.npz"), **problem.to_arrays(), **warm,
                 step=np.int64(self.steps_done + 1), failure=np.array(self.failure))

    def _angle(self, step: int | None = None) -> float | None:
        """The incline of step ``step`` (0-based; the coming one when None), in degrees: its ramp
        stage's (:meth:`RunConfig.ramp_stage`), else ``config.angle``."""
        step = self.steps_done if step is None else step
        return self.config.ramp_stage(step)[1] if self.config.ramp_stages else self.config.angle

    def _tilt(self) -> float:
        """Set the incline of the coming step's ramp stage; that angle (degrees)."""
        angle = self._angle()
        inclined.tilt(self.sim.scene, angle)
        return angle

    def warm_up(self) -> None:
        """Solve, untimed, a small problem of each cone family the run's law can produce.

        The first solve of a kind compiles numba kernels (seconds) and imports
        the solver's modules; a flowing layer meets a new kind when friction
        first appears, long after the first step. Here each kind is met once,
        at a loose tolerance (:data:`WARM_UP_TOL`, :data:`WARM_UP_ITERATIONS`),
        with the run's solver settings; nothing is applied to the state. The
        time goes to :attr:`warm_up_time`, not to the step timings.
        """
        self._warmed = True
        start = time.perf_counter()
        settings = self.sim.settings
        settings = replace(settings, tol=max(settings.tol, WARM_UP_TOL),
                           max_iter=WARM_UP_ITERATIONS, tol_fp=max(settings.tol_fp, WARM_UP_TOL),
                           max_outer=min(settings.max_outer, 2))
        for problem in warm_up_problems(self.sim):
            try:
                settings.solve(problem)
            except Exception:      # noqa: BLE001 - a warm-up only buys timing accuracy
                pass
        self.warm_up_time += time.perf_counter() - start

    def _interrupted(self) -> interrupt.Interrupted:
        """Write a checkpoint of the current step (with an output folder); the exception to raise."""
        checkpoint = None
        if self.out_dir is not None:
            self.save_checkpoint()
            checkpoint = self._file("checkpoint.npz")
        return interrupt.Interrupted(self.steps_done, checkpoint,
                                     describe(self.config, self._angle(max(self.steps_done - 1, 0))))

    def finish(self, progress: bool = False) -> dict[str, Any]:
        """Step to ``config.steps``, then write the final checkpoint and ``summary.json``.

        Parameters
        ----------
        progress : bool
            Show a progress bar (tqdm).

        Returns
        -------
        dict
            :meth:`summary`.
        """
        self.advance(self.config.steps - self.steps_done, progress)
        self.save_checkpoint()
        summary = self.summary()
        save_text(self._file("summary.json"), summary_json(summary))
        return summary

    def _measure(self, report: StepReport) -> None:
        k, config = self.steps_done, self.config
        if config.cross_check_every and k % config.cross_check_every == 0:
            self.cross_checks.append((k, cross_check(report)))
        if k % config.sample_every == 0:
            self._sample(report)
        if self.out_dir is not None and config.frame_every and k % config.frame_every == 0:
            self.save_frame()
        if self.out_dir is not None and k % config.checkpoint_every == 0:
            self.save_checkpoint()

    def _sample(self, report: StepReport) -> None:
        scene, contacts = self.sim.scene, report.contacts
        gamma_min = self.sim.law.gamma_min(contacts)
        normal = report.result.forces[: contacts.count]
        active = (report.gamma < 0) | (normal > self.config.tol * report.result.force_scale)
        masks = self.sim.law.contact_states(contacts, report.gamma, active)
        values = (self.steps_done, scene.time, measure.kinetic_energy(scene),
                  measure.flow_rate(scene) / flow_rate_unit(self.params),
                  int(np.count_nonzero(active)), *np.count_nonzero(masks, axis=1),
                  report.result.residual, report.result.iterations, report.result.success,
                  self.config.ramp_stage(self.steps_done - 1)[1],
                  measure.mean_velocity(scene) / self.params.velocity_scale,
                  *measure.coordination(masks, contacts.a_is_free, scene.grains.count))
        for name, value in zip(SERIES, values):
            self.series[name].append(value)
        if self.averaging:
            self.profiles.add(scene)
            self.gamma_counts += measure.gamma_histogram(report.gamma, gamma_min,
                                                         self.gamma_counts.size)

    # -- files ------------------------------------------------------------------------------
    def measurements(self) -> dict[str, np.ndarray]:
        """Time series, averaged profiles and histograms as arrays (``measurements.npz``).

        Returns
        -------
        dict of str to ndarray
            ``series.<name>`` for each of :data:`SERIES`, shape (samples,);
            ``profile.edges`` (K + 1,), ``profile.packing``,
            ``profile.velocity``, ``profile.area``, ``profile.momentum`` (K,)
            and ``profile.samples``; ``gamma_histogram`` (GAMMA_BINS,);
            ``cross_checks`` (n, 2) of (step, relative difference);
            ``wall_time``, ``cpu_time`` and ``warm_up_time`` (seconds);
            ``statuses``, ``rescued``, ``config`` and ``units`` (of the series) as JSON
            strings.
        """
        prof = self.profiles.profile()
        out = {f"series.{k}": np.asarray(v, dtype=float) for k, v in self.series.items()}
        out.update({"profile.edges": prof.edges, "profile.packing": prof.packing,
                    "profile.velocity": prof.velocity, "profile.area": self.profiles.area,
                    "profile.momentum": self.profiles.momentum,
                    "profile.samples": np.int64(self.profiles.samples),
                    "gamma_histogram": self.gamma_counts,
                    "cross_checks": np.asarray(self.cross_checks, dtype=float).reshape(-1, 2),
                    "wall_time": np.float64(self.wall_time),
                    "cpu_time": np.float64(self.cpu_time),
                    "warm_up_time": np.float64(self.warm_up_time),
                    "statuses": np.array(json.dumps(self.statuses)),
                    "rescued": np.array(json.dumps(self.rescued)),
                    "config": np.array(self.config.to_json()),
                    "units": np.array(json.dumps(units(self.params)))})
        return out

    def save_checkpoint(self) -> None:
        """Write ``checkpoint.npz`` and ``measurements.npz`` (atomically).

        Raises
        ------
        ValueError
            If the run has no output folder.
        """
        measurements = self.measurements()
        save_npz(self._file("measurements.npz"), **measurements)
        save_npz(self._file("checkpoint.npz"), **self.sim.state.to_arrays(), **measurements)

    def save_frame(self) -> None:
        """Write :func:`frame_arrays` of the current step to ``frames/frame_<step>.npz``.

        Raises
        ------
        ValueError
            If the run has no output folder.
        """
        save_npz(self._file("frames") / f"frame_{self.steps_done:08d}.npz",
                 **frame_arrays(self.sim, self.last_report))

    def _file(self, name: str) -> pathlib.Path:
        if self.out_dir is None:
            raise ValueError("out_dir: this run writes no files (it was created with out_dir=None)")
        return self.out_dir / name

    @classmethod
    def resume(cls, path: pathlib.Path, out_dir: pathlib.Path | None = None,
               steps: int | None = None, **changes: Any) -> FlowRun:
        """Rebuild a run from its checkpoint.

        When ``steps`` extends the run so that the averaging window starts
        after the checkpoint, the time averages (profiles, gamma histogram)
        restart, so that they cover the new window only; series are kept whole.

        Parameters
        ----------
        path : pathlib.Path
            A ``checkpoint.npz``.
        out_dir : pathlib.Path, optional
            Where the resumed run writes (default: the checkpoint's folder).
        steps : int, optional
            New total number of steps (default: the stored total); not below
            the checkpoint's step.
        **changes
            :class:`RunConfig` fields (e.g. ``friction=0.5``) that continue the
            run with other settings from the checkpoint's state; they are
            stored in the config of the checkpoints written afterwards. The
            :data:`~lubcontact.flow.config.DEFINING_FIELDS` cannot change.

        Returns
        -------
        FlowRun
            At the checkpoint's step, with its measurements so far.

        Raises
        ------
        ValueError
            Naming a defining field that ``changes`` would change, or
            ``steps`` when it is below the checkpoint's step.
        """
        path = pathlib.Path(path)
        with np.load(path) as data:
            data = dict(data)
        stored = RunConfig.from_json(str(data["config"]))
        if steps is not None:
            changes = {**changes, "steps": int(steps)}
        config = replace(stored, **changes)
        changed = stored.differences(config, DEFINING_FIELDS)
        if changed:
            raise ValueError("; ".join(f"{name}: the checkpoint's run has {old!r}, cannot continue "
                                       f"with {new!r}" for name, (old, new) in changed.items()))
        state = SimulationState.from_arrays(data)
        if config.steps < state.steps_done:
            raise ValueError(f"steps: {config.steps} is below the checkpoint's step "
                             f"{state.steps_done}")
        run = cls(config, state.scene, path.parent if out_dir is None else out_dir)
        run.sim.restore(state)
        run._restore_measurements(data)
        return run

    def _restore_measurements(self, data: dict[str, np.ndarray]) -> None:
        """Take the accumulators back from :meth:`measurements` arrays."""
        samples = data["series.step"].size
        self.series = {name: list(data.get(f"series.{name}", np.full(samples, np.nan)))
                       for name in SERIES}
        if "units" not in data:                  # older checkpoints: flow rate in length^2 / time
            scale = flow_rate_unit(self.params)
            self.series["flow_rate"] = [value / scale for value in self.series["flow_rate"]]
        self.profiles = measure.ProfileAccumulator(
            data["profile.edges"], self.profiles.period, area=data["profile.area"],
            momentum=data["profile.momentum"], samples=int(data["profile.samples"]))
        self.gamma_counts = data["gamma_histogram"].astype(np.int64)
        self.cross_checks = [tuple(row) for row in data["cross_checks"]]
        self.wall_time = float(data["wall_time"])
        self.cpu_time = float(data.get("cpu_time", np.nan))  # older checkpoints: unknown
        self.warm_up_time = float(data.get("warm_up_time", 0.0))
        self.statuses = json.loads(str(data["statuses"])) if "statuses" in data else None
        self.rescued = json.loads(str(data["rescued"])) if "rescued" in data else None
        if not self.averaging and self.profiles.samples:
            self.profiles.reset()
            self.gamma_counts[:] = 0

    def summary(self) -> dict[str, Any]:
        """Means over the averaging window and the flow verdict.

        Returns
        -------
        dict
            ``scene``, ``model``, ``angle`` (degrees; ``inclined_flow``
            only), ``steps``, ``time``, ``dt_fraction``; ``flow_rate`` and
            ``flow_rate_std`` (in units of ``d sqrt(g' d)``, over the
            averaging window); the last ``kinetic_energy``; the verdict of
            :func:`~lubcontact.flow.measure.classify_flow` (``state``,
            ``energy_ratio``, ``relative_change``; NaN when there are fewer
            than 4 samples), ``state`` being ``"failed"`` and ``failure``
            saying why when the run stopped early (:attr:`failure`; else None);
            ``fraction_<state>`` of the active contacts per contact state;
            ``mean_velocity`` (downhill, in ``sqrt(g' d)``) and
            ``coordination_<state>`` (contacts per free grain per state),
            means over the window (NaN when the checkpoint predates them);
            for a ramp, ``ramp_step``, ``ramp_stages`` and ``hold_steps`` (its
            ``angle`` is the first one; :mod:`~lubcontact.flow.hysteresis`
            reads its stages); ``seed``, ``friction``, ``viscosity`` and ``roughness`` (the
            parameters in force; the last two None when the preset sets
            ``gamma_min`` directly); ``unconverged_steps`` (None if unknown),
            ``step_statuses``, ``rescued_steps`` (re-solved by Clarabel,
            :data:`STEP_FAILURE_RESIDUAL`; None if unknown), ``unconverged_samples``;
            ``max_cross_check`` (NaN without cross-checks); ``wall_time`` and ``cpu_time``
            (seconds, the steps only), ``steps_per_second``,
            ``steps_per_cpu_second``, ``warm_up_time`` (seconds, untimed
            compilation and first imports); ``solver`` and ``tol``;
            ``units`` (:func:`units`). NaN is written ``null`` in
            ``summary.json`` (:func:`summary_json`).
        """
        series = {k: np.asarray(v, dtype=float) for k, v in self.series.items()}
        window = series["step"] > self.config.average_from * self.config.steps
        if not np.any(window):
            window = np.ones_like(series["step"], dtype=bool)
        active = series["contacts"][window]
        with np.errstate(invalid="ignore", divide="ignore"):
            fractions = {name: float(np.sum(series[name][window]) / max(np.sum(active), 1))
                         for name in measure.STATES}
        verdict = (measure.classify_flow(series["time"], series["kinetic_energy"],
                                         series["flow_rate"])
                   if series["time"].size >= 4 else None)
        cross = np.asarray(self.cross_checks, dtype=float).reshape(-1, 2)
        rate = series["flow_rate"][window]
        where = ({"angle": self.config.angle} if self.config.scene == "inclined_flow" else {})
        return {"scene": self.config.scene, "model": self.config.model, **where,
                "steps": self.steps_done, "time": float(self.sim.scene.time),
                "dt_fraction": self.config.dt_fraction,
                "flow_rate": float(np.mean(rate)) if window.any() else 0.0,
                "flow_rate_std": float(np.std(rate)) if window.any() else 0.0,
                "kinetic_energy": (float(series["kinetic_energy"][-1]) if series["time"].size
                                   else 0.0),
                "state": "failed" if self.failure else verdict.label if verdict else "unknown",
                "failure": self.failure,
                "energy_ratio": verdict.energy_ratio if verdict else float("nan"),
                "relative_change": verdict.relative_change if verdict else float("nan"),
                **{f"fraction_{k}": v for k, v in fractions.items()},
                "mean_velocity": _window_mean(series["mean_velocity"], window),
                **{f"coordination_{k}": _window_mean(series[f"coordination_{k}"], window)
                   for k in measure.STATES},
                **({"ramp_step": self.config.ramp_step, "ramp_stages": self.config.ramp_stages,
                    "hold_steps": self.config.hold_steps} if self.config.ramp_stages else {}),
                "seed": self.config.seed, "friction": self.params.friction,
                "viscosity": self.params.viscosity, "roughness": self.params.roughness,
                "unconverged_steps": (None if self.statuses is None else
                                      sum(n for s, n in self.statuses.items() if s != CONVERGED)),
                "step_statuses": self.statuses,
                "rescued_steps": self.rescued,
                "unconverged_samples": int(np.count_nonzero(series["converged"] == 0)),
                "max_cross_check": float(cross[:, 1].max()) if cross.size else float("nan"),
                "wall_time": self.wall_time,
                "steps_per_second": self.steps_done / self.wall_time if self.wall_time else 0.0,
                "cpu_time": self.cpu_time,
                "steps_per_cpu_second": (self.steps_done / self.cpu_time if self.cpu_time
                                         else 0.0),
                "warm_up_time": self.warm_up_time,
                "solver": self.config.solver, "tol": self.config.tol,
                "units": units(self.params)}


def read_checkpoint(path: pathlib.Path, field: str, hint: str = "") -> dict[str, np.ndarray]:
    """The arrays of a run's ``checkpoint.npz``, read whole.

    Parameters
    ----------
    path : pathlib.Path
    field : str
        The name the errors give (an option or a config field, e.g. ``start_from``).
    hint : str
        Said after "is not a run's checkpoint.npz" (e.g. what to use instead).

    Raises
    ------
    ValueError
        ``"<field>: no such file: ..."``, or ``"<field>: ... is not a run's checkpoint.npz"``
        for a file numpy cannot read as an archive or one without ``steps_done``.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"{field}: no such file: {path}")
    not_a_checkpoint = f"{field}: {path} is not a run's checkpoint.npz" + (f" {hint}" if hint else "")
    try:
        data = np.load(path)
    except (OSError, ValueError, zipfile.BadZipFile):
        raise ValueError(not_a_checkpoint) from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(not_a_checkpoint)
    with data:
        if "steps_done" not in data:
            raise ValueError(not_a_checkpoint)
        return {name: data[name] for name in data.files}


def _window_mean(values: np.ndarray, window: np.ndarray) -> float:
    """Mean of a series over the averaging window, leaving out NaN samples (those of a
    checkpoint that predates the series); NaN when no sample is left."""
    kept = values[window & np.isfinite(values)]
    return float(np.mean(kept)) if kept.size else float("nan")


def units(params: inclined.FlowParameters) -> dict[str, str]:
    """Units of a run's outputs (``summary.json``, ``measurements.npz``), in words.

    Parameters
    ----------
    params : FlowParameters
        The run's parameters (its unit system).

    Returns
    -------
    dict of str to str
        ``flow_rate`` (:data:`~lubcontact.flow.config.Q_UNIT`), ``dt_fraction``
        (:data:`~lubcontact.flow.config.DT_UNIT`), ``time``, ``kinetic_energy``,
        ``wall_time`` and ``d`` / ``g'`` (what the symbols stand for).
    """
    si = params.units == "SI"
    return {"flow_rate": Q_UNIT, "dt_fraction": DT_UNIT, "mean_velocity": "sqrt(g' d)",
            "angle": "deg", "coordination": "contacts per free grain",
            "d": "mean grain diameter", "g'": "reduced gravity g (1 - rho_f / rho_p)",
            "time": "s" if si else "sqrt(r/g') (r = g' = 1)",
            "kinetic_energy": "J/m (per unit depth)" if si else "rho_p g' r^3 (r = g' = rho_p = 1)",
            "wall_time": "s"}


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, inf) replaced by None, in dicts and lists."""
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def summary_json(summary: dict[str, Any]) -> str:
    """``summary`` as strict JSON (indented): a quantity without a finite value is ``null``."""
    return json.dumps(json_safe(summary), indent=2, allow_nan=False)


def describe(config: RunConfig, angle: float | None = None) -> str:
    """A run in words: ``inclined_flow dry 22 deg`` or ``sedimentation frictionless``; ``angle``
    (degrees) in place of ``config.angle``, for a ramp's current stage."""
    words = f"{config.scene} {config.model}"
    angle = config.angle if angle is None else angle
    return words if angle is None else f"{words} {angle:g} deg"


def warm_up_problems(sim: Simulation) -> list[StepProblem]:
    """Step problems of the current scene, one per set of cone kinds the law gives its contacts.

    The contacts are the scene's (when none touch yet, the first grain is
    placed on top of the second); each problem gives them all the same gluey
    state: unglued (0), glued (``gamma_min / 2``) and frictional
    (``gamma_min``), so that, e.g., boxes and friction cones both occur.
    Nothing of ``sim`` is changed.

    Parameters
    ----------
    sim : Simulation

    Returns
    -------
    list of StepProblem
        Distinct by cone kinds (empty with fewer than two grains and no contact).
    """
    scene = sim.scene.copy()
    contacts = find_contacts(scene, sim.d_max)
    if contacts.count == 0:
        grains = scene.grains
        if grains.count < 2:
            return []
        grains.positions[0] = grains.positions[1] + [0.0, grains.radii[0] + grains.radii[1]]
        contacts = find_contacts(scene, sim.d_max)
    floor = np.asarray(sim.law.gamma_min(contacts), dtype=float)
    finite = np.isfinite(floor)
    states = [np.zeros(contacts.count)]
    if finite.any():
        states += [np.where(finite, 0.5 * floor, 0.0), np.where(finite, floor, 0.0)]
    problems, seen = [], set()
    for gamma in states:
        cones = sim.law.cones(contacts, gamma)
        kinds = tuple(sorted(set(cones.kinds.tolist())))
        if kinds not in seen:
            seen.add(kinds)
            problems.append(assemble(scene, contacts, cones, sim.dt,
                                     rotations=sim.law.needs_rotation))
    return problems


def frame_arrays(sim: Simulation, report: StepReport | None) -> dict[str, np.ndarray]:
    """One frame of a run as arrays (``frames/frame_<step>.npz``).

    Parameters
    ----------
    sim : Simulation
    report : StepReport or None
        The last step; None: the contacts of ``sim``'s state
        (:meth:`~lubcontact.sim.simulation.Simulation.last_contacts`; none before its first step).

    Returns
    -------
    dict of str to ndarray
        ``time``; ``positions`` and ``velocities`` (N, 2), ``spins`` (N, 1)
        and ``radii`` (N,) of the free grains; ``fixed_positions``
        (M, 2) and ``fixed_radii`` (M,); ``period`` (0: not periodic); after a
        step, per contact (nc,): ``contact_a``, ``contact_b`` (body
        indices), ``contact_gamma``, ``contact_gamma_min``, ``contact_force``
        (normal impulse).
    """
    scene = sim.scene
    out = {"time": np.float64(scene.time), "positions": scene.grains.positions,
           "radii": scene.grains.radii, "velocities": scene.grains.velocities,
           "spins": scene.grains.spins, "fixed_positions": scene.fixed_positions,
           "fixed_radii": scene.fixed_radii, "period": np.float64(scene.period or 0.0)}
    drawn = sim.last_contacts(report)
    if drawn is not None:
        contacts, gamma, normal = drawn
        out.update({"contact_a": contacts.body_a, "contact_b": contacts.body_b,
                    "contact_gamma": gamma, "contact_gamma_min": sim.law.gamma_min(contacts),
                    "contact_force": normal})
    return out


def cross_check(report: StepReport) -> float:
    """Largest velocity difference between the step's solution and a Clarabel re-solve.

    Union contacts keep the push/pull branch the step chose, and the shift of
    the fixed point is frozen, so both solve the same convex problem.

    Parameters
    ----------
    report : StepReport
        A step as solved.

    Returns
    -------
    float
        ``max |v - v_ref|`` relative to ``max |v_ref| + max |U - v^k|`` (the
        velocity scale of the step); 0 without contacts.
    """
    problem, result = report.problem, report.result
    if problem.n_contacts == 0:
        return 0.0
    normal = result.forces[: problem.n_contacts]
    convex = problem.with_cones(problem.cones.with_branches(normal < 0))
    convex = convex.with_shift(result.shift)
    reference = solve(convex, "clarabel", tol=1e-9)
    scale = np.max(np.abs(reference.velocities)) + np.max(np.abs(problem.free_velocity))
    return float(np.max(np.abs(result.velocities - reference.velocities)) / scale)


def _progress_bar(total: int, enabled: bool, description: str) -> tqdm | None:
    """A tqdm bar over ``total`` steps named ``description``, or None when disabled or there is
    nothing to do."""
    if not enabled or total <= 0:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit="step", leave=False)
