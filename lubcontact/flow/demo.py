"""The inclined-flow part of ``lubcontact demo``: a small gluey + friction flow and its report."""
from __future__ import annotations

import math
import pathlib
from typing import Any

from ..io.files import save_text
from . import plots
from .bed import initial_scene
from .config import DT_UNIT, Q_UNIT, RunConfig
from .run import FlowRun

SIGNIFICANT_DIGITS = 4
"""Significant digits of the numbers in the text outputs (:func:`summary_lines`, the report)."""


def demo(out_dir: pathlib.Path, *, n_grains: int = 150, steps: int = 150, settle_steps: int = 400,
         width: float = 20.0) -> dict[str, Any]:
    """A small gluey + friction inclined flow with Clarabel cross-checks, its figures and report.

    150 grains on a 20-radius period (a layer about 14 diameters thick),
    settled without friction, then tilted to 24 degrees and stepped with
    gluey lubrication + friction by the fast solver (Clarabel when none is
    registered) at tolerance 1e-6; every 25th step is re-solved by Clarabel.
    Writes ``flow_snapshot.png``, ``flow_profile.png``, ``flow_report.md``
    and the run's files (:mod:`lubcontact.flow.run`) in ``out_dir`` itself
    (``lubcontact demo`` gives it ``out/flow``).

    The keyword arguments shrink it (tests); the defaults are the demo.

    Parameters
    ----------
    out_dir : pathlib.Path
        Output folder of the flow part.
    n_grains : int
        Free grains.
    steps : int
        Steps after tilting.
    settle_steps : int
        Sedimentation steps before tilting.
    width : float
        Period along x (mean radii).

    Returns
    -------
    dict
        The run summary (:meth:`FlowRun.summary <lubcontact.flow.run.FlowRun.summary>`:
        flow rate in units of ``d sqrt(g' d)``, contact fractions, cross-check
        error, timing); :func:`summary_lines` shows it as text.
    """
    out_dir = pathlib.Path(out_dir)
    config = RunConfig(scene="inclined_flow", n_grains=n_grains, width=width, model="gluey",
                       angle=24.0, steps=steps, dt_fraction=0.025, settle_steps=settle_steps,
                       tol=1e-6, checkpoint_every=100, sample_every=5, cross_check_every=25,
                       average_from=0.5)
    run = FlowRun(config, initial_scene(config, out_dir), out_dir)
    summary = run.finish()
    plots.snapshot(run.sim, run.last_report, out_dir / "flow_snapshot.png")
    plots.profiles([("gluey + friction, 24 deg", run.profiles.profile())],
                   out_dir / "flow_profile.png", run.params)
    save_text(out_dir / "flow_report.md", demo_report(summary, config))
    return summary


def format_value(value: Any, digits: int = SIGNIFICANT_DIGITS) -> str:
    """A summary value as text: floats to ``digits`` significant digits, ``n/a`` for NaN or None.

    Parameters
    ----------
    value : Any
        A float, int, str, None, or a dict or list of those.
    digits : int
        Significant digits of floats.

    Returns
    -------
    str
    """
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, bool) or not isinstance(value, float):
        if isinstance(value, dict):
            return ", ".join(f"{k} {format_value(v, digits)}" for k, v in value.items()) or "-"
        if isinstance(value, (list, tuple)):
            return ", ".join(format_value(v, digits) for v in value)
        return str(value)
    return f"{value:.{digits}g}"


def summary_lines(summary: dict[str, Any], indent: str = "  ") -> list[str]:
    """The lines ``key: value`` of a run summary, numbers rounded (:func:`format_value`).

    Parameters
    ----------
    summary : dict
        A run summary.
    indent : str
        Put before each line.

    Returns
    -------
    list of str
    """
    return [f"{indent}{key}: {format_value(value)}" for key, value in summary.items()]


def demo_report(summary: dict[str, Any], config: RunConfig) -> str:
    """A short Markdown report of the demo flow.

    Parameters
    ----------
    summary : dict
        The run's summary.
    config : RunConfig
        The run's configuration.

    Returns
    -------
    str
        Markdown: the set-up, a table of results (flow rate in units of
        ``d sqrt(g' d)``, time step in ``sqrt(d/g')``, with ``d`` the mean
        grain diameter and ``g'`` the reduced gravity) and the figures' names.
    """
    value = format_value
    lines = [
        "# Gluey + friction flow down a rough incline (demo)", "",
        (f"{config.n_grains} polydisperse disks (r = 1 +/- 20 %, dimensionless units r = g' = 1), "
         f"period {config.width:g} r, settled then tilted to {config.angle:g} degrees; "
         f"{summary['steps']} steps of dt = {config.dt_fraction:g} {DT_UNIT}."), "",
        (f"Units: d is the mean grain diameter (2 r), g' the reduced gravity g (1 - rho_f / rho_p); "
         f"the flow rate Q (grain area crossing a section per unit time) is given in units of "
         f"{Q_UNIT}, the time step in units of {DT_UNIT}."), "",
        "| quantity | value |", "|---|---|",
        f"| solver | {summary['solver']} (tol {summary['tol']:g}) |",
        (f"| flow rate Q (time-averaged, second half) | {value(summary['flow_rate'])} "
         f"{Q_UNIT} |"),
        f"| flow state | {summary['state']} |",
        (f"| active contacts unglued / glued / frictional | {summary['fraction_unglued']:.3f} / "
         f"{summary['fraction_glued']:.3f} / {summary['fraction_frictional']:.3f} |"),
        ("| largest Clarabel cross-check difference (relative velocity) | "
         f"{value(summary['max_cross_check'], 3)} |"),
        f"| steps not converged | {summary['unconverged_steps']} |",
        f"| steps solved again by Clarabel (above the failure threshold) | "
        f"{summary['rescued_steps']} |",
        (f"| speed | {summary['steps_per_second']:.1f} steps/s (after an untimed warm-up of "
         f"{summary.get('warm_up_time', 0.0):.2g} s: compilation, first imports) |"), "",
        ("Figures: `flow_snapshot.png` (contacts coloured by their glue level gamma / gamma_min, "
         "1 frictional to 0 lubricated), `flow_profile.png` (velocity and packing-fraction "
         "profiles)."), ""]
    return "\n".join(lines)
