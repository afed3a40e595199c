"""``lubcontact demo``: the main job on built-in scenes, with a text report and plots.

1. The poster's push-pull (gluey contact), against its exact solution.
2. A settling pile of polydisperse disks with gluey lubrication, and a table
   of every registered solver on its last step (time and error side by side).
3. A gluey + friction flow down an incline (``lubcontact.flow.demo``), with a fast solver and
   periodic Clarabel cross-checks.
"""
from __future__ import annotations

import argparse
import importlib
import time
from pathlib import Path

import numpy as np

from . import scenes
from .bench.harness import MethodRow, compare_methods
from .bench.options import plain
from .bench.tables import format_table
from .model.laws import GlueyLubrication
from .sim.simulation import Simulation
from .sim.trajectory import StepReport
from .solvers import CONVERGED, methods


def push_pull_section(out: Path, dt: float = 1e-2) -> str:
    """Run the push-pull, plot q(t) and gamma(t) against the exact solution."""
    sim = Simulation(scenes.push_pull(), GlueyLubrication(), dt, d_max=0.02)
    gamma = []
    sim.run(int(round(5.0 / dt)), callback=lambda s, r: gamma.append(r.gamma.min() if r.gamma.size else 0.0))
    record = sim.trajectory.arrays()
    times, gap = record["times"], record["positions"][:, 0, 1] - 0.5
    gamma = np.concatenate([[0.0], gamma])
    exact_gap = np.where(times < np.sqrt(2.0), 1.0 - times**2 / 2,
                         np.where(times < 4.0, 0.0, (times - 4.0) ** 2 / 2))
    exact_gamma = np.where((times >= np.sqrt(2.0)) & (times <= 2.0), -times,
                           np.where((times > 2.0) & (times < 4.0), times - 4.0, 0.0))
    unglue = times[1:][(gamma[1:] == 0) & (times[1:] > 2.0)][0]
    _plot_push_pull(out / "push_pull.png", times, gap, gamma, exact_gap, exact_gamma)
    return "\n".join([
        f"Push-pull (poster): q0 = 1, m = g = 1, force reversed at t = 2, dt = {dt}",
        f"  gamma(t=2)      = {gamma[int(round(2.0 / dt))]:+.9f}   (exact -2)",
        f"  unglued at t    = {unglue:.4f}        (exact 4)",
        f"  max |q - q_exact| after ungluing = {np.max(np.abs(gap - exact_gap)[times >= 4]):.2e} (O(dt))",
        f"  plot: {out / 'push_pull.png'}"])


def _plot_push_pull(path: Path, times: np.ndarray, gap: np.ndarray, gamma: np.ndarray,
                    exact_gap: np.ndarray, exact_gamma: np.ndarray) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    axes[0].plot(times, exact_gap, "k--", lw=1, label="exact (gluey limit)")
    axes[0].plot(times, gap, lw=2, alpha=0.8, label="lubcontact")
    axes[0].set_ylabel("gap q (length)")
    axes[1].plot(times, exact_gamma, "k--", lw=1, label="exact")
    axes[1].plot(times, gamma, lw=2, alpha=0.8, label="lubcontact")
    axes[1].set_ylabel(r"glue state $\gamma$ (impulse)")
    axes[1].set_xlabel("time t")
    for ax in axes:
        ax.axvline(2.0, color="grey", lw=0.5)
        ax.legend(loc="best")
        ax.grid(alpha=0.3)
    axes[0].set_title("Push-pull: pushed until t = 2, pulled after")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def pile_section(out: Path, n_grains: int = 200, steps: int = 80) -> str:
    """Settle a gluey pile, plot it, and compare every solver on its last step."""
    sim = Simulation(scenes.settling_pile(n_grains, seed=3), GlueyLubrication(), dt=0.05)
    start = time.perf_counter()
    sim.run(steps - 1)
    report = sim.step()
    elapsed = time.perf_counter() - start
    _plot_pile(out / "pile.png", sim, report)
    rows = compare_methods(report.problem, methods(), tol=1e-6)
    table = format_table(rows, ["method", "status", "iterations", "setup_s", "solve_s",
                                "velocity_error", "residual", "min_gap"])
    glued = int(np.count_nonzero(report.gamma < 0))
    contacts = report.contacts.count
    between_grains = int(np.count_nonzero(report.contacts.a_is_free))
    return "\n".join([
        f"Settling pile: {n_grains} disks, gluey lubrication, {steps} steps of dt = 0.05 "
        f"({elapsed:.1f} s with clarabel)",
        f"  last step: {contacts} contacts ({between_grains} between grains, "
        f"{contacts - between_grains} with the walls), {glued} glued, "
        f"most negative gap {report.gaps_after.min():.1e}",
        f"  plot: {out / 'pile.png'}",
        "", "Solvers on the last step (tol 1e-6; error = relative velocity error vs Clarabel 1e-10):",
        table, *_unconverged_note(rows)])


def _unconverged_note(rows: list[MethodRow]) -> list[str]:
    """A line under the solver table naming the methods that did not converge on the step, or
    none: their rows are the answers they stopped at, not failures of the table."""
    stopped = [f"{row.method} ({row.status})" for row in rows if row.status != CONVERGED]
    if not stopped:
        return []
    return [f"Not converged on this step: {', '.join(stopped)}; their errors are those of the answer "
            "they stopped at (which method suits which problem: docs/guide/choosing-a-solver.md)."]


def _plot_pile(path: Path, sim: Simulation, report: StepReport) -> None:
    """The pile with its contacts between grains (those with the walls are not drawn): unglued in
    grey, glued coloured by ``log10 |gamma|``.

    A linear scale drawn to the deepest glue (gamma near -100) painted the common glued
    contacts (-5 < gamma < 0) in the colour of unglued ones; a log scale and a separate
    colour for gamma = 0 keep the three apart (unglued, lightly and deeply glued).
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Circle

    grains = sim.scene.grains
    fig, ax = plt.subplots(figsize=(7, 6))
    circles = PatchCollection([Circle(p, r) for p, r in zip(grains.positions, grains.radii)],
                              facecolor="#d9c8a9", edgecolor="#7a6a50", lw=0.5)
    ax.add_collection(circles)
    contacts = report.contacts
    pairs = contacts.a_is_free
    segments = np.stack([grains.positions[contacts.body_a[pairs]],
                         grains.positions[contacts.body_b[pairs]]], 1)
    gamma = report.gamma[pairs]
    glued = gamma < 0
    ax.add_collection(LineCollection(segments[~glued], colors="#9a9a9a", lw=1.0,
                                     label=f"between grains, unglued (gamma = 0): "
                                           f"{np.count_nonzero(~glued)}"))
    if glued.any():
        lines = LineCollection(segments[glued], array=-gamma[glued], cmap="viridis", lw=1.6,
                               norm=LogNorm(vmin=(-gamma[glued]).min(), vmax=(-gamma[glued]).max()),
                               label=f"between grains, glued (gamma < 0): {np.count_nonzero(glued)}")
        ax.add_collection(lines)
        fig.colorbar(lines, ax=ax,
                     label=r"glue depth $|\gamma|$ (impulse; units $\rho = g = d = 1$; log scale)")
    fig.legend(loc="lower center", ncol=2, fontsize=8)          # below the axis label
    ax.set_xlim(0, sim.scene.metadata["width"])
    ax.set_ylim(0, grains.positions[:, 1].max() + 1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (grain diameters)")
    ax.set_ylabel("y (grain diameters)")
    ax.set_title(f"Gluey pile at t = {sim.scene.time:.2f}: contacts coloured by glue state")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def flow_section(out: Path) -> str:
    """The inclined-flow demo when :mod:`lubcontact.flow.demo` provides one."""
    try:
        flow_demo = importlib.import_module("lubcontact.flow.demo")
    except ModuleNotFoundError:
        return ""
    if not hasattr(flow_demo, "demo"):
        return ""
    summary = flow_demo.demo(out / "flow")
    lines = [f"Inclined flow (see {out / 'flow'}):"]
    lines += flow_demo.summary_lines(dict(summary or {}))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="lubcontact demo", description=plain(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    parser.add_argument("--no-flow", action="store_true", help="skip the inclined-flow part")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "summary.txt"
    sections = [push_pull_section(args.out), pile_section(args.out)]
    summary_path.write_text("\n\n".join(sections) + "\n")     # written before the long part
    print("\n\n".join(sections))
    if not args.no_flow:
        flow = flow_section(args.out)
        if flow:
            sections.append(flow)
            summary_path.write_text("\n\n".join(sections) + "\n")
            print("\n" + flow)
    print(f"\nreport written to {summary_path}")
    return 0
