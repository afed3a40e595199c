"""Glue against its exact solutions: the poster's push-pull and a gluey disk on an incline, and dt.

Teaches: the gluey limit of lubrication (docs/guide/model.md sections 1 and 7). A contact that is
pushed stores the impulse in its glue state gamma and holds a later pull for ``|gamma| / f``.
Units: m = g = 1 and a length unit L, so times are in sqrt(L / g) and impulses in m sqrt(g L).

- push-pull (7.1): a disk (r = 0.5) falls from gap 1, is pushed by -m g until t = 2, pulled by
  +m g after: gamma(2) = -2, it unglues at ``t_u = 2 + 2 = 4`` and flies, ``q = (t - 4)^2 / 2``;
- incline (7.3): a disk (r = 1) on a 30-degree plane, the force reversed at t = 2, the glue
  capped at ``gamma_min = -g cos a`` (one time unit of normal weight): gamma(2) = gamma_min, it
  unsticks at ``t_inv + |gamma_min| / (g cos a) = 3`` and leaves, ``q = g cos a (t - 3)^2 / 2``.

Checked numbers (apgd-as, tol 1e-10, every dt from 0.1 to 1e-3): gamma(2) exact to 1e-13;
ungluing exactly at 4 and 3 (both on the time grid); the free-flight error is the scheme's
discrete parabola, ``g_n dt (t_end - t_u) / 2`` to 1e-12 (5e-4 and 6.5e-4 at dt = 1e-3):
fitted slope 1.00 for both.

Run: ``python examples/push_pull_and_incline.py [--quick] [--out DIR]`` (about 30 s; ``--quick``,
dt >= 1e-2 only: 5 s).
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import GlueyLubrication, Scene, Simulation, scenes
from lubcontact.bench.tables import format_table

ANGLE, T_INV = np.pi / 6, 2.0
GAMMA_MIN = -np.cos(ANGLE)            # the impulse of the normal weight in one time unit
CASES = {  # name: scene, law, end time, gamma at t_inv, ungluing time, normal gravity
    "push-pull": (scenes.push_pull(), GlueyLubrication(), 5.0, -2.0, 4.0, 1.0),
    "incline": (scenes.disk_on_incline(ANGLE, height=0.05, t_inversion=T_INV),
                GlueyLubrication(gamma_min=GAMMA_MIN), 4.5, GAMMA_MIN,
                T_INV - GAMMA_MIN / np.cos(ANGLE), np.cos(ANGLE)),
}


def run(scene: Scene, law: GlueyLubrication, dt: float, t_end: float) -> dict[str, np.ndarray]:
    """Times, gap to the plane and glue state after each step (index 0: the initial state)."""
    sim = Simulation(scene, law, dt, d_max=0.02, solver="apgd-as", tol=1e-10)
    gamma = [0.0]
    sim.run(int(round(t_end / dt)), lambda s, report: gamma.append(report.gamma.min(initial=0.0)))
    times, centres = np.array(sim.trajectory.times), np.array(sim.trajectory.positions)[:, 0]
    normal, radius = scene.planes.normals[0], scene.grains.radii[0]
    return dict(t=times, gap=centres @ normal - radius, gamma=np.array(gamma))


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Run both cases at several dt, print the table, draw ``push_pull_and_incline.png``."""
    steps = [1e-1, 5e-2, 2e-2, 1e-2] + ([] if quick else [5e-3, 2e-3, 1e-3])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    rows, summary, checks = [], [], {}
    for (name, (scene, law, t_end, gamma_inv, t_u, g_n)), ax in zip(CASES.items(), axes):
        errors = []
        for dt in steps:
            r = run(scene, law, dt, t_end)
            unglued = r["t"][(r["gamma"] == 0) & (r["t"] > T_INV)][0]
            flying = r["t"] >= t_u
            errors.append(np.abs(r["gap"][flying] - g_n * (r["t"][flying] - t_u) ** 2 / 2).max())
            rows.append(dict(case=name, dt=dt, gamma_at_2=r["gamma"][int(round(T_INV / dt))],
                             unglue=unglued, exact=t_u, flight_error=errors[-1]))
        slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
        summary.append(dict(case=name, gamma_error=abs(rows[-1]["gamma_at_2"] - gamma_inv),
                            unglue_error=abs(unglued - t_u), slope=slope, flight_error=errors[-1],
                            discrete=g_n * dt * (t_end - t_u) / 2))
        checks |= {f"{name}_{key}": value for key, value in summary[-1].items() if key != "case"}
        ax.plot(r["t"], r["gap"], label=f"simulated, dt = {dt:g}")
        ax.plot(r["t"], np.where(r["t"] > t_u, g_n * (r["t"] - t_u) ** 2 / 2, 0.0), "k--",
                label=f"exact flight after t_u = {t_u:.4g}")
        ax.plot(r["t"], r["gamma"], label="glue state gamma (m sqrt(g L))")
        ax.set(xlabel="time t (sqrt(L / g))", ylabel="gap q (L), glue state gamma (m sqrt(g L))",
               title=f"{name}: glued, then unglued by the pull", ylim=(-2.2, 1.2))
        ax.legend(fontsize=8)
        axes[2].loglog(steps, errors, "o-", label=f"{name}: slope {slope:.2f}")
    print(format_table(rows, ["case", "dt", "gamma_at_2", "unglue", "exact", "flight_error"],
                       floats=".6g"))
    axes[2].loglog(steps, 2 * np.array(steps) * errors[0] / steps[0], "k:", label="slope 1")
    axes[2].set(xlabel="time step dt (sqrt(L / g))", ylabel="max free-flight error (L)",
                title="First-order convergence in dt")
    axes[2].legend()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "push_pull_and_incline.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    print(format_table(summary, list(summary[0]), floats=".3g"))
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="dt >= 1e-2 only")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
