"""Why a solver fails: a 1e6 mass ratio, the condition number it makes, and honest statuses.

Teaches: conditioning sets the speed of gradient methods, and a solver that cannot finish says
so (docs/guide/policies.md). The hard case ``mass_ratio_1e6_sandwich``
(``lubcontact.bench.cases.hard``): a grain of mass 1e6 resting on a unit grain on the floor. The
exact answer is "everything stays at rest". Both contacts carry force; the Delassus matrix on
them, ``W_AA``, has condition ``~4 m_heavy / m_light = 4e6``. A projected gradient contracts by
about ``1 - 1/cond`` per iteration, an accelerated one by ``1 - 1/sqrt(cond)``: pgd would need
some 1e8 iterations, apgd some 1e4.

Two runs of every method at tol 1e-8: with the default caps, then with a tight budget (1000
iterations for the first-order and QP methods, 4 for the interior-point ones). Each status says
what happened: ``converged``, ``max_iter`` (out of iterations: best iterate, flagged), or
``inaccurate`` (the solver's own "almost solved"). An interior point cut short whose answer the
active-set polish takes to tol is ``converged``; the ``raw`` column keeps what Clarabel said
(``user_limit``, ``MaxIterations``, ``optimal_inaccurate``).

Checked numbers (no quick mode: 3 s): cond(W_AA) = 4.0e6 on 2 loaded rows; default caps: pgd
and nsgs ``max_iter`` at 20 000 with velocity error 7e-3 (the grains fall as if there were no
contact), apgd converged in 11 770 iterations, bb in 36, apgd-as in 1 (exact active-set finish),
newton-ac in 2, every converged method within 3e-11 of rest (osqp; 1e-12 for the others); tight
budget: apgd, apgd-jacobi, pgd and nsgs ``max_iter`` with errors near 7e-3; clarabel,
clarabel-direct and clarabel-dual stop after 4 iterations (raw statuses ``user_limit``,
``MaxIterations`` and ``optimal_inaccurate``) and are ``converged`` by their polished answers
(errors 1.3e-13 to 6.7e-13); bb, apgd-as, newton-ac, osqp and scs converge within it.

Run: ``python examples/hard_case.py [--out DIR]``.
"""
import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lubcontact import solve, solver_info
from lubcontact.bench.cases.hard import CASES
from lubcontact.bench.tables import format_table
from lubcontact.problem.metrics import active_condition
from lubcontact.solvers import capable_methods

TOL = 1e-8


def main(quick: bool = False, out: Path = Path("out/gallery")) -> dict[str, float]:
    """Solve the case with every method twice, print statuses, draw ``hard_case.png``."""
    case = CASES["mass_ratio_1e6_sandwich"]
    problem = case.problem
    print(f"{case.name}: {case.hard}\nexpected: {case.expected}")
    reference = solve(problem, "clarabel", tol=1e-10)
    cond, loaded = active_condition(problem, reference.forces)
    print(f"cond(W_AA) = {cond:.3g} on {loaded} loaded rows; masses {problem.mass}")
    exact = case.exact(problem)
    results, rows = {}, []
    for budget in ("default", "tight"):
        for method in capable_methods(problem):
            cap = None if budget == "default" else \
                (4 if solver_info(method).kind == "interior-point" else 1000)
            result = solve(problem, method, tol=TOL, max_iter=cap)
            results[budget, method] = result
            rows.append(dict(budget=budget, method=method, status=result.status,
                             iterations=result.iterations, residual=result.residual,
                             error=np.abs(result.velocities - exact).max(),
                             raw=result.info.get("raw_status", "")))
    print(format_table(rows, ["budget", "method", "status", "iterations", "residual", "error", "raw"]))

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for method in ("pgd", "apgd", "apgd-jacobi", "bb"):
        history = results["default", method].residual_history
        ax.semilogy(np.arange(1, len(history) + 1), history, label=f"{method}: "
                    f"{results['default', method].status}")
    k = np.arange(1, 20001)
    ax.semilogy(k, (1 - 1 / cond) ** k, "k:", label="(1 - 1/cond)^k, pgd's rate")
    ax.semilogy(k, (1 - 1 / np.sqrt(cond)) ** k, "k--", label="(1 - 1/sqrt(cond))^k, apgd's rate")
    ax.axhline(TOL, color="0.6", lw=0.8, label=f"tol = {TOL:g}")
    ax.set(xlabel="iteration k", ylabel="scaled natural-map residual (-)", ylim=(1e-12, 10),
           title=f"Mass ratio 1e6: cond(W_AA) = {cond:.2g}")
    ax.legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "hard_case.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    checks = dict(cond=cond, pgd_status=results["default", "pgd"].status,
                  pgd_error=rows[[r["method"] for r in rows].index("pgd")]["error"],
                  worst_converged_error=max(r["error"] for r in rows if r["status"] == "converged"),
                  tight_statuses=sorted({r["status"] for r in rows if r["budget"] == "tight"}),
                  tight_interior_points=sorted({(r["status"], r["raw"]) for r in rows
                                                if r["budget"] == "tight" and r["raw"]
                                                and r["method"].startswith("clarabel")}))
    print(format_table([checks], list(checks)))
    return checks


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="accepted for uniformity (one step)")
    parser.add_argument("--out", type=Path, default=Path("out/gallery"), help="figure folder")
    args = parser.parse_args()
    main(args.quick, args.out)
