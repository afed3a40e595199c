"""One frictional contact, one step: the primal and dual forms, and a projected gradient on the cone.

Teaches: what a step problem is. A disk (r = 0.5, m = 1) slides at 1 on the floor and falls at
0.5 (mu = 0.3, g = 1, dt = 0.1). Its step has one contact and two force rows (normal n,
tangential t); the script prints the primal form (over velocities) and the dual form (over
forces) as cvxpy writes them, solves the dual by Clarabel and by the five-line projected
gradient ``lam <- P_K(lam - (W lam + b) / L)``, and draws the iterates on the friction cone.

Checked numbers (dt = 0.1, no quick mode: one step): the convex relaxation's force lies on the
cone edge, ``lam_n = -(b_n + mu b_t) / (W_nn + mu^2 W_tt) = 0.09 / 0.0127 = 7.0866``; Clarabel
matches it to 2e-15, the projected gradient to 1e-12 after 60 iterations (rate 2/3 per
iteration, as cond(W) = 3). The exact Coulomb force (fixed point on s) is (6, 1.8) to 1e-6: it
stops the fall (0.6 / dt) and lets the disk slide, ``lam_t = mu lam_n``.

Run: ``python examples/single_contact.py [--out DIR]`` (about 2 s).
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import Coulomb, Grains, Scene, Simulation, StepProblem, solve, solve_coulomb
from lubcontact.bench.tables import format_table
from lubcontact.problem.symbolic import dual_form, primal_form

MU, DT = 0.3, 0.1


def projected_gradient(problem: StepProblem, start: np.ndarray, steps: int = 60) -> np.ndarray:
    """Iterates ``lam <- P_K(lam - (W lam + b) / L)`` from ``start``, shape (steps + 1, 2)."""
    W, b = problem.delassus.toarray(), problem.offset
    step = 1.0 / np.linalg.eigvalsh(W).max()
    lam = problem.cones.project(start)
    iterates = [lam]
    for _ in range(steps):
        lam = problem.cones.project(lam - step * (W @ lam + b))
        iterates.append(lam)
    return np.array(iterates)


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Print both forms, solve, draw ``single_contact.png``; return the checked numbers."""
    grains = Grains.create([[0.0, 0.5]], 0.5, masses=1.0, velocities=[[1.0, -0.5]])
    scene = Scene.create(grains, plane_points=[0, 0], plane_normals=[0, 1], gravity=[0, -1])
    problem = Simulation(scene, Coulomb(MU), DT).next_problem()[2]
    print("PRIMAL (velocities v = (vx, vy, spin)):\n", primal_form(problem).problem, "\n")
    print("DUAL (forces lam = (lam_n, lam_t)):\n", dual_form(problem).problem, "\n")
    W, b = problem.delassus.toarray(), problem.offset
    exact = -(b[0] + MU * b[1]) / (W[0, 0] + MU**2 * W[1, 1])        # on the edge lam_t = mu lam_n
    clarabel = solve(problem, "clarabel", tol=1e-10).forces
    coulomb = solve_coulomb(problem, "clarabel", tol=1e-10).forces
    iterates = projected_gradient(problem, np.zeros(2))
    from_warm = projected_gradient(problem, np.array([11.0, -3.0]))
    rows = [dict(k=k, lam_n=iterates[k, 0], lam_t=iterates[k, 1],
                 distance=np.linalg.norm(iterates[k] - [exact, MU * exact]))
            for k in (0, 1, 2, 4, 8, 16, 32, 60)]
    print(format_table(rows, ["k", "lam_n", "lam_t", "distance"], floats=".4g"))
    checks = dict(exact_lam_n=exact, clarabel_error=abs(clarabel[0] - exact),
                  pgd_error=float(np.linalg.norm(iterates[-1] - [exact, MU * exact])),
                  coulomb_lam_n=float(coulomb[0]), coulomb_lam_t=float(coulomb[1]))
    print(format_table([checks], list(checks), floats=".4g"))

    fig, ax = plt.subplots(figsize=(6, 4.5))
    n = np.linspace(0, 12.0, 2)
    ax.fill_between(n, -MU * n, MU * n, color="0.9", label=f"cone |lam_t| <= {MU} lam_n")
    ax.plot(n, MU * n, "k-", n, -MU * n, "k-", lw=1)
    ax.plot(iterates[:, 0], iterates[:, 1], "o-", ms=3, label="projected gradient from 0")
    ax.plot(from_warm[:, 0], from_warm[:, 1], "s-", ms=3, label="projected gradient from (11, -3)")
    ax.plot(*clarabel, "r*", ms=14, label="Clarabel (convex relaxation)")
    ax.plot(*coulomb, "gD", ms=8, label="exact Coulomb (fixed point on s)")
    ax.set(xlabel="normal force lam_n (m g)", ylabel="tangential force lam_t (m g)",
           title="One sliding contact: dual iterates on the friction cone")
    ax.legend(loc="upper left", fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "single_contact.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="accepted for uniformity (one step)")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
