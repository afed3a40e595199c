"""Work against precision: every registered solver on one step of a 60-grain pile, tol 1e-2 to 1e-10.

Teaches: a stopping tolerance is not an accuracy, and speed means nothing without the error
next to it (docs/guide/choosing-a-solver.md). A pile of 60 polydisperse disks settles
(``scenes.settling_pile(60)``, frictionless, 100 steps of dt = 0.05); the next step is then
solved frictionless (``Inelastic``) and with friction (``Coulomb(0.3)``, one convex solve: the
relaxation, whose velocities are unique) by every method that accepts it, at each tolerance.
The error is ``|v - v_ref|_M / |U|_M`` against Clarabel at tol 1e-10 (polished); times are
the best of 3 solves (1 with ``--quick``) after one untimed warm-up per method (numba
compilation is never timed).

Checked numbers (full run, 2 cores; times vary by 2x between runs): frictionless, the gradient
methods and osqp reach 2e-14 or better at every tolerance (a converged result on a frictionless
problem ends with an exact active-set solve), the Clarabel forms 1e-15 except ``clarabel-direct``
at tol 1e-4 (4e-4, still ``converged``), scs follows its tolerance (2e-11 at 1e-10, ``inaccurate``
at 1e-2). With friction the gradient methods follow their tolerance (apgd: 3e-5 at tol 1e-6,
4e-9 at 1e-10), ``pgd`` stops at its 20 000-iteration cap from tol 1e-6 (``max_iter``, error
3e-4), and tol 1e-2 gives ``inaccurate`` for every method.

Run: ``python examples/solver_work_precision.py [--quick] [--out DIR]`` (about 30 s; quick 8 s).
"""
import argparse
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import Coulomb, Inelastic, Simulation, SolveResult, StepProblem, scenes, solve
from lubcontact.bench.tables import format_table
from lubcontact.problem.metrics import velocity_error
from lubcontact.solvers import capable_methods


def timed(problem: StepProblem, method: str, tol: float, repeats: int) -> tuple[SolveResult, float]:
    """The result of ``solve`` and its best wall time (s) over ``repeats`` solves."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        result = solve(problem, method, tol=tol)
        best = min(best, time.perf_counter() - start)
    return result, best


def sweep(problem: StepProblem, tolerances: list[float], repeats: int) -> list[dict]:
    """One row per method and tolerance: status, iterations, time (ms), velocity error."""
    reference = solve(problem, "clarabel", tol=1e-10).velocities
    rows = []
    for method in capable_methods(problem):
        solve(problem, method, tol=1e-6)                                # warm-up, untimed
        for tol in tolerances:
            result, seconds = timed(problem, method, tol, repeats)
            rows.append(dict(method=method, tol=tol, status=result.status,
                             iterations=result.iterations, ms=1e3 * seconds,
                             error=velocity_error(problem, result.velocities, reference)))
    return rows


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Settle the pile, sweep both laws, print the tables, draw ``solver_work_precision.png``."""
    tolerances, repeats = ([1e-2, 1e-5, 1e-8], 1) if quick else ([1e-2, 1e-4, 1e-6, 1e-8, 1e-10], 3)
    pile = Simulation(scenes.settling_pile(60, seed=1), Inelastic(), dt=0.05, solver="apgd-as")
    pile.run(100)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
    checks = {}
    laws = [("frictionless", Inelastic(), "Inelastic"), ("friction", Coulomb(0.3), "Coulomb(0.3), one solve")]
    for ax, (name, law, label) in zip(axes, laws):
        problem = Simulation(pile.scene, law, dt=0.05).next_problem()[2]
        rows = sweep(problem, tolerances, repeats)
        print(f"\n{name}: {problem.n_contacts} contacts, {problem.n_rows} force rows")
        print(format_table(rows, ["method", "tol", "status", "iterations", "ms", "error"]))
        for k, method in enumerate(dict.fromkeys(row["method"] for row in rows)):
            mine = [row for row in rows if row["method"] == method]
            ms, error = np.array([[r["ms"], max(r["error"], 1e-16)] for r in mine]).T
            line, = ax.loglog(ms, error, "-", marker="os^v<>Dph*"[k % 10], label=method)
            failed = [r["status"] != "converged" for r in mine]
            ax.loglog(ms[failed], error[failed], "x", color="k", ms=9)
        ax.loglog([], [], "kx", label="status not 'converged'")
        ax.set(xlabel="wall time of one solve (ms)", title=f"{label}: tol "
               f"{tolerances[0]:g} to {tolerances[-1]:g} along each line",
               ylabel="velocity error |v - v_ref|_M / |U|_M (-)")
        ax.legend(fontsize=7, ncol=2)
        converged = [row for row in rows if row["status"] == "converged"]
        checks[f"{name}_tightest_error"] = max(row["error"] for row in converged
                                               if row["tol"] == tolerances[-1])
        checks[f"{name}_worst_converged_error"] = max(row["error"] for row in converged)
        checks[f"{name}_not_converged"] = len(rows) - len(converged)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "solver_work_precision.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    print(format_table([checks], list(checks)))
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3 tolerances, 1 timed solve")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
