"""Frames for ParaView: a scene as a VTU file (grains as points, contacts as lines), and a PVD series.

Each VTU file (written with meshio) holds

- one ``vertex`` cell per grain, with point data ``radius`` (length),
  ``velocity`` (length/time, 3 components; z = 0 in 2D) and ``spin``
  (1/time, 3 components);
- one ``line`` cell per grain-grain contact (optional), with cell data
  ``gamma`` (the glue state, <= 0; 0 unglued), ``normal_force`` (force) and
  ``state`` (0 unglued or inactive, 1 glued, 2 frictional: the law's
  :meth:`~lubcontact.model.laws.Law.contact_states`);

and the vertex cells carry the same cell fields set to 0, as VTK requires a
value on every cell. In ParaView, show the points as spheres scaled by
``radius`` (Glyph filter) and colour the lines by ``gamma``.
"""
from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .. import checks
from ..model.contacts import Contacts
from ..model.scene import Scene
from .files import atomic_path, save_text

CONTACT_FIELDS = ("gamma", "normal_force", "state")


def _three(vectors: np.ndarray) -> np.ndarray:
    """Rows padded with zeros to 3 components."""
    out = np.zeros((vectors.shape[0], 3))
    out[:, : vectors.shape[1]] = vectors
    return out


def write_vtu(path: str | Path, scene: Scene, contacts: Contacts | None = None,
              gamma: np.ndarray | None = None, normal_force: np.ndarray | None = None,
              states: np.ndarray | None = None) -> Path:
    """Write the grains (and their grain-grain contacts) of ``scene`` to a ``.vtu`` file.

    Parameters
    ----------
    path : str or Path
        Output file (``.vtu``); written atomically.
    scene : Scene
    contacts : Contacts, optional
        The step's contacts; contacts with a plane or a fixed grain are left out.
    gamma, normal_force : ndarray, shape (nc,), optional
        Per-contact glue state and normal force (zeros when not given).
    states : ndarray of bool, shape (3, nc), optional
        The masks ``(unglued, glued, frictional)`` of the law's
        :meth:`~lubcontact.model.laws.Law.contact_states` (``state`` 0 everywhere when not
        given).

    Returns
    -------
    Path
        The file written.
    """
    import meshio

    grains = scene.grains
    n = grains.count
    points = _three(grains.positions)
    cells = [("vertex", np.arange(n).reshape(-1, 1))]
    cell_data = {name: [np.zeros(n)] for name in CONTACT_FIELDS}
    if contacts is not None and contacts.count:
        pairs = contacts.a_is_free
        values = {"gamma": gamma, "normal_force": normal_force}
        values = {k: np.zeros(contacts.count) if v is None else np.asarray(v, dtype=float)
                  for k, v in values.items()}
        masks = np.zeros((3, contacts.count)) if states is None else checks.as_array(
            "states", np.asarray(states, dtype=float), shape=(3, contacts.count))
        values["state"] = masks[1] + 2.0 * masks[2]
        cells.append(("line", np.stack([contacts.body_a[pairs], contacts.body_b[pairs]], axis=1)))
        for name in CONTACT_FIELDS:
            cell_data[name].append(values[name][pairs])
    mesh = meshio.Mesh(points, cells,
                       point_data={"radius": grains.radii.copy(),
                                   "velocity": _three(grains.velocities),
                                   "spin": _three(grains.spins)},
                       cell_data=cell_data)
    with atomic_path(path) as temporary:
        meshio.write(temporary, mesh, file_format="vtu")
    return Path(path)


def write_pvd(path: str | Path, frames: list[tuple[float, str | Path]]) -> Path:
    """A ParaView collection of VTU frames, ``(time, file)`` each, files relative to ``path``."""
    path = Path(path)
    rows = [f'    <DataSet timestep="{time:.17g}" file={quoteattr(str(Path(name).name))}/>'
            for time, name in frames]
    text = "\n".join(['<?xml version="1.0"?>',
                      '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                      "  <Collection>", *rows, "  </Collection>", "</VTKFile>", ""])
    save_text(path, text)
    return path
