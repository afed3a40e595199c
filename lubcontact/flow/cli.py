"""The commands ``lubcontact run`` (:func:`run_main`), ``lubcontact sweep`` (:func:`sweep_main`),
``lubcontact hysteresis`` (:func:`hysteresis_main`) and ``lubcontact window``
(:func:`window_main`: a run's series over a window of steps, from its checkpoint).

``lubcontact run SCENE`` steps one scene (``sedimentation`` or
``inclined_flow``) with a progress bar (on a terminal), writes the files of
:mod:`lubcontact.flow.run` in its output folder, a snapshot and the profiles,
and prints the summary. ``--resume`` continues the run of the folder's
checkpoint to its stored total (``--steps`` changes the total); options that
define the scene or the physics cannot change on resume.

``lubcontact sweep`` settles one bed, then runs the inclined flow for each
model and angle (:mod:`lubcontact.flow.sweep`, each run resumable), and writes
``sweep.csv`` with Q(theta) and the contact-state fractions, plus plots.

``lubcontact window RUN ...`` reads runs' checkpoints (finished or not) and prints a
sampled series over a window of steps: mean, block standard error, trend and block means
(:func:`~lubcontact.flow.measure.window_statistics`), the flow's verdict over the window
(:func:`~lubcontact.flow.measure.classify_flow`) and, with ``--approach``, the limit the block
means approach (:func:`~lubcontact.flow.measure.fit_approach`).

Parsing imports neither the solvers nor the scenes nor matplotlib, so that
``--help`` is instant: the options' defaults are ``None`` (that is how an option
given explicitly is told from a default) and :func:`_fill_defaults` puts the
real ones, shown in ``--help``, afterwards. A bad value is a one-line error
naming the option (exit status 2). Ctrl-C (SIGINT) or SIGTERM stop a run
between two steps with a checkpoint, one line on stderr, exit status 130.
"""
from __future__ import annotations

import argparse
import math
import pathlib
import shlex
import sys
from collections.abc import Callable
from dataclasses import fields
from typing import TYPE_CHECKING, Any, NoReturn

from ..bench.options import number
from . import interrupt
from .config import (
    DEFINING_FIELDS,
    DT_UNIT,
    MODEL_NAMES,
    PRESET_NAMES,
    Q_UNIT,
    SCENES,
    STEADY_TOL,
    STOP_RATIO,
    RunConfig,
)

if TYPE_CHECKING:
    import numpy as np

    from .run import FlowRun

FLAGS = {"scene": "SCENE", "n_grains": "--n", "preset": "--preset", "model": "--model",
         "angle": "--angle", "steps": "--steps", "dt_fraction": "--dt", "solver": "--solver",
         "tol": "--tol", "fixed_point": "--fixed-point", "tol_fp": "--tol-fp",
         "max_outer": "--max-outer", "joint": "--joint", "friction": "--mu",
         "checkpoint_every": "--checkpoint-every", "sample_every": "--sample-every",
         "frame_every": "--frame-every", "cross_check_every": "--cross-check-every",
         "settle_steps": "--settle-steps", "settle_model": "--settle-model", "bed": "--bed",
         "start_from": "--start-from", "widen": "--widen", "average_from": "--average-from",
         "width": "--width", "seed": "--seed", "viscosity": "--viscosity",
         "roughness": "--roughness"}
"""The option of each :class:`RunConfig` field (the name used in error messages)."""
DEFAULTS = {f.name: f.default for f in fields(RunConfig) if f.name in FLAGS and f.name != "solver"}
"""Real defaults of the config options (``solver``: :func:`~lubcontact.flow.config.default_solver`)."""


def parse_angles(text: str) -> Any:
    """Angles from ``"15:28:1"`` (start:stop:step, stop included) or ``"15,20,25"``.

    Parameters
    ----------
    text : str
        The ``--angles`` argument (degrees).

    Returns
    -------
    ndarray, shape (n,)
        The angles (degrees); a range is rounded to 10 decimals.

    Raises
    ------
    ValueError
        If ``text`` is neither form, or the step is not positive.
    """
    import numpy as np

    try:
        if ":" in text:
            start, stop, step = (float(v) for v in text.split(":"))
            if step <= 0:
                raise ValueError
            return np.round(np.arange(start, stop + 0.5 * step, step), 10)
        return np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise ValueError(f"angles: expected start:stop:step or a comma list, "
                         f"got {text!r}") from None


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line: ``prog: error: message (see prog --help)``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _angle(text: str) -> float:
    value = number(float)(text)
    if not -90 < value < 90:
        raise argparse.ArgumentTypeError(f"must be in (-90, 90) degrees, got {text}")
    return value


def _default(name: str) -> str:
    """``(default: X)`` for the help of a config option."""
    return f"(default: {DEFAULTS[name]:g})" if isinstance(DEFAULTS[name], float) else \
        f"(default: {DEFAULTS[name]})"


def _add_common(parser: argparse.ArgumentParser, resume: bool, steps: bool = True,
                start: bool = True) -> None:
    """The options ``run``, ``sweep`` and ``hysteresis`` share (defaults: :class:`RunConfig`,
    filled after parsing).

    ``resume``: the parser has ``--resume`` (the help says what it does to ``--steps`` and
    ``--mu``); ``steps``: it has ``--steps`` (a ramp's length follows from its stages);
    ``start``: it has ``--start-from`` and ``--average-from`` (a ramp starts from a bed at rest
    and reads its holds, not an averaging window).
    """
    add = parser.add_argument
    add("--n", dest="n_grains", type=number(int, 1), default=None, metavar="N",
        help=f"number of free grains {_default('n_grains')}")
    add("--preset", choices=PRESET_NAMES, default=None,
        help="physical parameters: poster (SI units, r = 1 mm, water-like fluid) or "
             f"dimensionless (r = g' = rho_p = 1) {_default('preset')}")
    if steps:
        add("--steps", type=number(int, 1), default=None,
            help=(f"total steps of the run {_default('steps')}; with --resume: the new total "
                  "(default there: the checkpoint's)") if resume else
                 f"total steps of each run {_default('steps')}")
    add("--dt", "--dt-fraction", dest="dt_fraction", type=number(float, 0, above=True),
        default=None, metavar="FRACTION",
        help=f"time step in units of {DT_UNIT}, d the mean grain diameter and g' the reduced "
             f"gravity g (1 - rho_f/rho_p) {_default('dt_fraction')}")
    add("--solver", default=None,
        help="step solver, a registered method name (an unknown name lists them) "
             "(default: newton-ac with --fixed-point, apgd-jacobi without; clarabel when not "
             "registered)")
    add("--tol", type=number(float, 0, above=True), default=None,
        help=f"solver tolerance (normalised residual) {_default('tol')}")
    add("--fixed-point", action=argparse.BooleanOptionalAction, default=None,
        help="exact Coulomb friction by the fixed point on s; --no-fixed-point: the convex "
             "relaxation, one solve per step (default: the relaxation)")
    add("--tol-fp", type=number(float, 0, above=True), default=None,
        help=f"tolerance of the fixed point on s {_default('tol_fp')}")
    add("--max-outer", type=number(int, 1), default=None,
        help=f"outer-iteration cap of the fixed point on s {_default('max_outer')}")
    add("--joint", type=number(int, 0), default=None,
        help="exact Coulomb: start each step with the joint phase, APGD updating the shift "
             f"every that many iterations, 0: never {_default('joint')}")
    add("--mu", dest="friction", type=number(float, 0), default=None,
        help="Coulomb friction coefficient" + ("; may change on --resume" if resume else "")
             + " (default: the preset's, 0.3)")
    add("--checkpoint-every", type=number(int, 1), default=None, metavar="STEPS",
        help=f"write checkpoint.npz every that many steps {_default('checkpoint_every')}")
    add("--sample-every", type=number(int, 1), default=None, metavar="STEPS",
        help=f"record the time series every that many steps {_default('sample_every')}")
    add("--cross-check-every", type=number(int, 0), default=None, metavar="STEPS",
        help="re-solve a step with Clarabel every that many steps, 0: never "
             f"{_default('cross_check_every')}")
    add("--settle-steps", type=number(int, 0), default=None, metavar="STEPS",
        help="sedimentation steps that settle the bed before it is tilted (inclined_flow "
             f"without --bed and without OUT/bed.npz) {_default('settle_steps')}")
    add("--settle-model", choices=MODEL_NAMES, default=None,
        help=f"contact model of that sedimentation {_default('settle_model')}")
    add("--bed", default=None, metavar="NPZ",
        help="settled bed to tilt: a bed.npz or a sedimentation checkpoint (default: OUT/bed.npz "
             "when it exists, else one settled first and saved there)")
    if start:
        add("--start-from", dest="start_from", default=None, metavar="CHECKPOINT",
            help="start inclined_flow from the grains of a run's checkpoint.npz, velocities "
                 "kept, tilted to the angle (a developed flow turned to another angle; no bed "
                 "is settled; the contacts' glue states and the solver's warm start begin "
                 "afresh); in a sweep, {model} and {seed} in the path are each run's, a "
                 "literal brace is written twice (default: none, the bed at rest)")
        add("--widen", type=number(int, 1), default=None, metavar="COPIES",
            help="with --start-from: that state's layer COPIES times side by side, the copies "
                 "parted by a velocity jitter of 1e-3 of the rms seeded by --seed; --n and "
                 f"--width are the wide layer's {_default('widen')}")
        add("--average-from", type=number(float, 0, high=1), default=None,
            metavar="FRACTION",
            help="time averages (Q, fractions, profiles) over the steps after this fraction "
                 f"of each run; fixed once a run has started {_default('average_from')}")
    add("--width", type=number(float, 0, above=True), default=None, metavar="RADII",
        help=f"period along x in mean grain radii {_default('width')}")
    add("--seed", type=number(int, 0), default=None,
        help="seed of the grain sizes, the bed and the initial jitter, and of the jitter that "
             f"parts the copies of --widen {_default('seed')}")
    add("--viscosity", type=number(float, 0, above=True), default=None, metavar="ETA",
        help="fluid viscosity eta (Pa s) of the poster preset: sets gamma_min (default: the "
             "preset's, 1e-3)")
    add("--roughness", type=number(float, 0, above=True), default=None, metavar="EPS",
        help="asperity height eps (m) of the poster preset: sets gamma_min (default: the "
             "preset's, 1e-6)")
    add("--no-progress", dest="progress", action="store_false",
        help="no progress bar (default: a bar when stderr is a terminal, none otherwise)")


def run_parser() -> argparse.ArgumentParser:
    """The parser of ``lubcontact run`` (its options' defaults are None: see the module)."""
    parser = _Parser(
        prog="lubcontact run",
        description="One run of the flow experiment with checkpoints: sedimentation (grains "
                    "settle on a rough bed) or inclined_flow (a settled bed tilted by --angle, "
                    "or a run's state with --start-from). "
                    "Writes checkpoint.npz, measurements.npz, summary.json and figures in OUT; "
                    "--resume continues the run stored there. Ctrl-C stops it with a checkpoint. "
                    f"Flow rates are given in units of {Q_UNIT}, the time step in {DT_UNIT} "
                    "(d: mean grain diameter, g': reduced gravity).")
    parser.add_argument("scene", nargs="?", choices=SCENES, default=None,
                        help="the scene: sedimentation or inclined_flow (default: none; with "
                             "--resume the checkpoint's)")
    parser.add_argument("--model", choices=MODEL_NAMES, default=None,
                        help="contact model: dry (Coulomb friction), gluey (gluey lubrication + "
                             "Coulomb friction) or frictionless " + _default("model"))
    parser.add_argument("--angle", type=_angle, default=None, metavar="DEGREES",
                        help="incline angle of inclined_flow (not for sedimentation) "
                             + _default("angle"))
    parser.add_argument("--frame-every", type=number(int, 0), default=None, metavar="STEPS",
                        help="write frames/frame_<step>.npz every that many steps, 0: none "
                             + _default("frame_every"))
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/run"),
                        help="output folder (default: out/run)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run of OUT/checkpoint.npz to its stored total; "
                             "--steps, the solver options, --mu and the output periods may "
                             "change, the options that define the scene or the physics and "
                             "--average-from may not (default: off, a new run)")
    _add_common(parser, resume=True)
    return parser


def sweep_parser() -> argparse.ArgumentParser:
    """The parser of ``lubcontact sweep`` (its options' defaults are None: see the module)."""
    parser = _Parser(
        prog="lubcontact sweep",
        description="Q(theta) and the contact states of inclined flows, for each model and "
                    "angle, all tilted from one settled bed (or from a run's state, "
                    "--start-from); each run is resumable (run the same "
                    "command again). Writes sweep.csv and figures in OUT. "
                    f"Flow rates Q are given in units of {Q_UNIT} (d: mean grain diameter, "
                    "g': reduced gravity).")
    parser.add_argument("--angles", default="15:28:1",
                        help="incline angles in degrees: start:stop:step (stop included) or a "
                             "comma list (default: 15:28:1)")
    parser.add_argument("--models", default="dry,gluey",
                        help="comma list of contact models among dry, gluey, frictionless "
                             "(default: dry,gluey)")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/sweep"),
                        help="output folder (default: out/sweep)")
    _add_parallel(parser)
    _add_axes(parser)
    _add_common(parser, resume=False)
    return parser


def _add_parallel(parser: argparse.ArgumentParser) -> None:
    """``--workers`` and ``--scheduler``: where the independent runs go."""
    parser.add_argument("--workers", type=int, default=1, metavar="N",
                        help="runs at once, each in its own process; the results do not "
                             "depend on it (default: 1)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run the runs on the Dask cluster of this scheduler "
                             "(tcp://host:port; its workers must see the files the runs read "
                             "and write; needs the optional "
                             "dependency distributed) (default: none, local processes)")


def hysteresis_parser() -> argparse.ArgumentParser:
    """The parser of ``lubcontact hysteresis`` (its options' defaults are None: see the module)."""
    from .config import FLOW_SPEED

    parser = _Parser(
        prog="lubcontact hysteresis",
        description="Hysteresis of the flow angle: for each model and seed, a settled bed tilted "
                    "to --from, held --hold steps at each angle and turned by --step degrees "
                    "up to --to, then back down. theta_start: the first angle of the way up "
                    "from which the layer flows (mean downhill velocity above --flow-speed at "
                    "the end of a hold) at every later hold; theta_stop: the first angle of the "
                    "way down from which it stays still. Writes hysteresis.csv, stages.csv and "
                    "ramp.png in OUT; the runs are resumable (run the same command again).")
    parser.add_argument("--models", default="dry,gluey",
                        help="comma list of contact models among dry, gluey, frictionless "
                             "(default: dry,gluey)")
    parser.add_argument("--seeds", default="0", metavar="LIST",
                        help="comma list of seeds, each with its own bed (default: 0)")
    parser.add_argument("--from", dest="start", type=_angle, default=14.0, metavar="DEGREES",
                        help="first angle of the ramp (default: 14)")
    parser.add_argument("--to", dest="stop", type=_angle, default=28.0, metavar="DEGREES",
                        help="turning angle of the ramp (default: 28)")
    parser.add_argument("--step", type=number(float, 0, above=True), default=1.0,
                        metavar="DEGREES", help="degrees per stage (default: 1)")
    parser.add_argument("--hold", type=number(int, 1), default=200, metavar="STEPS",
                        help="steps at each angle (default: 200)")
    parser.add_argument("--flow-speed", type=number(float, 0, above=True), default=FLOW_SPEED,
                        metavar="SPEED",
                        help="a layer flows when its mean downhill velocity exceeds this, in "
                             f"units of sqrt(g' d) (default: {FLOW_SPEED:g})")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/hysteresis"),
                        help="output folder (default: out/hysteresis)")
    _add_parallel(parser)
    _add_common(parser, resume=False, steps=False, start=False)
    return parser


RAMP_FLAGS = {**FLAGS, "angle": "--from", "stop": "--to", "step": "--step", "ramp_step": "--step",
              "ramp_stages": "--to", "hold_steps": "--hold", "steps": "--hold", "seed": "--seeds"}
"""The option of each field in ``lubcontact hysteresis`` (its ramp is given by --from, --to,
--step and --hold)."""
AXIS_FLAGS = {"seed": "--seeds", "viscosity": "--viscosities", "roughness": "--roughnesses"}
"""The list option of each axis a sweep can vary (:data:`lubcontact.flow.sweep.AXES`)."""


def _add_axes(parser: argparse.ArgumentParser) -> None:
    """``--seeds``, ``--viscosities``, ``--roughnesses``: comma lists, one sub-folder per combination."""
    add = parser.add_argument
    add("--seeds", default=None, metavar="LIST",
        help="comma list of seeds: each gets its own bed and runs in OUT/seed_<k>/, and "
             "sweep_means.csv gives the means over seeds with their spread (default: --seed's)")
    add("--viscosities", default=None, metavar="LIST",
        help="comma list of fluid viscosities eta (Pa s, poster preset), runs in OUT/eta_<eta>/; "
             "only the gluey model depends on it: sweep it with --models gluey "
             "(default: --viscosity's)")
    add("--roughnesses", default=None, metavar="LIST",
        help="comma list of asperity heights eps (m, poster preset), runs in OUT/eps_<eps>/; "
             "only the gluey model depends on it (default: --roughness's)")


def _axis_values(args: argparse.Namespace, parser: argparse.ArgumentParser,
                 names: tuple[str, ...] = tuple(AXIS_FLAGS)) -> dict[str, list | None]:
    """The values of the list options of ``names`` (``--seeds``, ``--viscosities``,
    ``--roughnesses``; None: not given)."""
    values: dict[str, list | None] = {}
    for name in names:
        flag = AXIS_FLAGS[name]
        text = getattr(args, flag[2:])
        if text is None:
            values[name] = None
            continue
        if getattr(args, name, None) is not None:
            parser.error(f"argument {flag}: not with {FLAGS[name]}")
        kind = number(int, 0) if name == "seed" else number(float, 0, above=True)
        try:
            items = [kind(item.strip()) for item in text.split(",") if item.strip()]
        except argparse.ArgumentTypeError as exc:
            parser.error(f"argument {flag}: {exc}")
        if not items or len(set(items)) != len(items):
            parser.error(f"argument {flag}: expected distinct comma-separated values, "
                         f"got {text!r}")
        values[name] = items
    return values


def _given(args: argparse.Namespace) -> set[str]:
    """The config options given on the command line (those not left at None)."""
    return {name for name in FLAGS if getattr(args, name, None) is not None}


def _fill_defaults(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Replace the None of options not given by their real defaults; check ``--solver``."""
    for name, value in DEFAULTS.items():
        if hasattr(args, name) and getattr(args, name) is None and name != "friction":
            setattr(args, name, value)
    from ..solvers import methods
    from .config import default_solver

    if args.solver is None:
        args.solver = default_solver(bool(args.fixed_point))
    elif args.solver not in methods():
        parser.error(f"argument --solver: unknown solver {args.solver!r}; registered: "
                     f"{', '.join(methods())}")


def _config(args: argparse.Namespace, parser: argparse.ArgumentParser,
            **overrides: Any) -> RunConfig:
    """The :class:`RunConfig` of parsed arguments, with ``overrides``; a bad value is a usage error."""
    names = RunConfig.field_names()
    values = {k: v for k, v in vars(args).items() if k in names}
    values.update(overrides)
    try:
        return RunConfig(**values)
    except ValueError as exc:
        field, _, message = str(exc).partition(": ")
        parser.error(f"argument {FLAGS.get(field, field)}: {message}")


def _show(name: str, value: Any, flags: dict[str, str] = FLAGS) -> str:
    """``--flag value`` as a user would type it (``flags``: the command's option of each field)."""
    flag = flags[name]
    if isinstance(value, bool):
        return flag if value else f"--no-{flag[2:]}"
    if value is None:
        return f"{flag} (its default)"
    shown = f"{value:g}" if isinstance(value, float) else str(value)
    return shown if flag == "SCENE" else f"{flag} {shown}"


def _resume(args: argparse.Namespace, parser: argparse.ArgumentParser, given: set[str]
            ) -> FlowRun:
    """The run of ``OUT/checkpoint.npz``, continued as the given options say (usage errors else)."""
    from .run import FlowRun
    from .sweep import stored_config

    checkpoint = args.out / "checkpoint.npz"
    if not checkpoint.exists():
        parser.error(f"--resume: no checkpoint at {checkpoint} (start the run without --resume)")
    stored = stored_config(checkpoint)
    conflicts = [name for name in DEFINING_FIELDS if name in given
                 and getattr(args, name) != getattr(stored, name)]
    if "average_from" in given and args.average_from != stored.average_from:
        parser.error(f"argument --average-from: the checkpoint's run averages from "
                     f"{stored.average_from:g} of its steps and its profiles were accumulated so; "
                     "drop the option, or start a new run in another --out")
    if conflicts:
        parser.error("--resume: " + ", ".join(_show(n, getattr(args, n)) for n in conflicts)
                     + " differ from the checkpoint's run ("
                     + ", ".join(_show(n, getattr(stored, n)) for n in conflicts)
                     + "); options that define the scene or the physics cannot change on resume: "
                       "drop them, or start a new run in another --out")
    changes = {name: getattr(args, name) for name in given - set(DEFINING_FIELDS) - {"steps"}
               if getattr(args, name) != getattr(stored, name)}
    steps = args.steps if "steps" in given else None
    try:
        run = FlowRun.resume(checkpoint, args.out, steps=steps, **changes)
    except ValueError as exc:
        field, _, message = str(exc).partition(": ")
        parser.error(f"argument {FLAGS.get(field, field)}: {message}")
    complete = " (complete: its summary is written again)" if run.steps_done >= run.config.steps \
        else ""
    print(f"resuming {checkpoint} at step {run.steps_done} of {run.config.steps}{complete}")
    if steps is not None and steps != stored.steps:
        print(f"--steps {steps}: the run's total changes from {stored.steps} to {steps} steps")
    for name, value in sorted(changes.items()):
        print(f"continuing with {_show(name, value)} (the checkpoint's run had "
              f"{_show(name, getattr(stored, name))})")
    return run


def _interrupted_line(exc: interrupt.Interrupted, resume: str) -> str:
    """The one line printed when a run is stopped by a signal."""
    if exc.checkpoint is None:
        return (f"interrupted at step {exc.step} ({exc.what}), before any checkpoint of the run: "
                f"nothing to resume; run the command again")
    return f"interrupted at step {exc.step} ({exc.what}); resume with: {resume}"


def run_main(argv: list[str] | None = None) -> int:
    """``lubcontact run SCENE [options]``: one run with checkpoints (``--resume`` continues).

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``run`` (default: the command line's).

    Returns
    -------
    int
        Exit status: 0, or 130 when stopped by SIGINT / SIGTERM (a checkpoint
        is written and one line printed on stderr). Usage errors exit with 2.
    """
    parser = run_parser()
    args = parser.parse_args(argv)
    given = _given(args)
    if args.resume:
        stored_scene = None
        checkpoint = args.out / "checkpoint.npz"
        if checkpoint.exists():
            from .sweep import stored_config

            stored_scene = stored_config(checkpoint).scene
        args.scene = args.scene or stored_scene or "inclined_flow"
        given.add("scene")
    elif args.scene is None:
        parser.error("the scene is required: sedimentation or inclined_flow (or --resume)")
    if args.scene == "sedimentation" and "angle" in given:
        parser.error("argument --angle: a sedimentation has no incline angle")
    _fill_defaults(args, parser)
    if args.scene == "sedimentation":
        args.angle = None
    progress = args.progress and sys.stderr.isatty()
    from .bed import initial_scene
    from .run import FlowRun, summary_json

    run = None
    if args.resume:
        run = _resume(args, parser, given)
    else:
        config = _config(args, parser)
        _check_start(config, parser)
    resume = f"lubcontact run --out {shlex.quote(str(args.out))} --resume"
    try:
        with interrupt.stop_on_signals():
            if run is None:
                run = FlowRun(config, initial_scene(config, args.out, progress), args.out)
            summary = run.finish(progress)
    except interrupt.Interrupted as exc:
        print(_interrupted_line(exc, resume), file=sys.stderr)
        return interrupt.EXIT_STATUS
    except KeyboardInterrupt:
        step = "" if run is None else f" at step {run.steps_done}"
        print(f"interrupted again{step}: stopped at once; the last checkpoint resumes: {resume}",
              file=sys.stderr)
        return interrupt.EXIT_STATUS
    from . import plots

    incline = run.config.scene == "inclined_flow"
    label = (f"{run.config.model} {run.config.angle:g} deg" if incline
             else f"{run.config.model} sedimentation")
    plots.snapshot(run.sim, run.last_report, args.out / "snapshot.png")
    plots.profiles([(label, run.profiles.profile())], args.out / "profile.png", run.params,
                   incline=incline)
    print(summary_json(summary))
    if run.failure is not None:
        print(f"lubcontact run: stopped at {run.failure}; the state before that step is in "
              f"{args.out / 'checkpoint.npz'}", file=sys.stderr)
        return 1
    return 0


def _check_runs(runs: list, parser: argparse.ArgumentParser,
                flags: dict[str, str] = FLAGS) -> None:
    """Refuse, before any work, run folders of other runs and unfinished runs past ``--steps``.

    ``flags``: the command's option of each config field (for its messages).
    """
    from .sweep import folder_conflicts, stored_steps

    for config, run_dir in runs:
        changed = folder_conflicts(run_dir, config)
        if changed:
            parser.error(f"argument --out: {run_dir} holds a run made with "
                         + ", ".join(_show(name, old, flags) for name, (old, _) in changed.items())
                         + " (here: " + ", ".join(_show(name, new, flags) for name, (_, new)
                                                  in changed.items())
                         + "): use another --out")
        done = stored_steps(run_dir / "checkpoint.npz")
        if done > config.steps and not (run_dir / "summary.json").exists():
            parser.error(f"argument {flags['steps']}: {config.steps} is below the step {done} "
                         f"that the unfinished run in {run_dir} has reached")
        if not (run_dir / "checkpoint.npz").exists():
            _check_start(config, parser)


def _check_start(config: RunConfig, parser: argparse.ArgumentParser) -> None:
    """Refuse, before any work, a ``--start-from`` state that a new run cannot start from."""
    if not config.start_from:
        return
    from .bed import started_scene

    try:
        started_scene(config)
    except ValueError as exc:
        parser.error(f"argument --start-from: {str(exc).partition(': ')[2]}")


def _models(text: str, parser: argparse.ArgumentParser) -> list[str]:
    """The models of ``--models`` (a usage error names an unknown one)."""
    models = [m.strip() for m in text.split(",") if m.strip()]
    unknown = [m for m in models if m not in MODEL_NAMES]
    if unknown or not models:
        parser.error(f"argument --models: unknown model(s) {', '.join(unknown) or '(none given)'}; "
                     f"choose from {', '.join(MODEL_NAMES)}")
    return models


def _guarded(work: Callable[[], Any], resume: str, scheduler: str | None) -> tuple[Any, int]:
    """Run a sweep's ``work`` (inside :func:`~lubcontact.flow.interrupt.stop_on_signals`).

    Returns
    -------
    (object, int)
        ``work()``'s result and 0, or None and the exit status after one line
        on stderr: 130 when stopped by a signal (the runs under way are
        checkpointed; ``resume`` continues them), 2 when ``scheduler`` cannot
        be reached, 1 when a worker process died.
    """
    from concurrent.futures.process import BrokenProcessPool

    try:
        with interrupt.stop_on_signals():
            return work(), 0
    except interrupt.Interrupted as exc:
        print(_interrupted_line(exc, resume), file=sys.stderr)
        return None, interrupt.EXIT_STATUS
    except KeyboardInterrupt:
        print(f"interrupted again: stopped at once; the last checkpoints resume: {resume}",
              file=sys.stderr)
        return None, interrupt.EXIT_STATUS
    except OSError as exc:              # --scheduler: no cluster at that address
        if scheduler is None:
            raise
        print(f"lubcontact: argument --scheduler: cannot reach {scheduler}: {exc}",
              file=sys.stderr)
        return None, 2
    except BrokenProcessPool:
        print(f"a worker process died (killed or out of memory); the runs resume from their last "
              f"checkpoints: {resume}", file=sys.stderr)
        return None, 1


def _check_parallel(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """``--workers`` >= 1; ``--scheduler`` only with the optional dependency installed."""
    if args.workers < 1:
        parser.error(f"argument --workers: must be >= 1, got {args.workers}")
    if args.scheduler is not None:
        try:
            import distributed  # noqa: F401
        except ImportError:
            parser.error("argument --scheduler: needs the optional dependency distributed "
                         "(pip install lubcontact[dask])")


def sweep_main(argv: list[str] | None = None) -> int:
    """``lubcontact sweep --angles 15:28:1``: Q(theta) and contact states for both models.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``sweep`` (default: the command line's).

    Returns
    -------
    int
        Exit status: 0, or 130 when stopped by SIGINT / SIGTERM (the run under
        way is checkpointed; the same command continues the sweep). Usage
        errors (malformed ``--angles``, an unknown model, a folder holding
        another sweep) exit with 2.
    """
    argv = sys.argv[2:] if argv is None else list(argv)
    parser = sweep_parser()
    args = parser.parse_args(argv)
    try:
        angles = parse_angles(args.angles)
    except ValueError as exc:
        parser.error(f"argument --angles: {str(exc).partition(': ')[2]}")
    models = _models(args.models, parser)
    if angles.size == 0:
        parser.error(f"argument --angles: no angle in {args.angles!r}")
    _check_parallel(args, parser)
    for angle in angles:
        if not -90 < angle < 90:
            parser.error(f"argument --angles: {angle:g} is not in (-90, 90) degrees")
    axes = _axis_values(args, parser)
    _fill_defaults(args, parser)
    config = _config(args, parser, scene="inclined_flow", model=models[0],
                     angle=float(angles[0]))
    from .sweep import axis_groups, sweep, sweep_runs, write_report

    groups = axis_groups(**axes)
    try:
        runs = sweep_runs(config, angles, models, args.out, groups)
    except ValueError as exc:              # e.g. --viscosities with the dimensionless preset
        field, _, message = str(exc).partition(": ")
        parser.error(f"argument {AXIS_FLAGS.get(field, FLAGS.get(field, field))}: {message}")
    _check_runs(runs, parser)
    progress = args.progress and sys.stderr.isatty()
    resume = "lubcontact sweep " + shlex.join(argv)
    rows, status = _guarded(lambda: sweep(config, angles, models, args.out,
                                          progress and args.workers == 1, workers=args.workers,
                                          scheduler=args.scheduler, groups=groups),
                            resume, args.scheduler)
    if rows is None:
        return status
    from . import plots

    plots.sweep_figures(rows, args.out, config.preset, groups)
    write_report(args.out, rows, resume)
    print(f"wrote {args.out / 'sweep.csv'}")
    return 0


def hysteresis_main(argv: list[str] | None = None) -> int:
    """``lubcontact hysteresis --from 14 --to 28``: theta_start and theta_stop per model and seed.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``hysteresis`` (default: the command line's).

    Returns
    -------
    int
        Exit status: 0, 130 when stopped by SIGINT / SIGTERM (the runs under
        way are checkpointed; the same command continues), 2 for a usage error.
    """
    argv = sys.argv[2:] if argv is None else list(argv)
    parser = hysteresis_parser()
    args = parser.parse_args(argv)
    models = _models(args.models, parser)
    _check_parallel(args, parser)
    if args.seed is not None:
        parser.error("argument --seed: use --seeds")
    seeds = _axis_values(args, parser, ("seed",))["seed"]
    _fill_defaults(args, parser)
    from .hysteresis import hysteresis, model_means, ramp_config, ramp_runs

    base = _config(args, parser, scene="inclined_flow", model=models[0], angle=args.start)
    try:
        config = ramp_config(base, args.start, args.stop, args.step, args.hold)
    except ValueError as exc:
        field, _, message = str(exc).partition(": ")
        parser.error(f"argument {RAMP_FLAGS.get(field, field)}: {message}")
    _check_runs(ramp_runs(config, models, seeds, args.out), parser, RAMP_FLAGS)
    progress = args.progress and sys.stderr.isatty()
    outcome, status = _guarded(lambda: hysteresis(
        config, models, seeds, args.out, flow_speed=args.flow_speed,
        progress=progress and args.workers == 1, workers=args.workers, scheduler=args.scheduler),
        "lubcontact hysteresis " + shlex.join(argv), args.scheduler)
    if outcome is None:
        return status
    from . import plots

    results, stage_rows = outcome
    plots.ramp_curves(stage_rows, args.out / "ramp.png", args.flow_speed)
    for model, entry in model_means(results).items():
        print(f"{model:6s} theta_start {entry['theta_start']:.4g} +/- {entry['theta_start_sd']:.2g}"
              f" ({entry['theta_start_n']} of {entry['seeds']} seeds)  theta_stop "
              f"{entry['theta_stop']:.4g} +/- {entry['theta_stop_sd']:.2g} "
              f"({entry['theta_stop_n']})  width {entry['width']:.3g} +/- "
              f"{entry['width_sd']:.2g} deg")
    print(f"wrote {args.out / 'hysteresis.csv'}")
    return 0


WINDOW_SERIES = ("flow_rate", "mean_velocity", "kinetic_energy", "contacts", "unglued", "glued",
                 "frictional", "coordination_unglued", "coordination_glued",
                 "coordination_frictional", "residual", "iterations", "converged", "time", "angle")
"""The sampled series ``lubcontact window`` reads (``series.<name>`` of a run's checkpoint): every
one of :data:`lubcontact.flow.run.SERIES` but ``step`` (written out here: parsing imports no run
code; a test holds the two equal)."""


def window_parser() -> argparse.ArgumentParser:
    """The parser of ``lubcontact window``."""
    parser = _Parser(
        prog="lubcontact window",
        description="A run's sampled series over a window of steps (the last --length steps "
                    "up to --end): its mean, the block standard error (the spread of the "
                    "means of --blocks equal blocks of steps) and the trend (last block's mean "
                    "minus the first's), for each run given; the flow rate in "
                    f"{Q_UNIT}. Also the flow's verdict over the window: no_flow where the "
                    f"kinetic energy at its end is below {STOP_RATIO:g} of the run's largest so "
                    "far, else from the mean flow rates of its two halves: steady (within "
                    f"{100 * STEADY_TOL:g} %), accelerating or transient (slowing), with the "
                    "relative change; with --approach, the value the block means approach (an "
                    "exponential fitted to them). Reads each run's checkpoint.npz, so a run "
                    "still going can be read.")
    parser.add_argument("runs", nargs="+", type=pathlib.Path, metavar="RUN",
                        help="run folders (holding checkpoint.npz) or checkpoint files")
    parser.add_argument("--length", type=number(int, 2), required=True, metavar="STEPS",
                        help="window length in steps, a multiple of --blocks")
    parser.add_argument("--end", type=number(int, 2), default=None, metavar="STEP",
                        help="last step of the window (default: each run's last step)")
    parser.add_argument("--blocks", type=number(int, 2), default=5, metavar="N",
                        help="blocks of steps the window is cut into (default: 5)")
    parser.add_argument("--series", choices=WINDOW_SERIES, default="flow_rate",
                        help="the sampled quantity (default: flow_rate)")
    parser.add_argument("--approach", action="store_true",
                        help="also fit m(t) = limit - A exp(-t / tau) to the block means (at "
                             "least 4 blocks) and print the limit, its standard error and tau "
                             "in steps: an extrapolation of the steady value of a run still "
                             "approaching it, whose standard error is the fit's only, not how "
                             "far the flow's approach is from an exponential ('-' where the "
                             "means show no approach)")
    return parser


def window_main(argv: list[str] | None = None) -> int:
    """``lubcontact window RUN ... --length 3000``: each run's series over a window of steps.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``window`` (default: the command line's).

    Returns
    -------
    int
        Exit status: 0, or 2 for a usage error (no checkpoint, a window the run has not
        reached or that is not a whole number of blocks, a series without samples there: one
        line naming the argument, before anything is printed).
    """
    argv = sys.argv[2:] if argv is None else list(argv)
    parser = window_parser()
    args = parser.parse_args(argv)
    import numpy as np

    from .measure import fit_approach, window_statistics
    from .run import read_checkpoint

    if args.approach and args.blocks < 4:
        parser.error(f"argument --blocks: --approach fits 3 parameters to the block means: "
                     f"needs at least 4 blocks, got {args.blocks}")
    key = f"series.{args.series}"
    rows = []
    for run in args.runs:                     # every run read before anything is printed
        if not run.exists():
            parser.error(f"argument RUN: no such file or folder: {run}")
        try:
            data = read_checkpoint(run / "checkpoint.npz" if run.is_dir() else run, "RUN")
        except ValueError as exc:
            parser.error(f"argument {exc}")
        done = int(data["steps_done"])
        if key not in data or (args.series == "flow_rate" and "units" not in data):
            parser.error(f"argument --series: {run} predates the series {args.series} (or its "
                         "unit): resume it once with lubcontact run --resume to convert it")
        end = done if args.end is None else args.end
        if end > done:
            parser.error(f"argument --end: {run} has reached step {done}, not {end}")
        if end < args.length:
            flag = "--length" if args.end is None else "--end"
            parser.error(f"argument {flag}: the window of {args.length} steps up to step {end} "
                         f"starts before {run}'s first step")
        steps = data["series.step"]
        inside = (steps > end - args.length) & (steps <= end)
        values = data[key][inside]
        if not np.isfinite(values).all():
            parser.error(f"argument --series: {run} has no {args.series} samples in the window "
                         "(a checkpoint older than the series)")
        try:
            window = window_statistics(steps[inside], values, end, args.length, args.blocks)
        except ValueError as exc:
            field, _, message = str(exc).partition(": ")
            flag = {"end": "--end", "length": "--length", "blocks": "--blocks"}.get(field, field)
            parser.error(f"argument {flag}: {run}: {message}")
        verdict = _window_verdict(data, inside, steps <= end)
        approach = ()
        if args.approach:
            fit = fit_approach(window.centres, window.blocks)
            approach = tuple(_significant(value, digits) if fit.found else "-" for value, digits
                             in ((fit.limit, 4), (fit.limit_error, 2), (fit.tau, 3)))
        rows.append((str(run), done, f"({end - args.length}, {end}]", window, verdict, approach))
    width = max(len(name) for name, *_ in rows)
    unit = f" in {Q_UNIT}" if args.series == "flow_rate" else ""
    print(f"{'run':{width}s} {'steps':>7s} {'window':>15s} {'mean':>10s} {'block s.e.':>10s} "
          f"{'trend':>10s}  {'flow (halves)':>20s}  "
          + (f"{'limit':>10s} {'s.e.':>8s} {'tau':>8s}  " if args.approach else "")
          + f"block means ({args.series}{unit})")
    for name, done, span, window, (label, change), approach in rows:
        fitted = "".join(f"{value:>{size}s} " for value, size in zip(approach, (10, 8, 8),
                                                                     strict=True)) if approach else ""
        blocks = " ".join(_significant(mean, 4) for mean in window.blocks)
        trend = ("+" if window.trend >= 0 else "") + _significant(window.trend, 3)
        print(f"{name:{width}s} {done:7d} {span:>15s} {_significant(window.mean, 4):>10s} "
              f"{_significant(window.standard_error, 2):>10s} {trend:>10s}  {label:>12s} "
              f"{change:>7s}  {fitted + ' ' if fitted else ''}{blocks}")
    return 0


def _window_verdict(data: dict, inside: np.ndarray, so_far: np.ndarray) -> tuple[str, str]:
    """The flow's verdict over a window (:func:`~lubcontact.flow.measure.classify_flow` on its
    samples ``inside``, the peak energy over the samples ``so_far``) and its relative change,
    as printed; ``("-", "-")`` for a checkpoint without the series or a window of fewer than four
    finite samples."""
    import numpy as np

    from .measure import classify_flow

    names = ("series.time", "series.kinetic_energy", "series.flow_rate")
    if not all(name in data for name in names):
        return "-", "-"
    flow = [data[name][inside] for name in names]
    if flow[0].size < 4 or not all(np.isfinite(series).all() for series in flow):
        return "-", "-"
    state = classify_flow(*flow, window=1.0,
                          peak_energy=np.nanmax(data["series.kinetic_energy"][so_far]))
    return state.label, f"{100 * state.relative_change:+.1f}%"


def _significant(value: float, digits: int) -> str:
    """``value`` with ``digits`` significant digits, in fixed notation from 1e-3 to 1e6 (so that
    146.0 prints next to 144.7, not as 146), else in exponent notation."""
    if value == 0 or not 1e-3 <= abs(value) < 1e6:
        return f"{value:.{digits}g}"
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(value))))
    return f"{value:.{decimals}f}"
