"""The contact Jacobian's rows in CSR arrays, compiled (numba).

:func:`~lubcontact.model.contacts.contact_jacobian` fills ``H`` (each contact's normal row, then
the tangential rows of the frictional contacts) in one compiled call: a pass that counts each
row's entries (two bodies at most), then passes that write them in place, in increasing column
order. The vectorised build it replaces (candidate entries per row, masks, then the scipy matrix
of each block and their stacking) took about 90 us of a 10-grain step's 560
(docs/records/benchmarks.md, "Small systems: the contact rows compiled"). Imported on first use,
as the solvers' kernels.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _in_column_order(a: int, b: int, n_grains: int) -> tuple[int, int, float]:
    """A contact's bodies in the order of their columns, the lower numbered grain first (an
    obstacle, numbered after the grains, last), and the sign of the first's entries: ``+1``
    where it is ``b`` (``+n`` on ``b``'s translations, ``-n`` on ``a``'s)."""
    if a >= n_grains or b < a:
        return b, a, 1.0
    return a, b, -1.0


@numba.njit(cache=True)
def jacobian_rows(body_a: np.ndarray, body_b: np.ndarray, normals: np.ndarray,
                  radius_a: np.ndarray, radius_b: np.ndarray, tangential: np.ndarray,
                  tangents: np.ndarray, levers: np.ndarray, n_grains: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``H``'s CSR arrays: the normal row of each contact, then ``tangents.shape[1]``
    tangential rows for each contact of ``tangential``.

    Parameters
    ----------
    body_a, body_b : ndarray of int, shape (nc,)
        Each contact's bodies; those numbered ``n_grains`` or more (obstacles) have no columns.
    normals : ndarray, shape (nc, dim)
        Unit normals from ``a`` to ``b``.
    radius_a, radius_b : ndarray, shape (nc,)
        Lever lengths (the radii; 0 for a plane).
    tangential : ndarray of int, shape (m,)
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
        ``indptr`` (nc + m nt + 1,) and ``indices``, 32-bit (the caller checks that they fit),
        and ``data``; canonical: in each row the lower numbered grain's translations, the
        other's, then their rotations in the same order. A normal row holds ``+n`` on ``b``'s
        translations and ``-n`` on ``a``'s; a tangential row ``+t`` and ``-r_b (n x t)`` on
        ``b``'s, ``-t`` and ``-r_a (n x t)`` on ``a``'s.
    """
    nc, dim = normals.shape
    m, nt, nrot = levers.shape
    n_rows = nc + m * nt
    indptr = np.zeros(n_rows + 1, dtype=np.int32)
    for c in range(nc):
        indptr[c + 1] = dim * ((body_a[c] < n_grains) + (body_b[c] < n_grains))
    for k in range(m):
        c = tangential[k]
        width = (dim + nrot) * ((body_a[c] < n_grains) + (body_b[c] < n_grains))
        for j in range(nt):
            indptr[nc + k * nt + j + 1] = width
    for row in range(n_rows):
        indptr[row + 1] += indptr[row]
    indices = np.empty(indptr[n_rows], dtype=np.int32)
    data = np.empty(indptr[n_rows])
    rot0 = n_grains * dim
    for c in range(nc):
        first, second, sign = _in_column_order(body_a[c], body_b[c], n_grains)
        e = indptr[c]
        for body, weight in ((first, sign), (second, -sign)):
            if body < n_grains:
                for d in range(dim):
                    indices[e], data[e] = body * dim + d, weight * normals[c, d]
                    e += 1
    for k in range(m):
        c = tangential[k]
        first, second, sign = _in_column_order(body_a[c], body_b[c], n_grains)
        lever_first, lever_second = (radius_b[c], radius_a[c]) if sign > 0 else \
            (radius_a[c], radius_b[c])
        for j in range(nt):
            e = indptr[nc + k * nt + j]
            for body, weight in ((first, sign), (second, -sign)):
                if body < n_grains:
                    for d in range(dim):
                        indices[e], data[e] = body * dim + d, weight * tangents[k, j, d]
                        e += 1
            for body, lever in ((first, lever_first), (second, lever_second)):
                if body < n_grains:
                    for d in range(nrot):
                        indices[e], data[e] = rot0 + body * nrot + d, -lever * levers[k, j, d]
                        e += 1
    return indptr, indices, data
