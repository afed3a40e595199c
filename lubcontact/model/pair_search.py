"""The pairs of grains closer than a detection distance, by a cell list, compiled (numba).

:func:`~lubcontact.model.geometry.close_pairs` finds the grain pairs here: the centres binned in
cells at least the contact reach ``2 r_max + d_max`` wide (periodic along x where the scene is,
the cells then tiling the period), the pairs looked for within each cell and between each pair of
neighbouring cells, once, and the gaps, normals and the pairs' orientation computed in the same
pass. The k-d tree it replaces (scipy's ``query_pairs`` on the centres and their periodic images,
then numpy passes over the candidates, then a sort by pair key) took 11-12 ms of a 10 000-grain
flow's step against about 3 here (docs/records/benchmarks.md, "the pair search by cells").
Imported on first use, as the solvers' kernels.
"""
from __future__ import annotations

import numba
import numpy as np

CELLS_PER_GRAIN = 8
"""The cells at most, per centre (and 64 more): where the reach-wide cells of a scene spread out
(a grain far from the others) would be more, the cells are widened to this many; the search stays
exact, with more candidates per cell."""


@numba.njit(cache=True, error_model="numpy")     # coincident centres: nan normals, as numpy's
def grain_pairs(centres: np.ndarray, radii: np.ndarray, n_free: int, d_max: float, reach: float,
                period: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every pair of bodies (a free grain and a grain, free or fixed) with gap ``D < d_max``.

    Parameters
    ----------
    centres : ndarray, shape (n, dim)
        Free grains first, then fixed grains.
    radii : ndarray, shape (n,)
    n_free : int
        The free grains (a pair of two fixed grains is not looked for).
    d_max : float
        Detection distance (length).
    reach : float
        ``2 r_max + d_max`` (length), at least the centre distance of a pair with ``D < d_max``.
    period : float
        The period along x (0: none), more than ``2 reach`` (the minimum image is unique).

    Returns
    -------
    body_a, body_b, gaps, normals
        Shapes (k,), (k,), (k,), (k, dim), sorted by ``a``, then ``b``: ``b`` a free grain and
        ``a`` the other (the lower numbered where both are free), the gap ``|x_b - x_a| - r_a - r_b``
        (the minimum image along a period) and the unit normal from ``a`` to ``b``.
    """
    n, dim = centres.shape
    periodic = period > 0.0
    lower = np.empty(dim)
    extent = np.empty(dim)
    for d in range(dim):
        lower[d] = centres[:, d].min() if n else 0.0
        extent[d] = centres[:, d].max() - lower[d] if n else 0.0
    size, limit = reach, CELLS_PER_GRAIN * n + 64
    cells = np.empty(dim)
    while True:                              # reach-wide cells, widened where too many
        for d in range(dim):
            cells[d] = max(1.0, period // size) if periodic and d == 0 else extent[d] // size + 1.0
        total = np.prod(cells)
        if total <= limit:
            break
        size *= max(1.01, (total / limit) ** (1.0 / dim))
    counts = cells.astype(np.int64)
    width = np.empty(dim)
    for d in range(dim):
        width[d] = period / counts[d] if periodic and d == 0 else size
    stride = np.ones(dim, dtype=np.int64)
    for d in range(1, dim):
        stride[d] = stride[d - 1] * counts[d - 1]
    key = np.zeros(n, dtype=np.int64)
    for i in range(n):
        for d in range(dim):
            x = centres[i, d]
            if periodic and d == 0:
                x -= period * np.floor(x / period)
                at = int(x / width[d])
            else:
                at = int((x - lower[d]) / width[d])
            key[i] += min(max(at, 0), counts[d] - 1) * stride[d]
    first, members = _counting_order(key, np.prod(counts))     # each cell's centres
    capacity = 4 * n + 16
    body_a = np.empty(capacity, dtype=np.int64)
    body_b = np.empty(capacity, dtype=np.int64)
    gaps = np.empty(capacity)
    normals = np.empty((capacity, dim))
    delta = np.empty(dim)
    place = np.empty(dim, dtype=np.int64)
    visited = np.empty(3**dim, dtype=np.int64)
    # a pair's centres are at most reach apart: a candidate farther apart than this is not one
    # (the margin covers the rounding of its square, so that the gap test alone decides the others)
    farthest = reach * reach * (1.0 + 1e-12)
    found = 0
    for here in range(first.size - 1):
        if first[here] == first[here + 1]:
            continue
        rest = here
        for d in range(dim):                 # the cell's place along each axis
            place[d] = rest % counts[d]
            rest //= counts[d]
        n_visited = 0
        for code in range(3**dim):           # each pair of neighbouring cells once, from the first
            near, inside = 0, True
            for d in range(dim):
                at = place[d] + (code // 3**d) % 3 - 1
                if periodic and d == 0:
                    at %= counts[0]
                elif at < 0 or at >= counts[d]:
                    inside = False
                near += at * stride[d]
            if not inside or near < here or near in visited[:n_visited]:
                continue                     # (fewer than three cells along a period: one twice)
            visited[n_visited] = near
            n_visited += 1
            for slot in range(first[here], first[here + 1]):
                start = slot + 1 if near == here else first[near]
                for other in range(start, first[near + 1]):
                    i, j = members[slot], members[other]
                    if j < i:
                        i, j = j, i
                    if i >= n_free:          # two fixed grains
                        continue
                    square = 0.0
                    for d in range(dim):
                        delta[d] = centres[j, d] - centres[i, d]
                    if periodic and abs(delta[0]) > 0.5 * period:   # the minimum image
                        delta[0] -= period * np.rint(delta[0] / period)
                    for d in range(dim):
                        square += delta[d] * delta[d]
                    if square > farthest:
                        continue
                    distance = np.sqrt(square)
                    gap = distance - radii[i] - radii[j]
                    if not gap < d_max:
                        continue
                    if found == capacity:
                        capacity *= 2
                        body_a, body_b = _grown(body_a, capacity), _grown(body_b, capacity)
                        gaps, normals = _grown(gaps, capacity), _grown(normals, capacity)
                    fixed = j >= n_free               # oriented so that b is free
                    body_a[found], body_b[found] = (j, i) if fixed else (i, j)
                    gaps[found] = gap
                    for d in range(dim):
                        normals[found, d] = (-delta[d] if fixed else delta[d]) / distance
                    found += 1
    return _by_bodies(body_a[:found], body_b[:found], gaps[:found], normals[:found], n)


@numba.njit(cache=True)
def _by_bodies(body_a: np.ndarray, body_b: np.ndarray, gaps: np.ndarray, normals: np.ndarray,
               n_bodies: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairs sorted by ``a``, then ``b`` (by their pair keys): counted by ``a``, each
    ``a``'s few pairs then sorted by insertion."""
    start, order = _counting_order(body_a, n_bodies)
    for a in range(n_bodies):
        for slot in range(start[a] + 1, start[a + 1]):
            pair = order[slot]
            before = slot
            while before > start[a] and body_b[order[before - 1]] > body_b[pair]:
                order[before] = order[before - 1]
                before -= 1
            order[before] = pair
    return body_a[order], body_b[order], gaps[order], normals[order]


@numba.njit(cache=True)
def _counting_order(keys: np.ndarray, n_keys: int) -> tuple[np.ndarray, np.ndarray]:
    """``keys``' places (``keys``: integers in ``[0, n_keys)``) by increasing key, in their own
    order within a key (a counting sort), and where each key's run of them starts: ``(start,
    order)``, shapes (n_keys + 1,) and (keys.size,)."""
    start = np.zeros(n_keys + 1, dtype=np.int64)
    for key in keys:
        start[key + 1] += 1
    for key in range(n_keys):
        start[key + 1] += start[key]
    filled = start[:-1].copy()
    order = np.empty(keys.size, dtype=np.int64)
    for place in range(keys.size):
        order[filled[keys[place]]] = place
        filled[keys[place]] += 1
    return start, order


@numba.njit(cache=True)
def _grown(array: np.ndarray, capacity: int) -> np.ndarray:
    """``array`` copied into a longer one (``capacity`` rows; the rest not set)."""
    out = np.empty((capacity,) + array.shape[1:], dtype=array.dtype)
    out[: array.shape[0]] = array
    return out
