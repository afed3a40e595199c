"""Add your own solver: a projected gradient in a dozen lines, registered, then verified.

Teaches: the solver contract (a function of the normalised ``ConicProblem``
returning a ``MethodOutput``), ``register`` with capabilities, and how one
registered name runs everywhere: ``Simulation``, ``lubcontact.solve`` against
the Clarabel reference, ``compare`` and ``check-hard``.

Run: ``python examples/user_solver.py`` (about 10 s).
"""
import numpy as np

from lubcontact.solvers import CONVERGED, CONVEX_CONES, MAX_ITER, MethodOutput, register


@register("my-pgd", kind="first-order", cones=CONVEX_CONES)      # every force set but UNION
def my_pgd(problem, *, tol, max_iter=200_000, warm_start=None):
    """Projected gradient on the dual: ``lam <- P_K(lam - (W lam + b) / L)``."""
    W, b, project = problem.delassus, problem.offset, problem.cones.project
    step = 1.0 / abs(W).sum(axis=1).max()            # 1 / L, L >= the largest eigenvalue of W
    lam = project(np.zeros(problem.n_rows) if warm_start is None else warm_start)
    for k in range(1, max_iter + 1):
        lam = project(lam - step * (W @ lam + b))
        if problem.natural_residual(lam) <= tol * np.sqrt(problem.n_rows):
            return MethodOutput(lam, CONVERGED, k)
    return MethodOutput(lam, MAX_ITER, max_iter)


def main() -> None:
    from lubcontact import Inelastic, Simulation, scenes, solve
    from lubcontact.problem.metrics import velocity_error

    sim = Simulation(scenes.settling_pile(30, seed=1), Inelastic(), dt=0.05, solver="my-pgd",
                     tol=1e-10)
    for _ in range(20):
        report = sim.step()
    reference = solve(report.problem, "clarabel", tol=1e-10)
    ours = solve(report.problem, "my-pgd", tol=1e-10)
    print(f"my-pgd: {ours.status} in {ours.iterations} iterations, velocity error against "
          f"Clarabel {velocity_error(report.problem, ours.velocities, reference.velocities):.1e}")


if __name__ == "__main__":
    main()
