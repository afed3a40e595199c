"""From a scene and its contacts to the step problem (docs/guide/model.md sections 3 and 4).

``assemble`` is the last stage of the model: it computes the free velocity
``U = v^k + dt M^-1 F_ext`` and stacks the contact rows ``H`` (normal rows,
then tangential rows of the frictional contacts). Rotational unknowns are
modelled only when asked (a law with friction): normal forces through the
centres cannot spin disks or spheres.
"""
from __future__ import annotations

import numpy as np

from ..problem.cones import Cones
from ..problem.step import StepProblem
from .contacts import Contacts, contact_jacobian, obstacle_offset
from .scene import Scene


def mass_diagonal(scene: Scene, rotations: bool) -> np.ndarray:
    """Diagonal of ``M``: each grain's mass per translation, then its inertia per rotation.

    Returns
    -------
    ndarray, shape (n_dof,)
        ``N dim`` masses, followed by ``N n_rot`` inertias when ``rotations``.
    """
    grains = scene.grains
    mass = np.repeat(grains.masses, grains.dim)
    if rotations:
        mass = np.concatenate([mass, np.repeat(grains.inertias, grains.spins.shape[1])])
    return mass


def assemble(scene: Scene, contacts: Contacts, cones: Cones, dt: float, *,
             rotations: bool) -> StepProblem:
    """The step problem of ``scene`` for the given contacts and force sets.

    Parameters
    ----------
    scene : Scene
        The state at the start of the step (velocities, spins, external forces at ``scene.time``).
    contacts : Contacts
        Candidate contacts (``find_contacts``).
    cones : Cones
        Force set of each contact (``law.cones``), in the contacts' order.
    dt : float
        Time step.
    rotations : bool
        Model rotational unknowns (``law.needs_rotation``).

    Returns
    -------
    StepProblem
        With the contacts' pair keys (for warm starts), zero shift, and the
        offset of moving obstacles when some obstacle moves.
    """
    grains = scene.grains
    mass = mass_diagonal(scene, rotations)
    velocity = grains.velocities.ravel()
    if rotations:
        velocity = np.concatenate([velocity, grains.spins.ravel()])
    force = scene.external_forces().ravel()
    free_velocity = velocity.copy()
    free_velocity[: force.size] += dt * force / mass[: force.size]
    jacobian = contact_jacobian(contacts, cones.tangential, rotations)
    obstacles = scene.obstacle_velocities()
    moving = obstacle_offset(contacts, obstacles, cones.tangential, dt) if np.any(obstacles) \
        else None
    return StepProblem(mass=mass, free_velocity=free_velocity, jacobian=jacobian,
                       gaps=contacts.gaps, cones=cones, dt=dt, keys=contacts.keys,
                       obstacle_offset=moving)
