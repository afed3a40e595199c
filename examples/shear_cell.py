"""A shear cell with moving walls: compress a granular layer, then shear it; the velocity profile.

Teaches: prescribed obstacle velocities (``Scene.create(..., fixed_velocity=Schedule(...))``).
100 disks (r = 0.45 +/- 10 %, unit density, no gravity, Coulomb mu = 0.5) sit between two rough
walls of fixed disks (r = 0.5, 1.2 apart), periodic along x (period 12). The top wall first comes
down at speed 1 for 200 steps (from y = 12 to y = 8: area fraction 0.77), then moves along +x at
U = 1 while the bottom wall stays at rest. Momentum goes down through the contacts: the
time-averaged velocity grows across the gap, and the profile settles from a shear band under the
lid to a nearly linear one.

There is no closed form: the script prints the profile ``v_x(y)`` in three time windows, the
slip at each wall and every step's status. Checked numbers (full run, 1000 shear steps, dt =
0.02, apgd with the joint fixed point at tol 1e-6): 100 % of the steps ``converged`` (a step
that did not would be flagged ``max_iter`` and applied as it is, ``on_failure="ignore"``), with
the deepest overlap after a step at 3.4e-7; the lid ends where its schedule puts
it (y = 8; x advanced by ``1000 dt U = 20`` to 3e-13); in the last window v_x rises across the
gap from 0.07-0.08 U in the bottom slab to 0.84-0.91 U in the top one, a straight-line fit
through the seven slabs rising by 0.8-0.9 U (``--quick``: 250 shear steps, every step converged,
the profile still developing: 0.03-0.08 U to 0.68-0.80 U, the fit rising by 0.6-0.7 U). The
trajectory is chaotic: rounding, which differs between CPUs' BLAS kernels, changes the exact
values (the ranges are two machines' runs), and a slab may lag the one below it by a few
hundredths of U. Compressed to 0.80 instead
(``COMPRESS = 210``, lid at 7.8) the layer jams: measured before the wider search, 10 % of the
steps ended ``max_iter`` and overlaps reached 0.36, which the statuses flag.

Run: ``python examples/shear_cell.py [--quick] [--out DIR]`` (about 10 s; quick 6 s).
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import PatchCollection
from matplotlib.patches import Circle

from lubcontact import Coulomb, Grains, Scene, Schedule, Simulation
from lubcontact.bench.tables import format_table

PERIOD, U, V, DT, COMPRESS, TOP0 = 12.0, 1.0, 1.0, 0.02, 200, 12.0


def cell(seed: int = 0) -> Scene:
    """The grains on a staggered lattice between the walls; the lid's velocity schedule."""
    rng = np.random.default_rng(seed)
    ix, iy = np.meshgrid(np.arange(12), np.arange(9))
    centres = np.stack([ix.ravel() + 0.5 + 0.3 * (iy.ravel() % 2), 1.0 + 1.2 * iy.ravel()], 1)[:100]
    grains = Grains.create(centres, 0.45 * (1 + 0.1 * rng.uniform(-1, 1, 100)), densities=1.0,
                           velocities=0.1 * rng.normal(size=(100, 2)))
    x = 1.2 * (np.arange(10) + 0.5)
    walls = np.vstack([np.stack([x, np.zeros(10)], 1), np.stack([x, np.full(10, TOP0)], 1)])
    lid = np.repeat([0.0, 1.0], 10)[:, None]                   # bottom at rest, the lid moves
    schedule = Schedule(times=(0.0, (COMPRESS - 0.5) * DT), values=(lid * [0, -V], lid * [U, 0]))
    return Scene.create(grains, fixed_positions=walls, fixed_radii=0.5, fixed_velocity=schedule,
                        period=PERIOD)


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Compress, shear, print the profiles and statuses, draw ``shear_cell.png``."""
    shear = 250 if quick else 1000
    sim = Simulation(cell(), Coulomb(0.5), DT, solver="apgd", tol=1e-6, tol_fp=1e-5,
                     solver_options={"joint": 5}, on_failure="ignore")
    sim.run(COMPRESS + shear)
    top = sim.scene.fixed_positions[10:]
    positions = np.array(sim.trajectory.positions[COMPRESS + 1:])
    velocities = np.array(sim.trajectory.velocities[COMPRESS + 1:])
    edges = np.linspace(0.5, top[0, 1] - 0.5, 8)
    middle = 0.5 * (edges[1:] + edges[:-1])
    windows = np.array_split(np.arange(shear), 3)
    profiles = []
    for window in windows:
        y, vx = positions[window, :, 1].ravel(), velocities[window, :, 0].ravel()
        slab = np.clip(np.digitize(y, edges) - 1, 0, len(middle) - 1)
        profiles.append(np.bincount(slab, vx, len(middle)) / np.bincount(slab, minlength=len(middle)))
    times = [f"t = {DT * (COMPRESS + w[0]):.0f}-{DT * (COMPRESS + w[-1] + 1):.0f}" for w in windows]
    print(format_table([dict(y=m, **{t: p[k] for t, p in zip(times, profiles)})
                        for k, m in enumerate(middle)], ["y"] + times))
    status, gaps = np.array(sim.trajectory.status), np.array(sim.trajectory.min_gap)
    checks = dict(converged=float(np.mean(status == "converged")), min_gap=gaps.min(),
                  lid_y=top[0, 1], lid_shift_error=abs(top[0, 0] - 0.6 - (shear * DT * U) % PERIOD),
                  bottom_slab=profiles[-1][0] / U, top_slab=profiles[-1][-1] / U,
                  rise=np.polyfit(middle, profiles[-1], 1)[0] * (middle[-1] - middle[0]) / U)
    print(format_table([checks], list(checks)))

    fig, (ax_p, ax_s) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1, 1.6]})
    for t, p in zip(times, profiles):
        ax_p.plot(p / U, middle, "o-", label=t)
    ax_p.plot([0, 1], [0.5, top[0, 1] - 0.5], "k:", label="linear, no slip at the walls")
    ax_p.set(xlabel="mean velocity along x, v_x / U (-)", ylabel="height y (length; d = 0.9)",
             title="Velocity profile across the gap (slab averages)")
    ax_p.legend(fontsize=8)
    scene = sim.scene
    disks = PatchCollection([Circle(p, r) for p, r in zip(scene.grains.positions, scene.grains.radii)],
                            cmap="viridis", edgecolor="0.3", linewidth=0.3)
    disks.set_array(scene.grains.velocities[:, 0] / U)
    disks.set_clim(0, 1)
    ax_s.add_collection(disks)
    ax_s.add_collection(PatchCollection([Circle(p, 0.5) for p in scene.fixed_positions], color="0.4"))
    fig.colorbar(disks, ax=ax_s, fraction=0.03, label="v_x / U (-)")
    ax_s.set(xlim=(0, PERIOD), ylim=(-0.6, top[0, 1] + 0.6), aspect="equal",
             xlabel="x, periodic (length)", ylabel="y (length)",
             title=f"t = {scene.time:.0f}: lid at y = {top[0, 1]:.3g} moving at U = {U:g}")
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "shear_cell.png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="250 shear steps")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
