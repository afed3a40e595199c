"""Gluey + friction: lubricated glide, friction once gamma reaches gamma_min, frictionless pull.

Teaches: the ``GlueyCoulomb`` law (docs/guide/model.md sections 1, 4 and 7.3). A disk (r = 1,
m = g = 1) lands on a 45-degree incline (mu = 0.5, gamma_min = -1.4); its weight is reversed at
t_inv = 5. The contact goes through four regimes:

1. glued and lubricated (cone ``FREE``): it glides without friction while
   ``gamma = -g cos a t`` is above gamma_min;
2. frictional (``UNION``, pushed piece) from ``t_f = -gamma_min / (g cos a) = 1.980``: the
   asperities touch and it slides with friction ``mu g cos a`` (rolling would need
   ``tan a <= 3 mu`` and time);
3. pulled from t_inv: the glue holds the disk on the plane without friction (``UNION``'s pulled
   piece, then ``FREE`` as gamma rises at ``g cos a`` above gamma_min);
4. unglued at ``t_u = t_inv - gamma_min / (g cos a) = 6.980``: it leaves the plane.

Checked numbers (dt = 0.01, apgd at tol 1e-10; ``--quick``: dt = 0.02, the same): the first
frictional step starts at 1.98, the grid point after t_f (the state is read at the start of a
step); the disk unglues at the step starting at 6.98; downhill velocity, spin and normal velocity
match the closed form of section 7.3 to 1.4e-5, 3.3e-5 and 1.9e-4 relative: the switches fall
at 1.98 and 6.98 instead of 1.9799 and 6.9799, the rest of the motion is exact on the grid.

Run: ``python examples/gluey_friction.py [--quick] [--out DIR]`` (about 6 s; quick 4 s).
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import ConeKind, GlueyCoulomb, Simulation, scenes
from lubcontact.bench.tables import format_table

ANGLE, MU, GAMMA_MIN, T_INV, T_END, G = np.pi / 4, 0.5, -1.4, 5.0, 7.5, 1.0
SIN, COS = np.sin(ANGLE), np.cos(ANGLE)
T_F, T_U = -GAMMA_MIN / (G * COS), T_INV - GAMMA_MIN / (G * COS)


def closed_form(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Downhill velocity, spin and normal velocity of section 7.3 (unit mass, r = 1)."""
    tau = np.clip(t, T_F, T_INV) - T_F
    along = G * SIN * np.minimum(t, T_INV) - MU * G * COS * tau - G * SIN * np.maximum(t - T_INV, 0)
    return along, -2 * MU * G * COS * tau, G * COS * np.maximum(t - T_U, 0.0)


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Run the disk through the four regimes, check them, draw ``gluey_friction.png``."""
    dt = 0.02 if quick else 0.01
    sim = Simulation(scenes.disk_on_incline(ANGLE, height=0.05, t_inversion=T_INV),
                     GlueyCoulomb(MU, gamma_min=GAMMA_MIN), dt, d_max=0.05, solver="apgd", tol=1e-10)
    steps = []
    sim.run(int(round(T_END / dt)), lambda s, report: steps.append(dict(
        start=s.scene.time - dt, gamma=report.gamma.min(initial=0.0),
        force=report.result.forces[0] if report.contacts.count else 0.0,
        kind=ConeKind(report.problem.cones.kinds[0]).name if report.contacts.count else "none")))
    record = sim.trajectory.arrays()
    t = record["times"]
    downhill, normal = np.array([COS, -SIN]), np.array([SIN, COS])
    along, off = record["velocities"][:, 0] @ downhill, record["velocities"][:, 0] @ normal
    exact = closed_form(t)
    after = t > 0.5                                               # past the impact at t = 0.38
    start = np.array([s["start"] for s in steps])
    kinds = np.array([s["kind"] for s in steps])
    frictional = start[kinds == "UNION"][0]
    unglued = start[(start > T_INV) & (kinds == "NONNEG")][0]
    errors = [np.abs(v - e)[after].max() / np.abs(e).max()
              for v, e in zip((along, record["spins"][:, 0, 0], off), exact)]
    checks = dict(t_f=T_F, first_union=frictional, t_u=T_U, unglued=unglued,
                  velocity_error=errors[0], spin_error=errors[1], normal_error=errors[2])
    print(format_table([s for s in steps if s["kind"] != steps[steps.index(s) - 1]["kind"]],
                       ["start", "kind", "gamma", "force"], floats=".4g"))
    print(format_table([checks], list(checks), floats=".4g"))

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    end = [s["start"] + dt for s in steps]
    axes[0].plot(end, [s["gamma"] for s in steps], label="gamma")
    axes[0].axhline(GAMMA_MIN, color="k", ls=":", label="gamma_min")
    axes[1].plot(end, [s["force"] for s in steps], label="normal force lam_n")
    axes[2].plot(t, along, label="downhill velocity v_t")
    axes[2].plot(t, off, label="normal velocity v_n")
    axes[2].plot([], [], "k--", lw=0.8, label="exact (section 7.3)")
    axes[2].plot(t, -record["spins"][:, 0, 0], label="spin x radius, -omega r")
    for e in exact:
        axes[2].plot(t[after], np.abs(e[after]), "k--", lw=0.8)
    regimes = [(0.38, T_F, "glued, lubricated"), (T_F, T_INV, "frictional"),
               (T_INV, T_U, "pulled, frictionless"), (T_U, T_END, "unglued")]
    for ax in axes:
        for (a, b, name), colour in zip(regimes, ("C0", "C1", "C2", "C3")):
            ax.axvspan(a, b, color=colour, alpha=0.12, label=name if ax is axes[0] else None)
        ax.legend(fontsize=8, loc="lower left" if ax is axes[0] else "best")
    axes[0].set(ylabel="glue state (m sqrt(g L))", title="A gluey + frictional disk on a 45-degree incline")
    axes[1].set(ylabel="normal force (m g)", ylim=(-1.2, 1.2))
    axes[1].annotate("impact (off scale)", (0.4, 1.1), fontsize=8, va="top")
    axes[2].set(ylabel="velocity (sqrt(g L))", xlabel="time t (sqrt(L / g))")
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "gluey_friction.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="dt = 0.02")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
