"""What ``lubcontact bench solvers`` solves: step problems of 2D piles at rest, and the next step.

See :mod:`lubcontact.bench.piles` for the benchmark itself.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.assemble import assemble
from ..model.contacts import Contacts, find_contacts, lookup_by_key
from ..model.scene import Scene
from ..problem.cones import ConeKind, Cones
from ..problem.step import StepProblem
from ..sim.simulation import Simulation


@dataclass
class PileCase:
    """One benchmark problem and what is needed to build the next step.

    Attributes
    ----------
    label : str
        ``dry`` or ``glued``.
    n_grains : int
    scene : Scene
        The pile.
    simulation : Simulation
        Its simulation (inelastic law, time step, contact distance).
    problem : StepProblem
        The step problem: NONNEG cones, FREE on the glued contacts.
    glued_keys : ndarray of int64
        Pair keys of the glued contacts.
    """

    label: str
    n_grains: int
    scene: Scene
    simulation: Simulation
    problem: StepProblem
    glued_keys: np.ndarray


PILES = ("settled", "deposited")


def pile_cases(n_grains: int, glued_fraction: float, dt: float, seed: int,
               pile: str = "settled", tiles: int = 1) -> list[PileCase]:
    """The dry and glued step problems of a pile of ``n_grains`` disks.

    Parameters
    ----------
    n_grains : int
    glued_fraction : float
        Fraction of the closed contacts glued in the ``glued`` case (0: no such case).
    dt : float
        Time step.
    seed : int
        Seed of the pile and of the choice of glued contacts.
    pile : {"settled", "deposited"}
        :func:`lubcontact.scenes.packing.settle_pile` (with ``tiles``, cached
        under ``out/cache``) or :func:`lubcontact.scenes.packing.deposit_pile`.
    tiles : int
        Settled copies side by side (settled piles only).
    """
    from ..model.laws import Inelastic
    from ..scenes.packing import deposit_pile, settle_pile

    if pile not in PILES:
        raise ValueError(f"pile: must be one of {PILES}, got {pile!r}")
    if pile == "settled":
        scene, info = settle_pile(n_grains, seed=seed, tiles=tiles)
        print(f"# settled pile N={n_grains} (tiles {tiles}): {info['steps']} steps, last max speed "
              f"{info['max_speed']:.1e}, at rest: {info['at_rest']}")
    else:
        scene = deposit_pile(n_grains, seed=seed)
    simulation = Simulation(scene, Inelastic(), dt)
    contacts = find_contacts(simulation.scene, simulation.d_max)
    closed = np.flatnonzero(np.abs(contacts.gaps) <= 1e-9 * contacts.smaller_radius)
    rng = np.random.default_rng(seed)
    glued = np.sort(rng.choice(closed, size=int(round(glued_fraction * closed.size)), replace=False))
    cases = []
    for label, keys in (("dry", np.zeros(0, dtype=np.int64)), ("glued", contacts.keys[glued])):
        if label == "glued" and glued_fraction <= 0:
            continue
        problem = assemble(simulation.scene, contacts, _cones(contacts, keys), simulation.dt,
                           rotations=simulation.law.needs_rotation)
        cases.append(PileCase(label, n_grains, scene, simulation, problem, keys))
    return cases


def _cones(contacts: Contacts, glued_keys: np.ndarray) -> Cones:
    """Frictionless cones: FREE on the glued pairs, NONNEG elsewhere."""
    kinds = np.where(np.isin(contacts.keys, glued_keys), ConeKind.FREE, ConeKind.NONNEG)
    return Cones.frictionless(kinds, contacts.dim - 1)


def next_step_problem(case: PileCase, velocities: np.ndarray) -> StepProblem:
    """The step problem after advancing the pile one step with ``velocities`` (same glued pairs)."""
    scene = case.simulation.scene.copy()
    n, dim = scene.grains.count, scene.grains.dim
    scene.grains.velocities[:] = velocities[: n * dim].reshape(n, dim)
    scene.grains.positions += case.simulation.dt * scene.grains.velocities
    scene.time += case.simulation.dt
    contacts = find_contacts(scene, case.simulation.d_max)
    return assemble(scene, contacts, _cones(contacts, case.glued_keys), case.simulation.dt,
                    rotations=case.simulation.law.needs_rotation)


def matched_forces(previous_keys: np.ndarray, previous_forces: np.ndarray,
                   problem: StepProblem) -> np.ndarray:
    """Previous normal forces matched to ``problem``'s contacts by pair key (0 if new).

    Parameters
    ----------
    previous_keys : ndarray of int64, shape (nc_old,)
        Sorted pair keys of the previous step.
    previous_forces : ndarray, shape (nc_old,)
        Its normal forces.
    problem : StepProblem

    Returns
    -------
    ndarray, shape (problem.n_rows,)
    """
    guess = np.zeros(problem.n_rows)
    guess[: problem.n_contacts] = lookup_by_key(previous_keys, previous_forces, problem.keys)
    return guess
