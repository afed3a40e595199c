"""Runs of the flow experiment with checkpoints, and the angle sweep.

``lubcontact run SCENE`` (:func:`run_main`) steps one scene
(``sedimentation`` or ``inclined_flow``) with a progress bar, measures it
(:mod:`lubcontact.measure`) and writes, in its output folder:

- ``checkpoint.npz``: the full simulation state every ``--checkpoint-every``
  steps (scene arrays, gluey state and warm start by pair key, step count,
  measurement accumulators); ``--resume`` continues from it and reaches the
  same final state as an uninterrupted run;
- ``measurements.npz``: time series (kinetic energy, flow rate, contact
  states, solver residuals and iterations, Clarabel cross-checks), the
  time-averaged profiles and the gamma histogram;
- ``frames/frame_<step>.npz``: positions, velocities, spins and the contacts
  with their gamma, every ``--frame-every`` steps.

Every file is written to a temporary name and renamed, so an interruption
never leaves a half-written file and loses nothing already saved.

``lubcontact sweep`` (:func:`sweep_main`) settles one bed, then runs the
inclined flow for each model and angle (each run resumable), and writes
``sweep.csv`` with Q(theta) and the contact-state fractions, plus plots.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import pathlib
import time
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from ..scenes import inclined as flow
from . import measure
from ..sim import Simulation, SimulationState, StepReport
from ..io.files import save_npz
from ..io.scene_arrays import scene_arrays, scene_from_arrays
from ..model.scene import Grains, Scene
from ..solvers import CONVERGED, methods, solve

SCENES = ("sedimentation", "inclined_flow")
FAST_SOLVERS = ("apgd",)


def default_solver() -> str:
    """The fast solver when one is registered, else the Clarabel reference."""
    available = methods()
    return next((name for name in FAST_SOLVERS if name in available), "clarabel")


@dataclass
class RunConfig:
    """Everything that defines a run (stored in its checkpoint as JSON).

    Attributes
    ----------
    scene : str
        ``sedimentation`` or ``inclined_flow``.
    n_grains : int
        Free grains.
    preset : str
        ``poster`` (SI) or ``dimensionless`` (see :mod:`lubcontact.flow`).
    model : str
        ``dry`` (Coulomb) or ``gluey`` (gluey lubrication + Coulomb).
    angle : float
        Incline angle (degrees) for ``inclined_flow``.
    steps : int
        Total steps of the run.
    dt_fraction : float
        Time step as a fraction of ``sqrt(d / g')``.
    solver, tol : str, float
        Step solver and its tolerance.
    fixed_point : bool
        Exact Coulomb friction by the fixed point on s; default False: the
        convex relaxation, one solve per step (the fixed point cost 3x more
        and often hit its outer-iteration cap on flowing piles, see
        docs/validation.md).
    tol_fp, max_outer : float, int
        Tolerance and outer-iteration cap of that fixed point.
    joint : int
        Solve Coulomb's problem jointly inside the first APGD run, updating
        the shift every ``joint`` iterations, before the outer loop checks it
        (``solve_coulomb(joint=...)``; 0: plain outer loop).
    friction : float or None
        Coulomb coefficient overriding the preset's ``mu`` (None: the preset's).
    checkpoint_every, sample_every, frame_every : int
        Periods (in steps) of checkpoints, measurement samples and frames
        (0: no frames).
    cross_check_every : int
        Every that many steps, re-solve the step with Clarabel (0: never).
    settle_steps : int
        Sedimentation steps before tilting (``inclined_flow`` without a bed).
    settle_model : str
        Model of that sedimentation (``frictionless`` settles fastest).
    bed : str
        Path of a settled bed (a sedimentation checkpoint); empty: settle here.
    average_from : float
        Profiles and means are time-averaged over steps after this fraction
        of the run.
    width : float
        Period along x in mean radii.
    seed : int
    bins_per_radius : int
        Profile slabs per mean radius.
    """

    scene: str = "inclined_flow"
    n_grains: int = 300
    preset: str = "dimensionless"
    model: str = "gluey"
    angle: float = 22.0
    steps: int = 1000
    dt_fraction: float = 0.01
    solver: str = field(default_factory=default_solver)
    tol: float = 1e-6
    fixed_point: bool = False
    tol_fp: float = 1e-8
    max_outer: int = 50
    joint: int = 0
    friction: float | None = None
    checkpoint_every: int = 200
    sample_every: int = 10
    frame_every: int = 0
    cross_check_every: int = 0
    settle_steps: int = 600
    settle_model: str = "frictionless"
    bed: str = ""
    average_from: float = 0.5
    width: float = 40.0
    seed: int = 0
    bins_per_radius: int = 2

    def __post_init__(self):
        if self.scene not in SCENES:
            raise ValueError(f"scene: must be one of {SCENES}, got {self.scene!r}")
        if self.preset not in flow.PRESETS:
            raise ValueError(f"preset: must be one of {tuple(flow.PRESETS)}, got {self.preset!r}")
        for name in ("model", "settle_model"):
            if getattr(self, name) not in flow.MODELS:
                raise ValueError(f"{name}: must be one of {flow.MODELS}, got {getattr(self, name)!r}")
        for name in ("n_grains", "checkpoint_every", "sample_every", "bins_per_radius", "max_outer"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name}: must be >= 1, got {getattr(self, name)}")
        for name in ("steps", "frame_every", "cross_check_every", "settle_steps", "joint"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"{name}: must be >= 0, got {getattr(self, name)}")
        if not self.tol_fp > 0:
            raise ValueError(f"tol_fp: must be > 0, got {self.tol_fp}")
        if self.friction is not None and not self.friction >= 0:
            raise ValueError(f"friction: must be >= 0, got {self.friction}")
        if not 0 <= self.average_from < 1:
            raise ValueError(f"average_from: must be in [0, 1), got {self.average_from}")

    @property
    def params(self) -> flow.FlowParameters:
        params = flow.PRESETS[self.preset]()
        return params if self.friction is None else replace(params, friction=self.friction)

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "RunConfig":
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in json.loads(text).items() if k in known})


# -- atomic files -------------------------------------------------------------------------------
def save_text(path: pathlib.Path, text: str) -> None:
    """Write text atomically (temporary file, then rename)."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text)
    os.replace(temporary, path)


# -- simulation state as arrays --------------------------------------------------------------------
# -- one run ------------------------------------------------------------------------------------
SERIES = ("step", "time", "kinetic_energy", "flow_rate", "contacts", "unglued", "glued",
          "frictional", "residual", "iterations", "converged")


class FlowRun:
    """A simulation with its measurements, checkpoints and frames.

    Parameters
    ----------
    config : RunConfig
    scene : Scene
        Initial scene (periodic).
    out_dir : pathlib.Path or None
        Where files go (None: nothing is written).
    """

    def __init__(self, config: RunConfig, scene: Scene, out_dir: pathlib.Path | None = None):
        self.config = config
        self.params = config.params
        self.out_dir = None if out_dir is None else pathlib.Path(out_dir)
        self.sim = Simulation(scene, self.params.law(config.model),
                              flow.time_step(self.params, config.dt_fraction), solver=config.solver,
                              tol=config.tol, on_failure="ignore", fixed_point=config.fixed_point,
                              tol_fp=config.tol_fp, max_outer=config.max_outer,
                              solver_options={"joint": config.joint} if config.joint else None,
                              keep_trajectory=False)
        r = self.params.radius
        top = float(scene.grains.positions[:, 1].max() + 2 * r)
        self.profiles = measure.ProfileAccumulator(
            np.arange(0.0, top + r / config.bins_per_radius, r / config.bins_per_radius),
            scene.period)
        self.series = {name: [] for name in SERIES}
        self.gamma_counts = np.zeros(20, dtype=np.int64)
        self.cross_checks: list[tuple[int, float]] = []
        self.statuses: dict[str, int] | None = {}      # solver status -> steps (None: unknown)
        self.wall_time = 0.0
        self.cpu_time = 0.0
        self.last_report: StepReport | None = None

    @property
    def steps_done(self) -> int:
        return self.sim.steps_done

    @property
    def averaging(self) -> bool:
        return self.steps_done > self.config.average_from * self.config.steps

    # -- stepping ---------------------------------------------------------------------------
    def advance(self, n_steps: int, progress: bool = False) -> None:
        """Step ``n_steps`` times (not beyond ``config.steps``), measuring and checkpointing."""
        end = min(self.config.steps, self.steps_done + n_steps)
        bar = _progress_bar(end - self.steps_done, self.steps_done, progress, self.config)
        while self.steps_done < end:
            start, start_cpu = time.perf_counter(), time.process_time()
            report = self.sim.step()
            self.wall_time += time.perf_counter() - start
            self.cpu_time += time.process_time() - start_cpu
            if self.statuses is not None:
                status = report.result.status
                self.statuses[status] = self.statuses.get(status, 0) + 1
            self.last_report = report
            self._measure(report)
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()

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
        if self.config.model == "dry":       # every active contact is a Coulomb contact
            states = np.array([0, 0, np.count_nonzero(active)])
        else:
            states = measure.contact_states(report.gamma, gamma_min, active)
        values = (self.steps_done, scene.time, measure.kinetic_energy(scene), measure.flow_rate(scene),
                  int(np.count_nonzero(active)), *states, report.result.residual,
                  report.result.iterations, report.result.success)
        for name, value in zip(SERIES, values):
            self.series[name].append(value)
        if self.averaging:
            self.profiles.add(scene)
            self.gamma_counts += measure.gamma_histogram(report.gamma, gamma_min,
                                                         self.gamma_counts.size)

    # -- files ------------------------------------------------------------------------------
    def measurements(self) -> dict[str, np.ndarray]:
        """Time series, averaged profiles and histograms as arrays."""
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
                    "statuses": np.array(json.dumps(self.statuses)),
                    "config": np.array(self.config.to_json())})
        return out

    def save_checkpoint(self) -> None:
        """Write ``checkpoint.npz`` and ``measurements.npz`` (atomically)."""
        measurements = self.measurements()
        save_npz(self.out_dir / "measurements.npz", **measurements)
        save_npz(self.out_dir / "checkpoint.npz", **self.sim.state.to_arrays(), **measurements)

    def save_frame(self) -> None:
        """Write the current state and contacts to ``frames/frame_<step>.npz``."""
        save_npz(self.out_dir / "frames" / f"frame_{self.steps_done:08d}.npz",
                 **frame_arrays(self.sim, self.last_report))

    @classmethod
    def resume(cls, path: pathlib.Path, out_dir: pathlib.Path | None = None,
               steps: int | None = None, **changes) -> "FlowRun":
        """Rebuild a run from its checkpoint; ``steps`` may extend the total.

        When the extension moves the averaging window past the checkpoint, the
        time averages (profiles, gamma histogram) restart, so that they cover
        the new window only; series are kept whole.

        ``changes`` (RunConfig fields, e.g. ``friction=0.5``) continue the run
        with other settings from the checkpoint's state; they are stored in
        the config of the checkpoints written afterwards.
        """
        path = pathlib.Path(path)
        with np.load(path) as data:
            data = dict(data)
        config = RunConfig.from_json(str(data["config"]))
        if steps is not None:
            changes = {**changes, "steps": int(steps)}
        config = replace(config, **changes)
        state = SimulationState.from_arrays(data)
        run = cls(config, state.scene, path.parent if out_dir is None else out_dir)
        run.sim.restore(state)
        run.series = {name: list(data[f"series.{name}"]) for name in SERIES}
        run.profiles.edges = data["profile.edges"]
        run.profiles.area, run.profiles.momentum = data["profile.area"], data["profile.momentum"]
        run.profiles.samples = int(data["profile.samples"])
        run.gamma_counts = data["gamma_histogram"].astype(np.int64)
        run.cross_checks = [tuple(row) for row in data["cross_checks"]]
        run.wall_time = float(data["wall_time"])
        run.cpu_time = float(data.get("cpu_time", np.nan))  # older checkpoints: unknown
        run.statuses = json.loads(str(data["statuses"])) if "statuses" in data else None
        if run.steps_done <= config.average_from * config.steps and run.profiles.samples:
            run.profiles.reset()
            run.gamma_counts[:] = 0
        return run

    def summary(self) -> dict:
        """Means over the averaging window and the flow verdict."""
        series = {k: np.asarray(v, dtype=float) for k, v in self.series.items()}
        window = series["step"] > self.config.average_from * self.config.steps
        if not np.any(window):
            window = np.ones_like(series["step"], dtype=bool)
        active = series["contacts"][window]
        with np.errstate(invalid="ignore", divide="ignore"):
            fractions = {name: float(np.sum(series[name][window]) / max(np.sum(active), 1))
                         for name in measure.STATES}
        verdict = (measure.classify_flow(series["time"], series["kinetic_energy"], series["flow_rate"])
                   if series["time"].size >= 4 else None)
        checks = np.asarray(self.cross_checks, dtype=float).reshape(-1, 2)
        return {"model": self.config.model, "angle": self.config.angle,
                "steps": self.steps_done, "time": float(self.sim.scene.time),
                "flow_rate": float(np.mean(series["flow_rate"][window])) if window.any() else 0.0,
                "flow_rate_std": float(np.std(series["flow_rate"][window])) if window.any() else 0.0,
                "kinetic_energy": float(series["kinetic_energy"][-1]) if series["time"].size else 0.0,
                "state": verdict.label if verdict else "unknown",
                "energy_ratio": verdict.energy_ratio if verdict else float("nan"),
                "relative_change": verdict.relative_change if verdict else float("nan"),
                **{f"fraction_{k}": v for k, v in fractions.items()},
                "unconverged_steps": (None if self.statuses is None else
                                      sum(n for s, n in self.statuses.items() if s != CONVERGED)),
                "step_statuses": self.statuses,
                "unconverged_samples": int(np.count_nonzero(series["converged"] == 0)),
                "max_cross_check": float(checks[:, 1].max()) if checks.size else float("nan"),
                "wall_time": self.wall_time,
                "steps_per_second": self.steps_done / self.wall_time if self.wall_time else 0.0,
                "cpu_time": self.cpu_time,
                "steps_per_cpu_second": (self.steps_done / self.cpu_time if self.cpu_time
                                         else 0.0),
                "solver": self.config.solver, "tol": self.config.tol}


def frame_arrays(sim: Simulation, report: StepReport | None) -> dict[str, np.ndarray]:
    """Positions, radii, velocities, spins, fixed grains and contacts with gamma."""
    scene = sim.scene
    out = {"time": np.float64(scene.time), "positions": scene.grains.positions,
           "radii": scene.grains.radii, "velocities": scene.grains.velocities,
           "spins": scene.grains.spins, "fixed_positions": scene.fixed_positions,
           "fixed_radii": scene.fixed_radii, "period": np.float64(scene.period or 0.0)}
    if report is not None:
        contacts = report.contacts
        out.update({"contact_a": contacts.body_a, "contact_b": contacts.body_b,
                    "contact_gamma": report.gamma,
                    "contact_gamma_min": sim.law.gamma_min(contacts),
                    "contact_force": report.result.forces[: contacts.count]})
    return out


def cross_check(report: StepReport) -> float:
    """Largest velocity difference between the step's solution and a Clarabel re-solve.

    Union contacts keep the push/pull branch the step chose, and the shift of
    the fixed point is frozen, so both solve the same convex problem. Relative
    to ``max |v_ref| + max |U - v^k|`` (the velocity scale of the step).
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


def _progress_bar(total: int, initial: int, enabled: bool, config: RunConfig):
    if not enabled or total <= 0:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=f"{config.scene} {config.model} {config.angle:g} deg",
                unit="step", leave=False)


# -- scenes for a config --------------------------------------------------------------------------
def initial_scene(config: RunConfig, out_dir: pathlib.Path | None = None,
                  progress: bool = False) -> Scene:
    """The scene a config starts from; ``inclined_flow`` settles a bed first (or loads ``bed``)."""
    params = config.params
    bed_scene = flow.sedimentation(config.n_grains, params, width=config.width * params.radius,
                                   seed=config.seed)
    if config.scene == "sedimentation":
        return bed_scene
    bed_path = pathlib.Path(config.bed) if config.bed else None
    if bed_path is None and out_dir is not None:
        bed_path = pathlib.Path(out_dir) / "bed.npz"
    if bed_path is not None and bed_path.exists():
        with np.load(bed_path) as data:
            settled = scene_from_arrays(dict(data))
    else:
        settled = settle(config, bed_scene, progress)
        if bed_path is not None:
            save_npz(bed_path, **scene_arrays(settled))
    return flow.inclined_flow(settled, config.angle)


def settle(config: RunConfig, scene: Scene, progress: bool = False) -> Scene:
    """Sediment ``scene`` for ``config.settle_steps`` steps with ``config.settle_model``."""
    settling = replace(config, scene="sedimentation", model=config.settle_model,
                       steps=config.settle_steps, cross_check_every=0, frame_every=0)
    run = FlowRun(settling, scene)
    run.advance(settling.steps, progress)
    settled = run.sim.scene.copy()
    settled.time = 0.0
    return settled


# -- command line ------------------------------------------------------------------------------
def _add_common(parser: argparse.ArgumentParser) -> None:
    defaults = RunConfig()
    parser.add_argument("--n", dest="n_grains", type=int, default=defaults.n_grains,
                        help="number of free grains")
    parser.add_argument("--preset", choices=tuple(flow.PRESETS), default=defaults.preset)
    parser.add_argument("--steps", type=int, default=defaults.steps, help="total steps per run")
    parser.add_argument("--dt", dest="dt_fraction", type=float, default=defaults.dt_fraction,
                        help="time step as a fraction of sqrt(d/g')")
    parser.add_argument("--solver", default=defaults.solver, help=f"one of {methods()}")
    parser.add_argument("--tol", type=float, default=defaults.tol)
    parser.add_argument("--fixed-point", action="store_true",
                        help="exact Coulomb friction by the fixed point on s (default: relaxation)")
    parser.add_argument("--tol-fp", type=float, default=defaults.tol_fp,
                        help="tolerance of the fixed point on s")
    parser.add_argument("--max-outer", type=int, default=defaults.max_outer,
                        help="outer-iteration cap of the fixed point on s")
    parser.add_argument("--joint", type=int, default=defaults.joint,
                        help="fixed point: update the shift inside APGD every that many iterations")
    parser.add_argument("--mu", dest="friction", type=float, default=None,
                        help="Coulomb coefficient (default: the preset's)")
    parser.add_argument("--checkpoint-every", type=int, default=defaults.checkpoint_every)
    parser.add_argument("--sample-every", type=int, default=defaults.sample_every)
    parser.add_argument("--cross-check-every", type=int, default=defaults.cross_check_every,
                        help="re-solve a step with Clarabel every that many steps (0: never)")
    parser.add_argument("--settle-steps", type=int, default=defaults.settle_steps)
    parser.add_argument("--settle-model", choices=flow.MODELS, default=defaults.settle_model)
    parser.add_argument("--bed", default="", help="settled bed (.npz) to tilt")
    parser.add_argument("--width", type=float, default=defaults.width, help="period in radii")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--no-progress", dest="progress", action="store_false")


def _config(args: argparse.Namespace, **overrides) -> RunConfig:
    names = {f.name for f in fields(RunConfig)}
    values = {k: v for k, v in vars(args).items() if k in names}
    values.update(overrides)
    return RunConfig(**values)


def run_main(argv: list[str] | None = None) -> int:
    """``lubcontact run SCENE [options]``: one run with checkpoints (``--resume`` continues)."""
    parser = argparse.ArgumentParser(prog="lubcontact run", description=run_main.__doc__)
    parser.add_argument("scene", choices=SCENES)
    parser.add_argument("--model", choices=flow.MODELS, default="gluey")
    parser.add_argument("--angle", type=float, default=RunConfig.angle, help="degrees")
    parser.add_argument("--frame-every", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/run"))
    parser.add_argument("--resume", action="store_true",
                        help="continue from OUT/checkpoint.npz (with --mu or --fixed-point: "
                             "continue with that friction)")
    _add_common(parser)
    args = parser.parse_args(argv)
    checkpoint = args.out / "checkpoint.npz"
    if args.resume and checkpoint.exists():
        changes = {"friction": args.friction} if args.friction is not None else {}
        if args.fixed_point:
            changes.update(fixed_point=True, tol_fp=args.tol_fp, max_outer=args.max_outer,
                           joint=args.joint)
        run = FlowRun.resume(checkpoint, args.out, steps=args.steps, **changes)
        print(f"resuming {checkpoint} at step {run.steps_done}")
    else:
        config = _config(args)
        run = FlowRun(config, initial_scene(config, args.out, args.progress), args.out)
    run.advance(run.config.steps - run.steps_done, args.progress)
    run.save_checkpoint()
    summary = run.summary()
    save_text(args.out / "summary.json", json.dumps(summary, indent=2))
    from . import plots

    plots.snapshot(run.sim, run.last_report, args.out / "snapshot.png")
    plots.profiles([(f"{run.config.model} {run.config.angle:g} deg", run.profiles.profile())],
                   args.out / "profile.png", run.params)
    print(json.dumps(summary, indent=2))
    return 0


def parse_angles(text: str) -> np.ndarray:
    """``"15:28:1"`` (start:stop:step, stop included) or ``"15,20,25"`` -> angles (degrees)."""
    try:
        if ":" in text:
            start, stop, step = (float(v) for v in text.split(":"))
            if step <= 0:
                raise ValueError
            return np.round(np.arange(start, stop + 0.5 * step, step), 10)
        return np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise ValueError(f"angles: expected start:stop:step or a comma list, got {text!r}") from None


SWEEP_COLUMNS = ("model", "angle", "flow_rate", "flow_rate_std", "state", "energy_ratio",
                 "relative_change", "fraction_unglued", "fraction_glued", "fraction_frictional",
                 "kinetic_energy", "steps", "time", "unconverged_steps", "max_cross_check",
                 "wall_time", "steps_per_second", "cpu_time", "steps_per_cpu_second", "solver", "tol")


def sweep(config: RunConfig, angles: np.ndarray, models: list[str], out_dir: pathlib.Path,
          progress: bool = False) -> list[dict]:
    """Every (model, angle) run from one settled bed; finished runs are read back, not redone."""
    out_dir = pathlib.Path(out_dir)
    rows = []
    for model in models:
        for angle in angles:
            run_dir = out_dir / model / f"angle_{angle:05.2f}"
            done = run_dir / "summary.json"
            if done.exists():
                rows.append(json.loads(done.read_text()))
                continue
            run_config = replace(config, model=model, angle=float(angle),
                                 bed=str(out_dir / "bed.npz"))
            checkpoint = run_dir / "checkpoint.npz"
            if checkpoint.exists():
                run = FlowRun.resume(checkpoint, run_dir, steps=run_config.steps)
            else:
                run = FlowRun(run_config, initial_scene(run_config, out_dir, progress), run_dir)
            run.advance(run_config.steps - run.steps_done, progress)
            run.save_checkpoint()
            summary = run.summary()
            save_text(done, json.dumps(summary, indent=2))
            rows.append(summary)
            print(f"{model:6s} {angle:5.1f} deg  Q = {summary['flow_rate']:.4g}  "
                  f"{summary['state']}  {summary['steps_per_second']:.1f} steps/s", flush=True)
    write_csv(out_dir / "sweep.csv", rows)
    return rows


def write_csv(path: pathlib.Path, rows: list[dict]) -> None:
    """Sweep rows as CSV (atomic)."""
    path = pathlib.Path(path)
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=SWEEP_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(temporary, path)


def sweep_main(argv: list[str] | None = None) -> int:
    """``lubcontact sweep --angles 15:28:1``: Q(theta) and contact states for both models."""
    parser = argparse.ArgumentParser(prog="lubcontact sweep", description=sweep_main.__doc__)
    parser.add_argument("--angles", default="15:28:1", help="start:stop:step or a comma list")
    parser.add_argument("--models", default="dry,gluey", help="comma list of dry, gluey")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/sweep"))
    _add_common(parser)
    args = parser.parse_args(argv)
    angles = parse_angles(args.angles)
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    for model in models:
        if model not in flow.MODELS:
            raise ValueError(f"models: unknown model {model!r}; choose from {flow.MODELS}")
    config = _config(args, scene="inclined_flow")
    rows = sweep(config, angles, models, args.out, args.progress)
    from . import plots

    plots.sweep_figures(rows, args.out, config.preset)
    print(f"wrote {args.out / 'sweep.csv'}")
    return 0


# -- demo ---------------------------------------------------------------------------------------
def demo(out_dir: pathlib.Path, *, n_grains: int = 150, steps: int = 150, settle_steps: int = 400,
         width: float = 20.0) -> dict:
    """A small gluey + friction inclined flow with Clarabel cross-checks; writes figures and a report.

    150 grains on a 20-radius period (a layer about 14 diameters thick),
    settled without friction, then tilted to 24 degrees and stepped with
    gluey lubrication + friction by the fast solver (Clarabel when none is
    registered) at tolerance 1e-6; every 25th step is re-solved by Clarabel. Writes
    ``flow_snapshot.png``, ``flow_profile.png``, ``flow_report.md`` and the
    run's files under ``out_dir/flow``.

    The keyword arguments shrink it (tests); the defaults are the demo.

    Returns
    -------
    dict
        The run summary (flow rate, contact fractions, cross-check error, timing).
    """
    out_dir = pathlib.Path(out_dir)
    run_dir = out_dir / "flow"
    config = RunConfig(scene="inclined_flow", n_grains=n_grains, width=width, model="gluey",
                       angle=24.0, steps=steps, dt_fraction=0.025, settle_steps=settle_steps, tol=1e-6,
                       checkpoint_every=100, sample_every=5, cross_check_every=25,
                       average_from=0.5)
    run = FlowRun(config, initial_scene(config, run_dir), run_dir)
    run.advance(config.steps)
    run.save_checkpoint()
    summary = run.summary()
    from . import plots

    plots.snapshot(run.sim, run.last_report, out_dir / "flow_snapshot.png")
    plots.profiles([("gluey + friction, 24 deg", run.profiles.profile())],
                   out_dir / "flow_profile.png", run.params)
    save_text(out_dir / "flow_report.md", demo_report(summary, config))
    save_text(run_dir / "summary.json", json.dumps(summary, indent=2))
    return summary


def demo_report(summary: dict, config: RunConfig) -> str:
    """A short Markdown report of the demo flow."""
    lines = [
        "# Gluey + friction flow down a rough incline (demo)", "",
        f"{config.n_grains} polydisperse disks (r = 1 +/- 20 %, dimensionless units r = g' = 1), "
        f"period {config.width:g} r, settled then tilted to {config.angle:g} degrees; "
        f"{summary['steps']} steps of dt = {config.dt_fraction:g} sqrt(d/g').", "",
        "| quantity | value |", "|---|---|",
        f"| solver | {summary['solver']} (tol {summary['tol']:g}) |",
        f"| flow rate Q (time-averaged, second half) | {summary['flow_rate']:.4g} r^2 / t |",
        f"| flow state | {summary['state']} |",
        f"| active contacts unglued / glued / frictional | {summary['fraction_unglued']:.3f} / "
        f"{summary['fraction_glued']:.3f} / {summary['fraction_frictional']:.3f} |",
        f"| largest Clarabel cross-check difference (relative velocity) | "
        f"{summary['max_cross_check']:.2e} |",
        f"| steps not converged | {summary['unconverged_steps']} |",
        f"| speed | {summary['steps_per_second']:.1f} steps/s |", "",
        "Figures: `flow_snapshot.png` (contacts coloured by gamma, gamma_min frictional to 0 "
        "lubricated), `flow_profile.png` (velocity and packing-fraction profiles).", ""]
    return "\n".join(lines)
