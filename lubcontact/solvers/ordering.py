"""A fill-reducing elimination order for sparse factorisations: approximate minimum degree
(numba, imported on first use).

newton-ac factorises an active block of its 2D Newton systems afresh where the rows changed too
much for the last block's order to carry over (``factorisations.Factorisations``). SuperLU's
minimum-degree ordering was about 7 of its 19 ms on the 20 000-row blocks of a 12 000-grain gluey
flow, and SuperLU gives no order without factorising; this order (5.5-7.3 ms), then the static
LU of those blocks, took 12-15 ms against SuperLU's 17-20, with 5 % fewer factor entries
(docs/records/benchmarks.md, "a fresh order by approximate minimum degree").

The method is the approximate minimum degree of Amestoy, Davis and Duff (SIAM J. Matrix Anal.
Appl. 17, 1996), written here from its description: the graph of the remaining rows is kept as a
quotient graph, each eliminated row an *element* standing for the clique it created, so no fill
edge is ever stored; each row keeps its list of elements and of the rows still adjacent to it,
and that list never grows (it gains the new element and loses the pivot or an element the new
one absorbed), so the lists are pruned in place. Per pivot (a row of least approximate degree):
the new element's rows are gathered from the pivot's elements (absorbed) and rows; for each
element ``e`` next to them ``|L_e \\ L_p|`` is counted; each row's degree is bounded by its old
degree plus the new element's, and by its rows plus the new element's plus those counts; rows
whose only neighbour is the new element are eliminated with the pivot (mass elimination), and
rows with the same lists are merged (supervariables, found by a hash). Not implemented: the
special handling of dense rows (none in contact networks; a row next to all others makes the
order quadratic in time: 0.4 s for a 20 000-row star) and aggressive absorption beyond the
elements whose rows all lie in the new one. The lists and the per-row arrays hold 32-bit
integers (the marks 64-bit: they count up by pivot and by candidate supervariable): the same
orders in 11 % less time than with 64-bit ones (195 against 220 ms for the 43 blocks of three
12 000-grain gluey steps, docs/records/benchmarks.md).

The order is returned postordered: rearranged along its elimination tree (Liu's algorithm) so
that each subtree is a contiguous run of places ending at its root. Any order that keeps the tree's
parents after their children has the same factor pattern up to relabelling, so the fill is
unchanged; but the columns that update a column now lie next to it in memory, where the minimum
degree picks its pivots all over the graph. On the blocks of 10^5-grain gluey flows (150 000
rows) the permutation, the static patterns and the static LU together took 2.6 times less time
(docs/records/benchmarks.md, "the minimum-degree order postordered").
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _both_triangles(pointers: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The adjacency of a symmetric pattern given by its part above the diagonal (column ``k``
    holding the rows ``i < k``, once each), with both triangles: ``(pointers, neighbours)``."""
    n = pointers.size - 1
    counts = np.zeros(n + 1, dtype=np.int32)
    for k in range(n):
        counts[k + 1] += pointers[k + 1] - pointers[k]
        for e in range(pointers[k], pointers[k + 1]):
            counts[rows[e] + 1] += 1
    for k in range(n):
        counts[k + 1] += counts[k]
    neighbours = np.empty(counts[n], dtype=np.int32)
    filled = counts[:-1].copy()
    for k in range(n):
        for e in range(pointers[k], pointers[k + 1]):
            i = rows[e]
            neighbours[filled[k]] = i
            filled[k] += 1
            neighbours[filled[i]] = k
            filled[i] += 1
    return counts, neighbours


@numba.njit(cache=True)
def _compacted(lists: np.ndarray, start: np.ndarray, length: np.ndarray, live: np.ndarray,
               room: int) -> tuple[np.ndarray, int]:
    """The live lists (``live``) of ``lists`` moved to the front of a new array with ``room``
    more entries; ``start`` updated in place. Returns ``(lists, free)``."""
    total = 0
    for i in range(start.size):
        if live[i]:
            total += length[i]
    moved = np.empty(total + room, dtype=np.int32)
    free = 0
    for i in range(start.size):
        if live[i]:
            for k in range(length[i]):
                moved[free + k] = lists[start[i] + k]
            start[i] = free
            free += length[i]
    return moved, free


@numba.njit(cache=True)
def approximate_minimum_degree(pointers: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """An elimination order of a square ``A`` that keeps the fill of its factors low: the
    approximate minimum degree of ``A + A^T``'s pattern (module docstring).

    Parameters
    ----------
    pointers, rows : ndarray of int
        The part of ``A + A^T``'s pattern above the diagonal, column ``k`` holding the rows
        ``i < k`` once each (:func:`~lubcontact.solvers.kernels.symmetrised_pattern`).

    Returns
    -------
    ndarray of int64, shape (n,)
        The rows in elimination order: factorise ``A[order][:, order]``.

    Raises
    ------
    ValueError
        Where the lists (both triangles and four entries a row) would hold 2^30 entries or
        more: their places are 32-bit; or where no row is left to pick (not met on a valid
        pattern).
    """
    if 4 * rows.size + 4 * pointers.size + 16 >= 2**30:
        raise ValueError("approximate_minimum_degree: more than 2^30 entries in the lists "
                         "(32-bit)")
    pointers, neighbours = _both_triangles(pointers, rows)
    n = pointers.size - 1
    if n == 0:
        return np.empty(0, dtype=np.int64)
    VARIABLE, ELEMENT, GONE = 0, 1, 2
    lists = np.empty(2 * neighbours.size + 4 * n + 16, dtype=np.int32)
    start = pointers[:-1].copy()
    length = pointers[1:] - pointers[:-1]
    lists[:neighbours.size] = neighbours
    free = neighbours.size
    elements = np.zeros(n, dtype=np.int32)     # a row's list: its elements first, then rows
    kind = np.zeros(n, dtype=np.int32)
    weight = np.ones(n, dtype=np.int32)         # rows a (super)variable stands for; 0 once merged
    degree = length.copy()                      # approximate external degree; an element's weight
    head = np.full(n + 1, -1, dtype=np.int32)   # rows by degree, doubly linked
    after = np.full(n, -1, dtype=np.int32)
    before = np.full(n, -1, dtype=np.int32)
    for i in range(n):
        d = degree[i]
        after[i] = head[d]
        if head[d] >= 0:
            before[head[d]] = i
        head[d] = i
    mark = np.full(n, -1, dtype=np.int64)
    stamp = 0
    outside_tag = np.full(n, -1, dtype=np.int64)
    outside = np.zeros(n, dtype=np.int32)       # |L_e \ L_p| for the elements next to L_p
    new_degree = np.zeros(n, dtype=np.int32)
    hashes = np.zeros(n, dtype=np.int32)
    bucket_head = np.full(n, -1, dtype=np.int32)
    bucket_next = np.full(n, -1, dtype=np.int32)
    copy = np.empty(n + 1, dtype=np.int32)
    first_member = np.arange(n, dtype=np.int32)     # the rows a (super)variable stands for,
    last_member = np.arange(n, dtype=np.int32)      # linked
    next_member = np.full(n, -1, dtype=np.int32)
    pivots = np.empty(n, dtype=np.int32)
    n_pivots = eliminated = least = 0
    while eliminated < n:
        while least <= n and head[least] < 0:
            least += 1
        if least > n:
            raise ValueError("approximate_minimum_degree: no row left of any degree")
        p = head[least]
        head[least] = after[p]
        if after[p] >= 0:
            before[after[p]] = -1
        eliminated += weight[p]
        kind[p] = ELEMENT
        pivots[n_pivots] = p
        n_pivots += 1
        stamp += 1
        mark[p] = stamp
        # the new element's rows, at the end of the lists
        bound = length[p] - elements[p]
        for k in range(elements[p]):
            bound += length[lists[start[p] + k]]
        if free + bound > lists.size:
            lists, free = _compacted(lists, start, length, kind != GONE, bound + lists.size // 2)
        new = free
        size = new_weight = 0
        for k in range(length[p]):
            node = lists[start[p] + k]
            if k < elements[p]:
                if kind[node] != ELEMENT:
                    continue
                for q in range(start[node], start[node] + length[node]):
                    j = lists[q]
                    if kind[j] == VARIABLE and weight[j] > 0 and mark[j] != stamp:
                        mark[j] = stamp
                        lists[new + size] = j
                        size += 1
                        new_weight += weight[j]
                kind[node] = GONE                   # absorbed by the new element
            elif kind[node] == VARIABLE and weight[node] > 0 and mark[node] != stamp:
                mark[node] = stamp
                lists[new + size] = node
                size += 1
                new_weight += weight[node]
        free += size
        start[p], length[p], elements[p] = new, size, 0
        for q in range(new, new + size):            # out of the degree lists
            i = lists[q]
            if before[i] >= 0:
                after[before[i]] = after[i]
            else:
                head[degree[i]] = after[i]
            if after[i] >= 0:
                before[after[i]] = before[i]
            after[i] = before[i] = -1
        for q in range(new, new + size):            # |L_e \ L_p|
            i = lists[q]
            for k in range(start[i], start[i] + elements[i]):
                e = lists[k]
                if kind[e] != ELEMENT or e == p:
                    continue
                if outside_tag[e] != stamp:
                    outside_tag[e] = stamp
                    outside[e] = degree[e]
                outside[e] -= weight[i]
        for q in range(new, new + size):            # each row's lists pruned, its degree
            i = lists[q]
            s, count, n_elements = start[i], length[i], elements[i]
            for k in range(count):
                copy[k] = lists[s + k]
            lists[s] = p                            # the new element first
            end = s + 1
            external = 0
            hashed = p
            for k in range(n_elements):
                e = copy[k]
                if kind[e] != ELEMENT or e == p:
                    continue
                if outside[e] <= 0:                 # all its rows in L_p: absorbed
                    kind[e] = GONE
                    continue
                lists[end] = e
                end += 1
                external += outside[e]
                hashed += e
            kept_elements = end - s
            for k in range(n_elements, count):
                j = copy[k]
                if kind[j] != VARIABLE or weight[j] == 0 or mark[j] == stamp:
                    continue
                lists[end] = j
                end += 1
                external += weight[j]
                hashed += j
            if end - s > count:
                raise ValueError("approximate_minimum_degree: a list grew")
            length[i], elements[i] = end - s, kept_elements
            if external == 0 and kept_elements == 1:    # next to the new element only
                weight[p] += weight[i]
                eliminated += weight[i]
                next_member[last_member[p]] = first_member[i]
                last_member[p] = last_member[i]
                weight[i] = 0
                kind[i] = GONE
                continue
            d = min(degree[i] + new_weight - weight[i], external + new_weight - weight[i])
            new_degree[i] = min(d, n - eliminated - weight[i])
            hashes[i] = hashed % n
        for q in range(new, new + size):            # supervariables: the same lists
            i = lists[q]
            if weight[i] > 0:
                bucket_next[i] = bucket_head[hashes[i]]
                bucket_head[hashes[i]] = i
        for q in range(new, new + size):
            b = hashes[lists[q]]
            while bucket_head[b] >= 0:
                i = bucket_head[b]
                bucket_head[b] = bucket_next[i]
                if weight[i] == 0:
                    continue
                stamp += 1
                for k in range(start[i], start[i] + length[i]):
                    mark[lists[k]] = stamp
                previous, j = -1, bucket_head[b]
                while j >= 0:
                    following = bucket_next[j]
                    same = weight[j] > 0 and length[j] == length[i] \
                        and elements[j] == elements[i]
                    if same:
                        for k in range(start[j], start[j] + length[j]):
                            if mark[lists[k]] != stamp:
                                same = False
                                break
                    if same:                        # j merged into i, out of the bucket
                        weight[i] += weight[j]
                        new_degree[i] -= weight[j]
                        next_member[last_member[i]] = first_member[j]
                        last_member[i] = last_member[j]
                        weight[j] = 0
                        kind[j] = GONE
                        if previous >= 0:
                            bucket_next[previous] = following
                        else:
                            bucket_head[b] = following
                    else:
                        previous = j
                    j = following
        count = total = 0
        for q in range(new, new + size):            # the element's rows, back by degree
            i = lists[q]
            if weight[i] == 0:
                continue
            lists[new + count] = i
            count += 1
            total += weight[i]
            d = max(new_degree[i], 0)
            degree[i] = d
            after[i], before[i] = head[d], -1
            if head[d] >= 0:
                before[head[d]] = i
            head[d] = i
            least = min(least, d)
        length[p], degree[p] = count, total
    order = np.empty(n, dtype=np.int64)
    k = 0
    for t in range(n_pivots):
        row = first_member[pivots[t]]
        while row >= 0:
            order[k] = row
            k += 1
            row = next_member[row]
    return order[_postorder(elimination_tree(pointers, neighbours, order))]


@numba.njit(cache=True)
def elimination_tree(pointers: np.ndarray, neighbours: np.ndarray, order: np.ndarray
                     ) -> np.ndarray:
    """The elimination tree of a symmetric pattern factorised in ``order``: the parent of each
    place ``k`` is the first place after ``k`` whose row of the Cholesky factor ``L`` has an
    entry in column ``k`` (Liu's algorithm, with path compression).

    Parameters
    ----------
    pointers, neighbours : ndarray of int
        The pattern's adjacency, both triangles, no diagonal (:func:`_both_triangles`).
    order : ndarray of int64, shape (n,)
        The rows in elimination order.

    Returns
    -------
    ndarray of int64, shape (n,)
        ``parent[k]``, a place after ``k``, or -1 for a root; places, not rows.
    """
    n = order.size
    place = np.empty(n, dtype=np.int64)
    for k in range(n):
        place[order[k]] = k
    parent = np.full(n, -1, dtype=np.int64)
    ancestor = np.full(n, -1, dtype=np.int64)       # a shortcut towards the root found so far
    for k in range(n):
        row = order[k]
        for e in range(pointers[row], pointers[row + 1]):
            i = place[neighbours[e]]
            if i >= k:
                continue
            while ancestor[i] != -1 and ancestor[i] != k:   # up to the root of i's subtree
                following = ancestor[i]
                ancestor[i] = k
                i = following
            if ancestor[i] == -1:                   # that root joins k
                ancestor[i] = k
                parent[i] = k
    return parent


@numba.njit(cache=True)
def _postorder(parent: np.ndarray) -> np.ndarray:
    """The places of a forest (``parent``: :func:`elimination_tree`) in a postorder: each
    subtree a contiguous run ending at its root, children in increasing place, roots too."""
    n = parent.size
    first_child = np.full(n, -1, dtype=np.int64)
    next_sibling = np.full(n, -1, dtype=np.int64)
    for k in range(n - 1, -1, -1):
        if parent[k] >= 0:
            next_sibling[k] = first_child[parent[k]]
            first_child[parent[k]] = k
    post = np.empty(n, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    count = 0
    for root in range(n):
        if parent[root] >= 0:
            continue
        top = 0
        stack[0] = root
        while top >= 0:
            k = stack[top]
            child = first_child[k]
            if child == -1:                         # every child done: k follows them
                top -= 1
                post[count] = k
                count += 1
            else:
                first_child[k] = next_sibling[child]
                top += 1
                stack[top] = child
    return post
