"""Regenerate ``reference/data/*.npz``: run ``python -m reference.regenerate``.

Each case's problem is rebuilt from its scene and solved with Clarabel on the
dual form (tol 1e-10, active-set polishing); the script refuses to write a
solution whose status is not ``converged`` or whose primal and dual
velocities differ by more than 1e-9 (relative).
"""
from __future__ import annotations

import sys

import numpy as np

from lubcontact import solve
from reference.cases import CASES, DATA


def regenerate(names: list[str]) -> None:
    DATA.mkdir(parents=True, exist_ok=True)
    for name in names:
        problem = CASES[name].problem()
        dual = solve(problem, "clarabel", tol=1e-10)
        primal = solve(problem, "clarabel-primal", tol=1e-10)
        scale = max(np.linalg.norm(dual.velocities), 1e-300)
        agreement = np.linalg.norm(primal.velocities - dual.velocities) / scale
        if dual.status != "converged" or agreement > 1e-9:
            raise SystemExit(f"{name}: status {dual.status}, primal/dual agreement {agreement:.2e}")
        np.savez_compressed(DATA / f"{name}.npz", forces=dual.forces, velocities=dual.velocities,
                            **problem.to_arrays())
        print(f"{name:<20} contacts {problem.n_contacts:>4}  primal/dual {agreement:.1e}  "
              f"residual {dual.residual:.1e}")


if __name__ == "__main__":
    regenerate(sys.argv[1:] or list(CASES))
