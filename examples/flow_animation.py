"""An immersed granular flow down a rough incline, animated, contacts coloured by the glue state.

Teaches: what the poster's experiment looks like (docs/guide/model.md section 8). 48
polydisperse disks (r = 1 +/- 20 %, dimensionless units r = g' = 1, mu = 0.3,
``gamma_min = -0.5 m sqrt(g' d)``) settle without friction on a rough bed (period 16 r), then the
bed is tilted to 30 degrees and the layer flows with gluey lubrication + friction
(``GlueyCoulomb``, apgd-jacobi with the joint fixed point). Each contact segment is coloured by
its glue level gamma / gamma_min: 0 (yellow, lubricated, just glued) to 1 (dark, frictional:
asperities touch, gamma at its floor gamma_min).

Nothing here has a closed form; the script prints what a reader should check (full run, 300
steps to t = 10.6): the flow rate ``Q = sum pi r^2 v_x / L`` keeps growing (0.43 to 9.5: at 30
degrees this thin layer accelerates); most active contacts sit at gamma_min (frictional, 66 % at
the end); a step whose fixed point on s runs out of outer iterations ends with status
``max_iter`` (1 of the 300 steps today): it is applied (``on_failure="ignore"``) and counted,
never hidden, and its deepest overlap is printed beside that of the converged steps (1.2e-5 r
for both today).

Run: ``python examples/flow_animation.py [--quick] [--out DIR]`` (about 14 s; ``--quick``: 60
flow steps, 6 s). Writes ``flow_animation.gif`` and its last frame ``flow_animation.png``.
"""
import argparse
from collections import Counter
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.animation import PillowWriter
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.patches import Circle

from lubcontact import Simulation, StepReport
from lubcontact.bench.tables import format_table
from lubcontact.flow.measure import flow_rate
from lubcontact.flow.plots import GLUE_COLORMAP, contact_segments
from lubcontact.scenes import inclined

ANGLE, GRAINS, WIDTH = 30.0, 48, 16.0


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Settle, tilt, run and film the flow; write the GIF and its last frame."""
    steps, every = (60, 3) if quick else (300, 6)
    params = inclined.dimensionless_parameters()
    dt = inclined.time_step(params, 0.025)
    settle = Simulation(inclined.sedimentation(GRAINS, params, width=WIDTH, seed=3),
                        params.law("frictionless"), dt, solver="apgd-as", tol=1e-6)
    settle.run(300)
    law = params.law("gluey")
    tilted = inclined.inclined_flow(settle.scene, ANGLE)
    tilted.time = 0.0                                             # the clock starts at the tilt
    sim = Simulation(tilted, law, dt, solver="apgd-jacobi",
                     tol=1e-6, tol_fp=1e-5, solver_options={"joint": 5}, on_failure="ignore")
    scene = sim.scene
    fig, ax = plt.subplots(figsize=(7, 6.5))
    ax.add_collection(PatchCollection([Circle(p, r) for p, r in zip(scene.fixed_positions,
                                                                     scene.fixed_radii)], color="0.4"))
    grains = ax.add_collection(PatchCollection([], facecolor="0.88", edgecolor="0.6", antialiased=False))
    lines = ax.add_collection(LineCollection([], cmap=GLUE_COLORMAP, linewidths=2.5))
    lines.set_clim(0.0, 1.0)
    fig.colorbar(lines, ax=ax, fraction=0.04, label="glue level gamma / gamma_min (-)\n"
                 "0: unglued or lubricated ... 1: frictional")
    ax.set(xlim=(0, WIDTH), ylim=(0, 16), aspect="equal", xlabel="x, downhill (r, periodic)",
           ylabel="y, normal to the bed (r)")
    fig.tight_layout()
    rows = []

    def frame(s: Simulation, report: StepReport) -> None:
        if s.steps_done % every:
            return
        grains.set_paths([Circle(p, r) for p, r in zip(s.scene.grains.positions, s.scene.grains.radii)])
        segments, level = contact_segments(s, *s.last_contacts(report))
        lines.set_segments(segments)
        lines.set_array(level)
        ax.set_title(f"Gluey + frictional flow at {ANGLE:g} degrees, t = {s.scene.time:.2f} sqrt(r / g')")
        writer.grab_frame()
        active = (report.gamma < 0) | (report.result.forces[: report.contacts.count] > 0)
        unglued, glued, frictional = s.law.contact_states(report.contacts, report.gamma,
                                                          active).sum(axis=1)
        rows.append(dict(t=s.scene.time, flow_rate=flow_rate(s.scene), contacts=int(active.sum()),
                         glued=glued, frictional=frictional, min_gap=min(s.trajectory.min_gap[-every:])))

    out.mkdir(parents=True, exist_ok=True)
    writer = PillowWriter(fps=8)
    with writer.saving(fig, out / "flow_animation.gif", dpi=60):
        sim.run(steps, frame)
    fig.savefig(out / "flow_animation.png", dpi=75, bbox_inches="tight")
    plt.close(fig)
    print(format_table(rows[:: max(1, len(rows) // 10)] + rows[-1:],
                       ["t", "flow_rate", "contacts", "glued", "frictional", "min_gap"]))
    statuses = Counter(sim.trajectory.status)
    print("statuses:", dict(statuses))
    status, gaps = np.array(sim.trajectory.status), np.array(sim.trajectory.min_gap)
    checks = dict(flow_rate=rows[-1]["flow_rate"], frictional_fraction=rows[-1]["frictional"] /
                  rows[-1]["contacts"], min_gap_converged=gaps[status == "converged"].min(),
                  min_gap_not_converged=gaps[status != "converged"].min(initial=0.0),
                  max_iter_fraction=statuses["max_iter"] / steps)
    print(format_table([checks], list(checks)))
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="60 flow steps")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
