"""Reference cases: step problems taken from the built-in scenes, with tight solutions.

Each case is a scene, a law and a number of steps: the problem of the step
after those steps is the case. ``lubcontact/bench/cases/data/<name>.npz`` stores the
problem's arrays and its Clarabel solution (primal form, tol 1e-10, polished on
its active set), produced by ``python -m lubcontact.bench.cases.regenerate``. Tests check
that the code still builds the same problems and that every solver reproduces
the stored velocities.

Analytic results (exact solutions of docs/guide/model.md section 7) live in ``ANALYTIC``.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lubcontact import GlueyLubrication, Inelastic, Law, Scene, Simulation, StepProblem, scenes

DATA = Path(__file__).resolve().parent / "data"


@dataclass(frozen=True)
class Case:
    """A named step problem: ``steps`` steps of ``scene()`` with ``law()``, then one more."""

    name: str
    scene: Callable[[], Scene]
    law: Callable[[], Law]
    dt: float
    steps: int
    description: str
    d_max: float | None = None

    def problem(self) -> StepProblem:
        sim = Simulation(self.scene(), self.law(), self.dt, d_max=self.d_max)
        sim.run(self.steps)
        return sim.step().problem


CASES = {case.name: case for case in [
    Case("push_pull_impact", scenes.push_pull, GlueyLubrication, 1e-2, 140,
         "the step where the grain hits the plane (unglued, one-sided)", d_max=0.05),
    Case("push_pull_pulled", scenes.push_pull, GlueyLubrication, 1e-2, 250,
         "glued contact under a pull: bilateral, negative force", d_max=0.05),
    Case("incline_resting", lambda: scenes.disk_on_incline(np.pi / 4, height=0.0),
         Inelastic, 1e-2, 10, "disk sliding on a frictionless 45 degree incline"),
    Case("two_grains_glued", lambda: scenes.two_grains(push_time=1.0), GlueyLubrication, 1e-2, 150,
         "two glued grains being pulled apart"),
    Case("pile200_inelastic", lambda: scenes.settling_pile(200, seed=3), Inelastic, 0.05, 80,
         "200-disk pile settling on a floor between walls, dry"),
    Case("pile200_gluey", lambda: scenes.settling_pile(200, seed=3), GlueyLubrication, 0.05, 80,
         "the same pile with gluey lubrication (most contacts glued)"),
]}

ANALYTIC = {
    "push_pull": {"gamma_at_inversion": -2.0, "unglue_time": 4.0,
                  "unglue_time_gamma_min_-1": 3.0},
    "incline_frictionless": "x_t(t) = g sin(alpha) t^2 / 2, v_n = 0 after impact",
    "incline_gluey": "unstick at t_inv + |max(gamma_min, -g t_inv cos alpha)| / (g cos alpha)",
    "two_grains": "glue time = stored push impulse / pull force",
}


def load(name: str) -> tuple[StepProblem, dict[str, np.ndarray]]:
    """The stored problem of case ``name`` and its stored solution (forces, velocities)."""
    with np.load(DATA / f"{name}.npz") as data:
        arrays = dict(data)
    solution = {key: arrays.pop(key) for key in ("forces", "velocities")}
    return StepProblem.from_arrays(arrays), solution
