"""Building blocks of the hard cases: arrangements of grains and scene -> step problem.

Every hard case ends as a :class:`~lubcontact.problem.StepProblem` built by the
same code the time stepper uses (:func:`lubcontact.model.assemble.assemble`), so the suite
tests what a simulation would hand to a solver. Units are dimensionless:
radius ``r = 0.5`` unless said otherwise, ``g = 1``, natural time
``sqrt(r / g)``.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from lubcontact import (
    ConeKind,
    Cones,
    Contacts,
    Grains,
    Law,
    Scene,
    Simulation,
    StepProblem,
    find_contacts,
)
from lubcontact.model.assemble import assemble
from lubcontact.model.scene import ForceLike


class ExplicitFriction(Law):
    """Every contact gets a Coulomb cone with the same ``mu``, tangential rows included.

    Unlike :class:`lubcontact.laws.Coulomb`, ``mu = 0`` still writes friction
    rows (the "mu = 0 written as friction" hard case).
    """

    needs_rotation = True
    has_friction = True

    def __init__(self, mu: float):
        self.mu = float(mu)

    def cones(self, contacts: Contacts, gamma: np.ndarray) -> Cones:
        nc = contacts.count
        return Cones(kinds=np.full(nc, ConeKind.COULOMB, dtype=np.int8), mu=np.full(nc, self.mu),
                     tangential=np.arange(nc), tangent_dim=contacts.dim - 1)


def scene_problem(scene: Scene, law: Law, dt: float, *, d_max: float | None = None,
                  gamma: np.ndarray | None = None) -> StepProblem:
    """The step problem a :class:`~lubcontact.Simulation` would solve next.

    Parameters
    ----------
    gamma : ndarray, shape (nc,), optional
        Gluey state per contact in contact (key) order; default all 0.
    """
    sim = Simulation(scene, law, dt, d_max=d_max)
    contacts = find_contacts(sim.scene, sim.d_max)
    gamma = np.zeros(contacts.count) if gamma is None else np.asarray(gamma, dtype=float)
    return assemble(sim.scene, contacts, law.cones(contacts, gamma), sim.dt,
                    rotations=law.needs_rotation)


def floor_scene(positions: ArrayLike, radii: ArrayLike, *, masses: ArrayLike | None = None,
                densities: ArrayLike | None = None, velocities: ArrayLike | None = None,
                gravity: float = 1.0, walls: tuple[float, float] | None = None, lid: float | None = None,
                external_force: ForceLike = None) -> Scene:
    """Grains above the floor ``y = 0``; optional side walls ``x = walls`` and a lid ``y = lid``."""
    positions = np.asarray(positions, dtype=float)
    dim = positions.shape[1]
    up = np.eye(dim)[1]
    points, normals = [np.zeros(dim)], [up]
    if walls is not None:
        points += [walls[0] * np.eye(dim)[0], walls[1] * np.eye(dim)[0]]
        normals += [np.eye(dim)[0], -np.eye(dim)[0]]
    if lid is not None:
        points.append(lid * up)
        normals.append(-up)
    grains = Grains.create(positions, radii, masses=masses, densities=densities,
                           velocities=velocities)
    return Scene.create(grains, plane_points=points, plane_normals=normals,
                        gravity=-gravity * up, external_force=external_force)


def hexagonal_box(columns: int, rows: int, radius: float = 0.5) -> tuple[np.ndarray, float, float]:
    """Disks in a hexagonal packing filling a box exactly.

    Even rows hold ``columns`` disks touching both walls, odd rows
    ``columns - 1`` disks nested in the pockets; every disk touches its
    neighbours (gap 0 up to rounding).

    Returns
    -------
    (ndarray (N, 2), float, float)
        Centres, box width, height of the top of the last row.
    """
    diameter = 2.0 * radius
    centres = []
    for row in range(rows):
        count = columns - (row % 2)
        x = radius + diameter * np.arange(count) + (row % 2) * radius
        y = np.full(count, radius + row * diameter * np.sqrt(3.0) / 2.0)
        centres.append(np.stack([x, y], axis=1))
    centres = np.vstack(centres)
    return centres, columns * diameter, centres[:, 1].max() + radius


def pyramid(base: int, radius: float = 0.5) -> np.ndarray:
    """Disks stacked in a triangle on the floor (``base`` on the bottom row), all touching."""
    centres = []
    for row in range(base):
        count = base - row
        x = radius * (1 + row) + 2.0 * radius * np.arange(count)
        centres.append(np.stack([x, np.full(count, radius + row * radius * np.sqrt(3.0))], axis=1))
    return np.vstack(centres)


def loose_pile(count: int, seed: int, radius: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A pyramid spread by 5 %, random radii (+/- 5 %) and random lifts: gaps from 0 to ~0.15 r.

    Returns
    -------
    (ndarray (N, 2), ndarray (N,), ndarray (N, 2))
        Centres, radii and random velocities of order ``sqrt(g r)``.
    """
    rng = np.random.default_rng(seed)
    base = int(np.ceil((np.sqrt(8 * count + 1) - 1) / 2))
    centres = pyramid(base, radius)[:count]
    spread = rng.uniform(0.0, 0.05 * radius, count) * (rng.uniform(size=count) > 0.25)
    centres = centres * (1.0 + 0.05) + np.stack([np.zeros(count), spread], axis=1)
    radii = radius * (1.0 + 0.05 * rng.uniform(-1.0, 1.0, count))
    velocities = np.sqrt(radius) * rng.normal(size=(count, 2))
    return centres, radii, velocities
