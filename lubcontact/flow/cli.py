"""The commands ``lubcontact run`` (:func:`run_main`) and ``lubcontact sweep`` (:func:`sweep_main`).

``lubcontact run SCENE`` steps one scene (``sedimentation`` or
``inclined_flow``) with a progress bar, writes the files of
:mod:`lubcontact.flow.run` in its output folder, a snapshot and the profiles,
and prints the summary; ``--resume`` continues from the folder's checkpoint.

``lubcontact sweep`` settles one bed, then runs the inclined flow for each
model and angle (:mod:`lubcontact.flow.sweep`, each run resumable), and writes
``sweep.csv`` with Q(theta) and the contact-state fractions, plus plots.
"""
from __future__ import annotations

import argparse
import json
import pathlib
from typing import Any

import numpy as np

from ..scenes import inclined
from ..solvers import methods
from .bed import initial_scene
from .config import SCENES, RunConfig
from .run import FlowRun
from .sweep import sweep


def parse_angles(text: str) -> np.ndarray:
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


def _add_common(parser: argparse.ArgumentParser) -> None:
    """The options ``run`` and ``sweep`` share (defaults: :class:`RunConfig`)."""
    defaults = RunConfig()
    parser.add_argument("--n", dest="n_grains", type=int, default=defaults.n_grains,
                        help="number of free grains")
    parser.add_argument("--preset", choices=tuple(inclined.PRESETS), default=defaults.preset)
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
    parser.add_argument("--settle-model", choices=inclined.MODELS, default=defaults.settle_model)
    parser.add_argument("--bed", default="", help="settled bed (.npz) to tilt")
    parser.add_argument("--width", type=float, default=defaults.width, help="period in radii")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--no-progress", dest="progress", action="store_false")


def _config(args: argparse.Namespace, **overrides: Any) -> RunConfig:
    """The :class:`RunConfig` of parsed arguments (their config fields), with ``overrides``."""
    names = RunConfig.field_names()
    values = {k: v for k, v in vars(args).items() if k in names}
    values.update(overrides)
    return RunConfig(**values)


RUN_DESCRIPTION = ("``lubcontact run SCENE [options]``: one run with checkpoints "
                   "(``--resume`` continues).")
SWEEP_DESCRIPTION = ("``lubcontact sweep --angles 15:28:1``: Q(theta) and contact states "
                     "for both models.")


def run_main(argv: list[str] | None = None) -> int:
    """``lubcontact run SCENE [options]``: one run with checkpoints (``--resume`` continues).

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``run`` (default: the command line's).

    Returns
    -------
    int
        Exit status (0).
    """
    parser = argparse.ArgumentParser(prog="lubcontact run", description=RUN_DESCRIPTION)
    parser.add_argument("scene", choices=SCENES)
    parser.add_argument("--model", choices=inclined.MODELS, default="gluey")
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
    summary = run.finish(args.progress)
    from . import plots

    plots.snapshot(run.sim, run.last_report, args.out / "snapshot.png")
    plots.profiles([(f"{run.config.model} {run.config.angle:g} deg", run.profiles.profile())],
                   args.out / "profile.png", run.params)
    print(json.dumps(summary, indent=2))
    return 0


def sweep_main(argv: list[str] | None = None) -> int:
    """``lubcontact sweep --angles 15:28:1``: Q(theta) and contact states for both models.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``sweep`` (default: the command line's).

    Returns
    -------
    int
        Exit status (0).

    Raises
    ------
    ValueError
        For malformed ``--angles`` or an unknown model in ``--models``.
    """
    parser = argparse.ArgumentParser(prog="lubcontact sweep", description=SWEEP_DESCRIPTION)
    parser.add_argument("--angles", default="15:28:1", help="start:stop:step or a comma list")
    parser.add_argument("--models", default="dry,gluey", help="comma list of dry, gluey")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/sweep"))
    _add_common(parser)
    args = parser.parse_args(argv)
    angles = parse_angles(args.angles)
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    for model in models:
        if model not in inclined.MODELS:
            raise ValueError(f"models: unknown model {model!r}; choose from {inclined.MODELS}")
    config = _config(args, scene="inclined_flow")
    rows = sweep(config, angles, models, args.out, args.progress)
    from . import plots

    plots.sweep_figures(rows, args.out, config.preset)
    print(f"wrote {args.out / 'sweep.csv'}")
    return 0
