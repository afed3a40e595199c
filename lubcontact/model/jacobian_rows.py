"""The contact Jacobian's rows in CSR arrays, compiled (numba).

:func:`~lubcontact.model.contacts.contact_jacobian` fills ``H`` (each contact's normal row, then
the tangential rows of the frictional contacts) in one pass over the contacts: a row holds the
entries of two bodies at most, so each is written in place, in increasing column order. The
vectorised build it replaces (candidate entries per row, masks, then the scipy matrix of each
block and their stacking) took 80-90 us of a 10-grain step's 570 (docs/records/benchmarks.md,
"Small systems: the contact rows compiled"). Imported on first use, as the solvers' kernels.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def jacobian_rows(body_a: np.ndarray, body_b: np.ndarray, normals: np.ndarray,
                  radius_a: np.ndarray, radius_b: np.ndarray, which: np.ndarray,
                  tangents: np.ndarray, levers: np.ndarray, n_grains: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``H``'s CSR arrays: the normal row of each contact, then ``tangents.shape[1]``
    tangential rows for each contact of ``which``.

    Parameters
    ----------
    body_a, body_b : ndarray of int, shape (nc,)
        Each contact's bodies (``b`` a free grain; ``a`` an obstacle when ``>= n_grains``).
    normals : ndarray, shape (nc, dim)
        Unit normals from ``a`` to ``b``.
    radius_a, radius_b : ndarray, shape (nc,)
        Lever lengths (the radii; 0 for a plane).
    which : ndarray of int, shape (m,)
        The contacts with tangential rows, in row order.
    tangents, levers : ndarray, shapes (m, nt, dim) and (m, nt, nrot)
        Their tangent basis and ``n x t`` (:func:`~lubcontact.model.geometry.tangent_basis`,
        :func:`~lubcontact.model.geometry.lever_coefficients`).
    n_grains : int
        Free grains (the bodies with columns; the rotational columns follow their ``n_grains
        dim`` translations).

    Returns
    -------
    (ndarray, ndarray, ndarray)
        ``indptr`` (nc + m nt + 1,), ``indices`` and ``data``, canonical, the indices in 32 bits
        (scipy's own choice at these sizes: given 64-bit ones, its constructor scans and copies
        them, 12.4 against 7.5 us for 50 rows; the caller checks that they fit): in each row the lower
        numbered grain's translations, the other's, then their rotations in the same order; an
        obstacle has no columns. A normal row holds ``+n`` on ``b``'s translations and ``-n``
        on ``a``'s; a tangential row ``+t`` and ``-r_b (n x t)`` on ``b``'s, ``-t`` and ``-r_a
        (n x t)`` on ``a``'s.
    """
    nc, dim = normals.shape
    m, nt, nrot = levers.shape
    n_rows = nc + m * nt
    indptr = np.zeros(n_rows + 1, dtype=np.int32)
    for c in range(nc):
        indptr[c + 1] = dim if body_a[c] >= n_grains else 2 * dim
    for k in range(m):
        width = dim + nrot if body_a[which[k]] >= n_grains else 2 * (dim + nrot)
        for j in range(nt):
            indptr[nc + k * nt + j + 1] = width
    for row in range(n_rows):
        indptr[row + 1] += indptr[row]
    indices = np.empty(indptr[n_rows], dtype=np.int32)
    data = np.empty(indptr[n_rows])
    rot0 = n_grains * dim
    for c in range(nc):
        a, b = body_a[c], body_b[c]
        first_is_b = a >= n_grains or b < a
        first, second = (b, a) if first_is_b else (a, b)
        sign = 1.0 if first_is_b else -1.0                 # +n on b's columns, -n on a's
        e = indptr[c]
        for d in range(dim):
            indices[e], data[e] = first * dim + d, sign * normals[c, d]
            e += 1
        if second < n_grains:
            for d in range(dim):
                indices[e], data[e] = second * dim + d, -sign * normals[c, d]
                e += 1
    for k in range(m):
        c = which[k]
        a, b = body_a[c], body_b[c]
        first_is_b = a >= n_grains or b < a
        first, second = (b, a) if first_is_b else (a, b)
        sign = 1.0 if first_is_b else -1.0
        lever_first, lever_second = (radius_b[c], radius_a[c]) if first_is_b else \
            (radius_a[c], radius_b[c])
        for j in range(nt):
            e = indptr[nc + k * nt + j]
            for d in range(dim):
                indices[e], data[e] = first * dim + d, sign * tangents[k, j, d]
                e += 1
            if second < n_grains:
                for d in range(dim):
                    indices[e], data[e] = second * dim + d, -sign * tangents[k, j, d]
                    e += 1
            for d in range(nrot):
                indices[e], data[e] = rot0 + first * nrot + d, -lever_first * levers[k, j, d]
                e += 1
            if second < n_grains:
                for d in range(nrot):
                    indices[e], data[e] = rot0 + second * nrot + d, -lever_second * levers[k, j, d]
                    e += 1
    return indptr, indices, data
