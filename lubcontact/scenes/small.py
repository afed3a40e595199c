"""Small built-in scenes: the exact-solution cases of docs/guide/model.md section 7 and a settling pile
(dimensionless units)."""
from __future__ import annotations

import numpy as np

from ..model.scene import Grains, Scene, Schedule, inclined_plane_normal


def push_pull(gap: float = 1.0, t_inversion: float = 2.0, mass: float = 1.0, g: float = 1.0,
              radius: float = 0.5) -> Scene:
    """One disk above a horizontal plane, pushed by ``-m g`` then pulled by ``+m g``.

    The disk starts at rest with gap ``gap`` (the poster's q0 = 1); the force
    reverses at ``t_inversion``.
    """
    grains = Grains.create([[0.0, radius + gap]], radius, masses=mass)
    force = Schedule(times=(0.0, t_inversion), values=([0.0, -mass * g], [0.0, mass * g]))
    return Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0],
                        external_force=force, metadata={"name": "push_pull", "gap": gap,
                                                        "t_inversion": t_inversion, "g": g})


def disk_on_incline(angle: float, height: float = 0.1, radius: float = 1.0, mass: float = 1.0,
                    g: float = 1.0, t_inversion: float | None = None) -> Scene:
    """A disk released at rest with gap ``height`` above a plane tilted by ``angle`` (rad).

    The plane passes through the origin; gravity is ``-g e_y``. With
    ``t_inversion`` the force per unit mass reverses at that time (gluey test).
    """
    normal = inclined_plane_normal(angle)
    grains = Grains.create([(radius + height) * normal], radius, masses=mass)
    weight = np.array([0.0, -mass * g])
    force = None if t_inversion is None else Schedule(times=(0.0, t_inversion),
                                                      values=(weight, -weight))
    return Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=normal,
                        gravity=None if force is not None else [0.0, -g], external_force=force,
                        metadata={"name": "disk_on_incline", "angle": angle, "g": g,
                                  "height": height, "t_inversion": t_inversion})


def two_grains(push_time: float = 1.0, push_force: float = 1.0, pull_force: float = 1.0,
               gap: float = 0.05, radius: float = 0.5, mass: float = 1.0) -> Scene:
    """Two disks on the x axis pushed together until ``push_time``, then pulled apart.

    Each grain feels ``push_force`` towards the other, then ``pull_force`` away.
    """
    positions = [[-(radius + gap / 2), 0.0], [radius + gap / 2, 0.0]]
    grains = Grains.create(positions, radius, masses=mass)
    towards = np.array([[1.0, 0.0], [-1.0, 0.0]])
    schedule = Schedule(times=(0.0, push_time), values=(push_force * towards, -pull_force * towards))
    return Scene.create(grains, external_force=schedule,
                        metadata={"name": "two_grains", "push_time": push_time,
                                  "push_force": push_force, "pull_force": pull_force})


def settling_pile(n_grains: int = 200, radius: float = 0.5, polydispersity: float = 0.2,
                  width: float | None = None, g: float = 1.0, seed: int = 0) -> Scene:
    """Polydisperse disks on a loose jittered grid above a floor, between two walls.

    Radii are uniform in ``radius (1 +/- polydispersity)``; masses are
    proportional to area (unit density). Deterministic for a given ``seed``.
    """
    rng = np.random.default_rng(seed)
    columns = max(1, int(np.ceil(np.sqrt(n_grains))))
    spacing = 2.0 * radius * (1.0 + polydispersity) * 1.1
    width = columns * spacing if width is None else width
    rows = int(np.ceil(n_grains / columns))
    ix, iy = np.meshgrid(np.arange(columns), np.arange(rows))
    centres = np.stack([(ix.ravel() + 0.5) * spacing, (iy.ravel() + 0.5) * spacing + 0.1 * radius],
                       axis=1)[:n_grains]
    radii = radius * (1.0 + polydispersity * rng.uniform(-1.0, 1.0, n_grains))
    jitter = 0.5 * (spacing - 2.0 * radii)[:, None] * rng.uniform(-1.0, 1.0, (n_grains, 2))
    grains = Grains.create(centres + jitter, radii, densities=1.0)
    return Scene.create(grains, plane_points=[[0.0, 0.0], [0.0, 0.0], [width, 0.0]],
                        plane_normals=[[0.0, 1.0], [1.0, 0.0], [-1.0, 0.0]], gravity=[0.0, -g],
                        metadata={"name": "settling_pile", "seed": seed, "width": width})
