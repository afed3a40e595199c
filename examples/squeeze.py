"""Two plates and a glued grain: a rigid grain cannot be squeezed, and two glues cannot part.

Teaches: moving plates (``Scene.create(..., plane_velocity=Schedule(...))``), what a glued
contact demands, and how a problem without solution is reported. A disk (r = 0.5, m = g = 1)
rests on the floor, glued by its weight (``GlueyLubrication(gamma_min=-1)``: gamma = -g t, at
the cap -1 from t = 1). A top plate comes down at V = 0.5 from 0.5 above the disk, reaches it
exactly at t = 1 (dt = 1/64, every number exact in binary) and leaves at +V.

1. At the arrival step both contacts hold the disk at rest and the forces are not unique: the
   floor pushes ``m g + lam_top`` for any ``lam_top >= 0``. The first-order methods return
   ``lam_top = 0``: the top film stores nothing and the plate leaves freely; the grain stays glued
   on the floor. The interior-point methods return the analytic centre, ``lam_top = 1/sqrt(2)``:
   the top film is glued (gamma = -dt/sqrt(2)) and when the plates part the grain would have to
   follow both: the step is infeasible, every method says so by its status, and the simulation
   raises ``SolverError`` leaving the scene at t = 1.
2. A plate that keeps coming down squeezes a rigid grain against the floor: also infeasible,
   reported the same way.

Checked numbers (no quick mode, about 5 s): floor gamma = -1 exactly at t = 1; grain height 0.5
exactly (apgd-as: the whole run to t = 2; clarabel: until it stops at t = 1); top force at the
arrival step 0 (apgd-as) and 0.70711 = 1/sqrt(2) (clarabel), hence top gamma 0 and
-0.011049 = -dt/sqrt(2); on the parting and the squeeze steps no method converges: ``failed``
(the Clarabel forms, osqp, scs: infeasibility detected) or ``max_iter`` (the gradient methods,
residual stuck at 32).

Run: ``python examples/squeeze.py [--out DIR]``.
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import GlueyLubrication, Grains, Scene, Schedule, Simulation, SolverError, StepReport, solve
from lubcontact.bench.tables import format_table
from lubcontact.solvers import capable_methods

DT, V, LAW = 1 / 64, 0.5, GlueyLubrication(gamma_min=-1.0)


def plates(leave: bool) -> Scene:
    """Disk on the floor (body 1), top plate (body 2) 0.5 above it coming down, then leaving."""
    velocity = [np.array([[0.0, 0.0], [0.0, -V]]), np.array([[0.0, 0.0], [0.0, V]])]
    schedule = Schedule(times=(0.0, 1.0 - DT / 2), values=velocity if leave else velocity[:1] * 2)
    return Scene.create(Grains.create([[0.0, 0.5]], 0.5, masses=1.0), gravity=[0, -1],
                        plane_points=[[0, 0], [0, 1.5]], plane_normals=[[0, 1], [0, -1]],
                        plane_velocity=schedule)


def run(scene: Scene, solver: str) -> tuple[dict[str, np.ndarray], Simulation, str]:
    """Run to t = 2 or to the first failure: per step time, grain height, plate, gammas, forces."""
    sim = Simulation(scene, LAW, DT, d_max=0.05, solver=solver)
    rows = []

    def record(s: Simulation, report: StepReport) -> None:
        top, floor = report.contacts.body_a == 2, report.contacts.body_a == 1
        rows.append((s.scene.time, s.scene.grains.positions[0, 1], s.scene.planes.points[1, 1],
                     report.gamma[floor].sum(), report.gamma[top].sum(),
                     report.result.forces[top].sum()))
    try:
        sim.run(128, record)
        outcome = "ran to t = 2"
    except SolverError as error:
        outcome = f"stopped at t = {sim.scene.time:g}: {error}"
    names = ["t", "y", "plate", "gamma_floor", "gamma_top", "force_top"]
    return dict(zip(names, np.array(rows).T)), sim, outcome


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Run the plates with two solvers, list every status on the failing steps, draw a figure."""
    fig, (ax_y, ax_g) = plt.subplots(1, 2, figsize=(12, 4.2))
    checks, rows, summary = {}, [], []
    for solver in ("apgd-as", "clarabel"):
        r, sim, outcome = run(plates(leave=True), solver)
        arrival = int(np.argmin(np.abs(r["t"] - 1.0)))
        print(f"{solver}: {outcome}")
        summary.append(dict(solver=solver, top_force=r["force_top"][arrival],
                            top_gamma=r["gamma_top"][arrival], floor_gamma=r["gamma_floor"][arrival],
                            height_error=np.abs(r["y"] - 0.5).max(), last_t=r["t"][-1]))
        checks |= {f"{solver}_{key}": value for key, value in summary[-1].items() if key != "solver"}
        ax_y.plot(r["t"], r["plate"] - r["y"] - 0.5, label=f"{solver}: gap to the top plate")
        ax_g.plot(r["t"], r["gamma_floor"], label=f"{solver}: floor film")
        ax_g.plot(r["t"], r["gamma_top"], "--", label=f"{solver}: top film")
        if solver == "clarabel":                       # the parting step it could not solve
            parting = sim.next_problem()[2]
            ax_g.annotate(f"clarabel: top film glued, gamma = {r['gamma_top'][arrival]:.3f};\n"
                          "parting is infeasible: status failed", (1.0, r["gamma_top"][arrival]),
                          (1.05, -0.35), arrowprops=dict(arrowstyle="->"), fontsize=8)
            ax_y.plot(1.0, 0.0, "rx", ms=10, label="clarabel stops: SolverError (failed)")
    squeeze = run(plates(leave=False), "apgd-as")
    print(f"squeeze (apgd-as): {squeeze[2]}")
    for name, problem in (("parting, both glued", parting), ("squeeze", squeeze[1].next_problem()[2])):
        for method in capable_methods(problem):
            result = solve(problem, method, tol=1e-9)
            rows.append(dict(step=name, method=method, status=result.status,
                             iterations=result.iterations, residual=result.residual))
    print(format_table(rows, ["step", "method", "status", "iterations", "residual"]))
    print(format_table(summary, list(summary[0]), floats=".5g"))
    checks["converged_on_infeasible"] = sum(row["status"] == "converged" for row in rows)
    ax_y.set(xlabel="time t (sqrt(L / g))", ylabel="gap between disk and top plate (L)",
             title="The top plate comes down, touches at t = 1, leaves")
    ax_g.set(xlabel="time t (sqrt(L / g))", ylabel="glue state gamma (m sqrt(g L))",
             title="Glue: the floor film, and the top film glued or not")
    ax_g.set_ylim(-1.1, 0.1)
    for ax in (ax_y, ax_g):
        ax.legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "squeeze.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="accepted for uniformity (3 s)")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
