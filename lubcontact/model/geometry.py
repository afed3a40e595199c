"""Vectorised geometry (any dimension): the pair search, tangent bases and lever arms.

Bodies are numbered globally: free grains ``0..N-1``, fixed grains
``N..N+F-1``, planes ``N+F..N+F+P-1``. Periodic boundaries along x: see
:mod:`lubcontact.model.contacts`.
"""
from __future__ import annotations

import numpy as np


def tangent_basis(normals: np.ndarray) -> np.ndarray:
    """Orthonormal tangent vectors for each unit normal.

    Parameters
    ----------
    normals : ndarray, shape (n, dim)
        Unit normals, dim = 2 or 3.

    Returns
    -------
    ndarray, shape (n, dim - 1, dim)
        In 2D the single tangent is ``n`` rotated by +90 degrees, so that
        ``n x t = +e_z``; in 3D two vectors with ``t1 x t2 = n``.
    """
    n, dim = normals.shape
    if dim == 2:
        return np.stack([-normals[:, 1], normals[:, 0]], axis=1)[:, None, :]
    helper = np.zeros_like(normals)
    use_y = np.abs(normals[:, 0]) > 0.9
    helper[~use_y, 0] = 1.0
    helper[use_y, 1] = 1.0
    t1 = np.cross(helper, normals)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    return np.stack([t1, t2], axis=1)


def lever_coefficients(normals: np.ndarray, tangents: np.ndarray) -> np.ndarray:
    """``n x t_k`` for each tangent: the rotational weight of a unit lever along ``n``.

    Returns
    -------
    ndarray, shape (n, dim - 1, nrot)
        ``nrot`` = 1 in 2D (the z component), 3 in 3D.
    """
    if normals.shape[1] == 2:
        cross = normals[:, None, 0] * tangents[:, :, 1] - normals[:, None, 1] * tangents[:, :, 0]
        return cross[:, :, None]
    return np.cross(normals[:, None, :], tangents)


def smaller_radius(radius_a: np.ndarray, radius_b: np.ndarray) -> np.ndarray:
    """The smaller radius of each pair; ``radius_a = 0`` marks a plane (the grain's radius)."""
    return np.where(radius_a > 0, np.minimum(radius_a, radius_b), radius_b)


def close_pairs(centres: np.ndarray, radii: np.ndarray, n_free: int, d_max: float,
                period: float | None, plane_points: np.ndarray, plane_normals: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every pair of bodies with gap ``D < d_max``, sorted by pair key (a cell list search).

    Parameters
    ----------
    centres : ndarray, shape (N + F, dim)
        Free grains first, then fixed grains.
    radii : ndarray, shape (N + F,)
    n_free : int
        ``N``, the number of free grains (each pair has a free body ``b``).
    d_max : float
        Detection distance (length), >= 0.
    period : float or None
        Period along x (None: not periodic).
    plane_points, plane_normals : ndarray, shape (P, dim)

    Returns
    -------
    body_a, body_b, keys, gaps, normals, radius_a
        Arrays of length ``nc``: global body numbers (``a`` any kind, ``b`` a
        free grain), pair keys ``a * n_bodies + b``, gaps, unit normals from
        ``a`` to ``b`` (shape (nc, dim)) and the radius of ``a`` (0 for a plane).
    """
    dim = centres.shape[1]
    n_fixed = len(radii) - n_free
    parts = [_grain_pairs(centres, radii, n_free, d_max, period),
             _plane_pairs(centres[:n_free], radii[:n_free], plane_points, plane_normals,
                          n_free + n_fixed, d_max)]
    a = np.concatenate([p[0] for p in parts])
    b = np.concatenate([p[1] for p in parts])
    gaps = np.concatenate([p[2] for p in parts])
    normals = np.vstack([p[3] for p in parts]).reshape(-1, dim)
    radius_a = np.concatenate([p[4] for p in parts])
    keys = a.astype(np.int64) * (len(radii) + len(plane_points)) + b    # sorted: the grain pairs
    return a, b, keys, gaps, normals, radius_a      # by (a, b), then the planes' (numbered after)


_Pairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""body_a, body_b, gaps, normals, radius_a of some pairs, sorted by pair key."""


def _grain_pairs(centres: np.ndarray, radii: np.ndarray, n_free: int, d_max: float,
                 period: float | None = None) -> _Pairs:
    """The grain pairs of :func:`close_pairs`, by a cell list
    (:func:`~lubcontact.model.pair_search.grain_pairs`).

    Raises
    ------
    ValueError
        If a centre is not finite, or the period is not larger than twice the search reach
        (the minimum image would be ambiguous).
    """
    from .pair_search import grain_pairs  # numba, imported on first use

    dim = centres.shape[1]
    if len(radii) < 2 or n_free == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0), np.zeros((0, dim)), np.zeros(0)
    if not np.isfinite(centres).all():
        raise ValueError("positions: the grains' and fixed grains' centres must be finite, got nan or inf")
    reach = 2.0 * radii.max() + d_max
    if period is not None and not period > 2.0 * reach:
        raise ValueError(f"period: must exceed twice the contact reach 2 (2 r_max + d_max) = "
                         f"{2.0 * reach:.6g}, got {period}")
    a, b, gaps, normals = grain_pairs(np.ascontiguousarray(centres, dtype=float),
                                      np.ascontiguousarray(radii, dtype=float), n_free,
                                      float(d_max), reach, 0.0 if period is None else float(period))
    return a, b, gaps, normals, radii[a]


def _plane_pairs(centres: np.ndarray, radii: np.ndarray, plane_points: np.ndarray,
                 plane_normals: np.ndarray, first_plane_id: int, d_max: float) -> _Pairs:
    """The grain-plane pairs of :func:`close_pairs`, by plane, then grain (by pair key)."""
    offsets = np.einsum("pd,pd->p", plane_points, plane_normals)
    gaps = (centres @ plane_normals.T - offsets[None, :] - radii[:, None]).T     # (P, N)
    p, b = np.nonzero(gaps < d_max)
    return (first_plane_id + p, b, gaps[p, b], plane_normals[p], np.zeros(len(b)))
