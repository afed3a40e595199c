"""What ``lubcontact bench friction`` solves: the external problem files and the pile steps.

See :mod:`lubcontact.bench.friction` for the benchmark itself.
"""
from __future__ import annotations

import fnmatch
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..problem.step import StepProblem
from .problem_sets import FRICTION, PILE_DT, PILE_STEPS

SETTLING_SEED, DEPOSITED_SEED = 3, 1          # the seeds of the comparison sets


@dataclass(frozen=True)
class ExternalProblem:
    """An external problem file.

    Attributes
    ----------
    name : str
        Short label (the table's ``problem`` column).
    path : str
        Relative to the benchmark-data folder.
    quick : bool
        Part of the ``--quick`` subset (seconds in all).
    """

    name: str
    path: str
    quick: bool


EXTERNAL = (
    ExternalProblem("fc2d-00667", "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat", True),
    ExternalProblem("fc2d-02020", "siconos-fc2d/fc2d_granularflowonwall_02020_00213.dat", False),
    ExternalProblem("fc2d-07002", "siconos-fc2d/fc2d_granularflowonwall_07002_00801.dat", False),
    ExternalProblem("local_problem_test", "fclib-local/local_problem_test.hdf5", True),
    ExternalProblem("LMGC_PerioBox", "fclib-local/LMGC_100_PR_PerioBox-i00361-60-03000.hdf5", True),
    ExternalProblem("Capsules", "fclib-local/Capsules-i125-1213.hdf5", False),
    ExternalProblem("Box_Stacks", "fclib-local/Box_Stacks-i0122-82-5.hdf5", True),
)


def select_problems(patterns: list[str] | None, quick: bool) -> list[ExternalProblem]:
    """The problems whose name or file name matches one of ``patterns`` (globs; all when None)."""
    chosen = [p for p in EXTERNAL if p.quick or not quick]
    if not patterns:
        return chosen
    return [p for p in chosen
            if any(fnmatch.fnmatch(p.name, pat) or fnmatch.fnmatch(Path(p.path).name, pat)
                   for pat in patterns)]



@dataclass
class PileStep:
    """A frictional step problem of a pile and the warm start a simulation would give it.

    Attributes
    ----------
    label : str
        ``settling`` or ``deposited``.
    n_grains : int
    problem : StepProblem
        Coulomb cones (mu = FRICTION) on every contact.
    warm_start : ndarray, shape (n_rows,), or None
        Previous step's forces matched by pair key (None: no previous step).
    shift : ndarray, shape (nc,), or None
        Previous step's shift ``s`` matched by pair key.
    note : str
        How it was built.
    """

    label: str
    n_grains: int
    problem: StepProblem
    warm_start: np.ndarray | None
    shift: np.ndarray | None
    note: str


def settling_step(n_grains: int, steps: int = PILE_STEPS, dt: float = PILE_DT,
                  seed: int = SETTLING_SEED) -> PileStep:
    """The step after ``steps`` steps of a frictional settling pile (module docstring)."""
    from ..model.laws import Coulomb
    from ..scenes.small import settling_pile
    from ..sim.simulation import Simulation
    from ..solvers import CONVERGED

    start = time.perf_counter()
    sim = Simulation(settling_pile(n_grains, seed=seed), Coulomb(FRICTION), dt,
                     solver="clarabel-direct", tol=1e-8, tol_fp=1e-6, on_failure="ignore")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim.run(steps)
    failed = sum(status != CONVERGED for status in sim.trajectory.status)
    _, _, problem, forces, shift = sim.next_problem()
    speed = float(np.max(np.linalg.norm(sim.scene.grains.velocities, axis=1)))
    note = (f"settling_pile({n_grains}, seed={seed}) after {steps} steps of dt = {dt:g} "
            f"(fixed point around clarabel-direct, {failed} steps not converged, "
            f"{time.perf_counter() - start:.1f} s), max speed {speed:.2f}")
    return PileStep("settling", n_grains, problem, forces, shift, note)


def deposited_step(n_grains: int, dt: float = PILE_DT, seed: int = DEPOSITED_SEED) -> PileStep:
    """The first step of a deposited frictional pile (module docstring)."""
    from ..model.laws import Coulomb
    from ..scenes.packing import deposit_pile
    from .problem_sets import snapshot

    problem = snapshot(deposit_pile(n_grains, seed=seed), Coulomb(FRICTION), dt)
    return PileStep("deposited", n_grains, problem, None, None,
                    f"deposit_pile({n_grains}, seed={seed}), first step of dt = {dt:g}")
