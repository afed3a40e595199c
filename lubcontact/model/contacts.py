"""Contact detection and contact Jacobians.

Bodies are numbered globally: free grains ``0..N-1``, fixed grains
``N..N+F-1``, planes ``N+F..N+F+P-1``. Each contact joins a body ``a`` (any
kind) to a free grain ``b``; its normal points from ``a`` to ``b`` and the
relative velocity is ``u = v_b(contact point) - v_a(contact point)``. A
positive normal force pushes the bodies apart.

Periodic scenes (``scene.period`` = L along x): the neighbour search's cells tile
the period, those at either end neighbours of each other, and a pair across the
boundary is measured with the minimum-image separation, so its key is the same
on both sides of the boundary and the pair keeps its gluey state when a grain
crosses it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .geometry import close_pairs, lever_coefficients, smaller_radius, tangent_basis
from .scene import Scene, n_rotations


@dataclass
class Contacts:
    """Candidate contacts of one configuration, all arrays of length ``nc``.

    Attributes
    ----------
    body_a, body_b : ndarray of int
        Global body numbers; ``body_b`` is always a free grain.
    keys : ndarray of int64
        Pair identity ``body_a * n_bodies + body_b``, sorted increasingly.
    gaps : ndarray
        Signed distances ``D`` (length); negative means overlap.
    normals : ndarray, shape (nc, dim)
        Unit normals from ``a`` to ``b``.
    points : ndarray, shape (nc, dim)
        Contact points (middle of the gap).
    radius_a, radius_b : ndarray
        Radii (0 for a plane).
    n_grains : int
        Number of free grains (columns of the Jacobians are built from it).
    """

    body_a: np.ndarray
    body_b: np.ndarray
    keys: np.ndarray
    gaps: np.ndarray
    normals: np.ndarray
    points: np.ndarray
    radius_a: np.ndarray
    radius_b: np.ndarray
    n_grains: int

    @property
    def count(self) -> int:
        return self.gaps.shape[0]

    @property
    def dim(self) -> int:
        return self.normals.shape[1]

    @property
    def a_is_free(self) -> np.ndarray:
        return self.body_a < self.n_grains

    @property
    def effective_radius(self) -> np.ndarray:
        """``r`` for a plane contact, ``r_a r_b / (r_a + r_b)`` for two grains."""
        plane = self.radius_a == 0
        ra = np.where(plane, 1.0, self.radius_a)
        return np.where(plane, self.radius_b, ra * self.radius_b / (ra + self.radius_b))

    @property
    def smaller_radius(self) -> np.ndarray:
        """The smaller radius of the two bodies (the grain's for a plane contact)."""
        return smaller_radius(self.radius_a, self.radius_b)


def find_contacts(scene: Scene, d_max: float) -> Contacts:
    """All pairs with gap ``D < d_max``, found with a cell list (no O(N^2) search).

    Parameters
    ----------
    scene : Scene
    d_max : float
        Detection distance (length), >= 0.
    """
    grains = scene.grains
    a, b, keys, gaps, normals, radius_a = close_pairs(
        np.vstack([grains.positions, scene.fixed_positions]),
        np.concatenate([grains.radii, scene.fixed_radii]), grains.count, d_max, scene.period,
        scene.planes.points, scene.planes.normals)
    radius_b = grains.radii[b]
    points = grains.positions[b] - (radius_b + 0.5 * gaps)[:, None] * normals
    return Contacts(body_a=a, body_b=b, keys=keys, gaps=gaps, normals=normals, points=points,
                    radius_a=radius_a, radius_b=radius_b, n_grains=grains.count)


def dof_count(n_grains: int, dim: int, rotations: bool) -> int:
    """Length of the generalised velocity ``[v (N*dim), omega (N*nrot)]``."""
    return n_grains * (dim + (n_rotations(dim) if rotations else 0))


def contact_jacobian(contacts: Contacts, tangential: np.ndarray, rotations: bool) -> sp.csr_matrix:
    """``H``: the normal rows ``B``, ``(B v)_c = u_n,c``, then the tangential rows ``T``.

    ``T`` holds ``dim - 1`` rows for each contact of ``tangential``: ``(T v)`` is their
    tangential relative velocity.

    Parameters
    ----------
    contacts : Contacts
    tangential : ndarray of int, shape (m,)
        The contacts that get tangential rows, in row order (empty: normal rows only).
    rotations : bool
        Columns for the rotational unknowns (after the translations); needed by tangential
        rows.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (nc + m (dim - 1), n_dof)
        Canonical, with 32-bit indices (filled by
        :func:`~lubcontact.model.jacobian_rows.jacobian_rows`, compiled).

    Raises
    ------
    ValueError
        Naming ``rotations`` when tangential rows are asked for without rotational columns;
        naming ``contacts`` when ``H``'s columns or entries would not fit 32-bit indices.
    """
    from .jacobian_rows import jacobian_rows  # numba, imported on first use

    tangential = np.asarray(tangential, dtype=np.int64)
    if tangential.size and not rotations:
        raise ValueError("rotations: tangential rows need the rotational columns, got False")
    dim, n = contacts.dim, contacts.n_grains
    n_dof = dof_count(n, dim, rotations)
    entries = 2 * (dim + n_rotations(dim)) * (contacts.count + tangential.size * (dim - 1))
    if max(n_dof, entries) >= 2**31:                # an upper bound of H's entries
        raise ValueError(f"contacts: H of {contacts.count} contacts and {n_dof} unknowns would "
                         f"hold up to {entries} entries, beyond 32-bit indices")
    normals = contacts.normals[tangential]
    tangents = tangent_basis(normals)                       # (m, dim - 1, dim)
    levers = lever_coefficients(normals, tangents)          # (m, dim - 1, nrot)
    indptr, indices, data = jacobian_rows(contacts.body_a, contacts.body_b, contacts.normals,
                                          contacts.radius_a, contacts.radius_b, tangential,
                                          tangents, levers, n)
    return sp.csr_matrix((data, indices, indptr), shape=(indptr.size - 1, n_dof))


def obstacle_offset(contacts: Contacts, obstacle_velocities: np.ndarray, tangential: np.ndarray,
                    dt: float) -> np.ndarray:
    """What moving obstacles add to the constraint values ``g``, laid out like a force vector.

    A contact whose body ``a`` is an obstacle with prescribed velocity ``w_a``
    has relative velocity ``u = v_b - w_a`` at its point (obstacles do not
    spin), so its rows of ``g = [D + s, 0] + dt H v`` gain ``-dt (n . w_a)``
    and ``-dt (t_k . w_a)``.

    Parameters
    ----------
    contacts : Contacts
    obstacle_velocities : ndarray, shape (F + P, dim)
        ``Scene.obstacle_velocities()`` (fixed grains, then planes).
    tangential : ndarray of int
        Contacts with tangential rows, in row order (``cones.tangential``).
    dt : float

    Returns
    -------
    ndarray, shape (nc + len(tangential) * (dim - 1),)
        Length units.
    """
    nc, dim, n = contacts.count, contacts.dim, contacts.n_grains
    velocity = np.zeros((nc, dim))
    obstacle = ~contacts.a_is_free
    velocity[obstacle] = obstacle_velocities[contacts.body_a[obstacle] - n]
    normal = -dt * np.einsum("cd,cd->c", contacts.normals, velocity)
    tangents = tangent_basis(contacts.normals[tangential])                  # (m, nt, dim)
    along = -dt * np.einsum("ckd,cd->ck", tangents, velocity[tangential])    # (m, nt)
    return np.concatenate([normal, along.ravel()])


def lookup_by_key(stored_keys: np.ndarray, values: np.ndarray, wanted: np.ndarray,
                  width: int | None = None) -> np.ndarray:
    """Values of the wanted keys in ``stored_keys`` (sorted), 0 for keys not stored.

    ``values`` has one entry (``width`` is None) or one row of ``width``
    entries per stored key.
    """
    shape = (wanted.size,) if width is None else (wanted.size, width)
    out = np.zeros(shape)
    if stored_keys.size == 0 or wanted.size == 0:
        return out
    pos = np.clip(np.searchsorted(stored_keys, wanted), 0, stored_keys.size - 1)
    found = stored_keys[pos] == wanted
    out[found] = values[pos[found]]
    return out
