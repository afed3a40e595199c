"""Coulomb friction on an incline: rolling below tan(a) = 3 mu, sliding above; and dilatancy.

Teaches: exact Coulomb friction (docs/guide/model.md sections 5 and 7.3-7.4). A disk (r = 1,
m = g = 1, mu = 0.3) released 0.05 above a plane tilted by a rolls without slip when
``tan a <= 3 mu`` (a <= 42 degrees): ``x = x_imp + 2/3 v_imp t2 + g sin a t2^2 / 3``; above, it
slides, ``x = x_imp + (v_t + mu v_n) t2 + g (sin a - mu cos a) t2^2 / 2``, and spins at the
fraction ``min(1, 2 mu / (tan a - mu))`` of the rolling spin at long times. The convex relaxation
(``Simulation(..., fixed_point=False)``, one cone solve per step) lifts a sliding disk by
``mu dt |u_T|`` in a step: on a horizontal plane, launched at 2 without spin, it takes off; the
fixed point on s keeps it on the plane.

Checked numbers (dt = 0.01, apgd at tol 1e-10 and tol_fp 1e-10): downhill position against the
exact one after impact to 3.3e-3 relative over 8 angles from 20 to 70 degrees (``dt / t``: the
scheme's first-order error); spin fraction at t = 3 against the exact one to 7e-15 (42 degrees,
just above the threshold at 41.99, already slides); first lift of the relaxation equal to
``mu dt |u_T|`` to 6e-13, after which the disk flies to 0.113 (``(mu |u_T|)^2 / 2 g = 0.111``);
fixed point: gap within 7e-13 and speed ``2 - mu g t`` to 1.4e-11. ``--quick`` (5 angles,
t = 2): the same, position to 5e-3.

Run: ``python examples/coulomb_incline.py [--quick] [--out DIR]`` (about 15 s; quick 6 s).
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import Coulomb, Grains, Scene, Simulation, scenes
from lubcontact.bench.tables import format_table

MU, DT, HEIGHT, G = 0.3, 0.01, 0.05, 1.0


def exact(angle: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Downhill position and spin fraction ``-omega r / v_t`` (r = 1), valid after the impact."""
    sin, cos = np.sin(angle), np.cos(angle)
    t_imp = np.sqrt(2 * HEIGHT / (G * cos))
    v_t, v_n, x_imp = G * sin * t_imp, -G * cos * t_imp, G * sin * t_imp**2 / 2
    t2 = np.maximum(t - t_imp, 0.0)
    if np.tan(angle) <= 3 * MU:
        return x_imp + 2 / 3 * v_t * t2 + G * sin * t2**2 / 3, np.ones_like(t)
    along = v_t + MU * v_n + G * (sin - MU * cos) * t2
    spin = 2 * MU * v_n - 2 * MU * G * cos * t2
    return x_imp + (v_t + MU * v_n) * t2 + G * (sin - MU * cos) * t2**2 / 2, -spin / along


def incline(angle: float, t_end: float) -> dict[str, np.ndarray]:
    """Time, downhill position and spin fraction of the disk released on the incline."""
    sim = Simulation(scenes.disk_on_incline(angle, height=HEIGHT), Coulomb(MU), DT,
                     solver="apgd", tol=1e-10, tol_fp=1e-10)
    record = sim.run(int(round(t_end / DT))).arrays()
    downhill = np.array([np.cos(angle), -np.sin(angle)])
    along = record["velocities"][:, 0] @ downhill
    fraction = -record["spins"][:, 0, 0] / np.where(along > 0, along, 1.0)
    return dict(t=record["times"], x=(record["positions"][:, 0] - record["positions"][0, 0]) @ downhill,
                fraction=fraction)


def sliding_disk(fixed_point: bool) -> dict[str, np.ndarray]:
    """Disk (r = 0.5) launched at 2 on a flat plane: times, gap, speed, the first lift's distance
    to ``mu dt |u_T|`` and the take-off speed it gives (zero with the fixed point)."""
    grains = Grains.create([[0.0, 0.5]], 0.5, masses=1.0, velocities=[[2.0, 0.0]])
    scene = Scene.create(grains, plane_points=[0, 0], plane_normals=[0, 1], gravity=[0, -G])
    sim = Simulation(scene, Coulomb(MU), DT, solver="apgd", tol=1e-10, tol_fp=1e-10,
                     fixed_point=fixed_point)
    first = sim.step()
    slip = DT * abs(first.problem.jacobian[1] @ first.result.velocities)[0]      # dt |u_T|
    record = sim.run(int(round(1.0 / DT)) - 1).arrays()
    return dict(t=record["times"], gap=record["positions"][:, 0, 1] - 0.5,
                speed=record["velocities"][:, 0, 0], lift_error=abs(first.gaps_after[0] - MU * slip),
                takeoff=first.gaps_after[0] / DT)


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Sweep the angle, compare with the exact motion, draw ``coulomb_incline.png``."""
    degrees, t_end = ([25, 40, 45, 55, 70], 2.0) if quick else ([20, 30, 38, 42, 45, 50, 60, 70], 3.0)
    fig, (ax_x, ax_f, ax_d) = plt.subplots(1, 3, figsize=(15, 4.2))
    rows = []
    for deg in degrees:
        r = incline(np.radians(deg), t_end)
        x, fraction = exact(np.radians(deg), r["t"])
        after = r["t"] > np.sqrt(2 * HEIGHT / (G * np.cos(np.radians(deg)))) + 2 * DT
        rows.append(dict(angle=deg, regime="rolls" if np.tan(np.radians(deg)) <= 3 * MU else "slides",
                         x_end=r["x"][-1], x_error=np.max(np.abs(r["x"] - x)[after]) / x[-1],
                         fraction=r["fraction"][-1], fraction_error=abs(r["fraction"][-1] - fraction[-1])))
        line, = ax_x.plot(r["t"], r["x"], label=f"{deg} deg, {rows[-1]['regime']}")
        ax_x.plot(r["t"][after], x[after], "k--", lw=0.8)
        ax_f.plot(deg, r["fraction"][-1], "o", color=line.get_color())
    print(format_table(rows, ["angle", "regime", "x_end", "x_error", "fraction", "fraction_error"]))
    sweep = np.radians(np.linspace(15, 75, 200))
    ax_f.plot(np.degrees(sweep), [exact(a, np.array([t_end]))[1][0] for a in sweep], "k--",
              label=f"exact at t = {t_end:g}")
    ax_f.axvline(np.degrees(np.arctan(3 * MU)), color="0.5", ls=":", label="tan a = 3 mu")
    ax_x.plot([], [], "k--", lw=0.8, label="exact")
    ax_x.set(xlabel="time t (sqrt(L / g))", ylabel="downhill distance (L)",
             title=f"Disk on an incline, mu = {MU}")
    ax_f.set(xlabel="incline angle a (degrees)", ylabel="spin / rolling spin, -omega r / v_t (-)",
             title="Rolling below the threshold, sliding above")
    relaxed, exact_fp = sliding_disk(False), sliding_disk(True)
    ax_d.plot(relaxed["t"], relaxed["gap"], label="convex relaxation (fixed_point=False)")
    ax_d.plot(exact_fp["t"], exact_fp["gap"], label="fixed point on s (exact Coulomb)")
    ax_d.set(xlabel="time t (sqrt(L / g))", ylabel="gap to the plane (L)",
             title="Dilatancy: a disk sliding at 2 on a flat plane")
    for ax in (ax_x, ax_f, ax_d):
        ax.legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "coulomb_incline.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    checks = dict(x_error=max(row["x_error"] for row in rows),
                  fraction_error=max(row["fraction_error"] for row in rows),
                  first_lift_error=relaxed["lift_error"], relaxed_apex=relaxed["gap"].max(),
                  exact_apex=relaxed["takeoff"] ** 2 / (2 * G),
                  fixed_point_gap=np.abs(exact_fp["gap"]).max(),
                  fixed_point_speed_error=np.abs(exact_fp["speed"] - (2.0 - MU * G * exact_fp["t"])).max())
    print(format_table([checks], list(checks)))
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="5 angles, t = 2")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
