"""Small vectorised geometric helpers (any dimension)."""
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
