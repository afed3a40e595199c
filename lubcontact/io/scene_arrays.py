"""A scene as plain arrays (for checkpoints and frames) and back, bit for bit."""
from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

from ..model.scene import Grains, Scene

_GRAIN_FIELDS = ("positions", "radii", "masses", "inertias", "velocities", "spins", "angles")


def scene_arrays(scene: Scene) -> dict[str, np.ndarray]:
    """The arrays that rebuild ``scene`` with :func:`scene_from_arrays`.

    Not stored: the external force and the prescribed obstacle velocities (functions or
    schedules); the caller rebuilds them. Obstacle positions are stored as they are now.
    """
    grains = scene.grains
    out = {f"grains.{name}": getattr(grains, name) for name in _GRAIN_FIELDS}
    out["grains.densities"] = grains.densities if grains.densities is not None else np.zeros(0)
    out.update({"plane_points": scene.planes.points, "plane_normals": scene.planes.normals,
                "fixed_positions": scene.fixed_positions, "fixed_radii": scene.fixed_radii,
                "gravity": scene.gravity, "fluid_density": np.float64(scene.fluid_density),
                "time": np.float64(scene.time), "period": np.float64(scene.period or 0.0),
                "metadata": np.array(json.dumps(scene.metadata, default=float))})
    return out


def scene_from_arrays(data: Mapping[str, np.ndarray]) -> Scene:
    """Inverse of :func:`scene_arrays` (values restored bit for bit)."""
    densities = data["grains.densities"]
    grains = Grains.create(data["grains.positions"], data["grains.radii"],
                           masses=data["grains.masses"], inertias=data["grains.inertias"],
                           densities=densities if densities.size else None,
                           velocities=data["grains.velocities"], spins=data["grains.spins"])
    grains.angles[:] = data["grains.angles"]
    period = float(data["period"])
    return Scene.create(grains, plane_points=data["plane_points"], plane_normals=data["plane_normals"],
                        fixed_positions=data["fixed_positions"], fixed_radii=data["fixed_radii"],
                        gravity=data["gravity"], fluid_density=float(data["fluid_density"]),
                        time=float(data["time"]), check_overlaps=False,
                        metadata=json.loads(str(data["metadata"])), period=period or None)
