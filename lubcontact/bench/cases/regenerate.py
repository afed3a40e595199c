"""Regenerate ``lubcontact/bench/cases/data/*.npz``: run ``python -m lubcontact.bench.cases.regenerate``.

Each case's problem is rebuilt from its scene and solved with Clarabel on the
primal form (tol 1e-10, active-set polishing); the script refuses to write a
solution whose status is not ``converged`` or whose primal and dual
velocities differ by more than 1e-9 (relative).
"""
from __future__ import annotations

import sys

import numpy as np

from lubcontact import solve
from lubcontact.bench.cases.reference import CASES, DATA


def regenerate(names: list[str]) -> None:
    DATA.mkdir(parents=True, exist_ok=True)
    for name in names:
        problem = CASES[name].problem()
        primal = solve(problem, "clarabel", tol=1e-10)
        dual = solve(problem, "clarabel-dual", tol=1e-10)
        scale = max(np.linalg.norm(primal.velocities), 1e-300)
        agreement = np.linalg.norm(primal.velocities - dual.velocities) / scale
        if primal.status != "converged" or agreement > 1e-9:
            raise SystemExit(f"{name}: status {primal.status}, primal/dual agreement {agreement:.2e}")
        np.savez_compressed(DATA / f"{name}.npz", forces=primal.forces, velocities=primal.velocities,
                            **problem.to_arrays())
        print(f"{name:<20} contacts {problem.n_contacts:>4}  primal/dual {agreement:.1e}  "
              f"residual {primal.residual:.1e}")


if __name__ == "__main__":
    regenerate(sys.argv[1:] or list(CASES))
