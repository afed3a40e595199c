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
elements whose rows all lie in the new one. Rows known to share their neighbours (a contact's two
rows of a 2D block) can be given as groups, supervariables from the start
(:func:`grouped_minimum_degree`). Its integers are 32-bit: the same orders in 11 % less
time than with 64-bit ones (195 against 220 ms for the 43 blocks of three 12 000-grain gluey steps,
docs/records/benchmarks.md). The lists hold unsigned ones (no wrap-around check on an index read
from them), and a row's fields are one record (:data:`KIND` and the others), not an array each:
on blocks of 10^5-grain gluey steps (150 000 rows) the elimination jumps all over the rows, and
with one cache line a row instead of one a field the orders took 0.7 of the time, 0.84 on the
blocks of 10 000-grain steps (docs/records/benchmarks.md, "the minimum-degree order postordered
along its assembly tree").

The order is returned postordered: rearranged so that each subtree of its elimination tree is a
contiguous run of places ending at its root. Any order that keeps the tree's parents after their
children has the same factor pattern up to relabelling, so the fill is unchanged; but the columns
that update a column now lie next to it in memory, where the minimum degree picks its pivots all
over the graph. On the blocks of 10^5-grain gluey flows (150 000 rows) the permutation, the static
patterns and the static LU together took 2.6 times less time (docs/records/benchmarks.md, "the
minimum-degree order postordered"). The tree is the elimination's own assembly tree, each pivot's
element a child of the element that absorbed it (its supervariables' rows a chain), as
SuiteSparse's AMD postorders: no pass over the pattern after the elimination. Against the
elimination tree found afresh from the pattern (Liu's algorithm), the same fill on the blocks of
10 000-grain gluey steps in a quarter less time for the whole order (docs/records/benchmarks.md,
"the minimum-degree order postordered along its assembly tree").
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
def approximate_minimum_degree(pointers: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """An elimination order of a square ``A`` that keeps the fill of its factors low: the
    approximate minimum degree of ``A + A^T``'s pattern, postordered along its assembly tree
    (module docstring).

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
    weights = np.ones(pointers.size - 1, dtype=np.int32)
    pivots, first_member, next_member, absorber = _pivots(pointers, rows, weights)
    return _rows_of(_assembly_postorder(pivots, absorber), first_member, next_member)


@numba.njit(cache=True)
def grouped_minimum_degree(pointers: np.ndarray, rows: np.ndarray, group: np.ndarray,
                           weights: np.ndarray) -> np.ndarray:
    """:func:`approximate_minimum_degree` of a square ``A`` whose rows come in groups eliminated
    together, from the pattern of its groups: the rows of each group one after the other.

    A contact's two rows of a 2D Newton block (its normal and its sticking tangential row) have
    the same neighbours, so the elimination would merge them into one supervariable once it
    compared them; given as one group of weight 2 from the start, the graph the elimination
    walks has 21-30 % fewer rows and 41-53 % fewer entries on the fresh blocks of 10 000-grain
    gluey steps (docs/records/benchmarks.md, "the minimum-degree order by contacts").

    Parameters
    ----------
    pointers, rows : ndarray of int
        The part above the diagonal of the groups' pattern (``g`` next to ``h`` where a row of
        ``g`` has an entry in a column of ``h`` or the other way round), column ``h`` holding
        the groups ``g < h`` once each (:func:`~lubcontact.solvers.kernels.grouped_pattern`).
    group : ndarray of int, shape (n,)
        Each row's group, ``0 .. weights.size - 1``.
    weights : ndarray of int32, shape (n_groups,)
        The rows in each group (each at least 1).

    Returns
    -------
    ndarray of int64, shape (n,)
        The rows in elimination order, each group's in increasing row.

    Raises
    ------
    ValueError
        Where the groups do not match the pattern and the weights: a weight below 1, weights
        not one a column of the pattern, or rows counted in ``group`` other than ``weights``
        says (numba does not check the bounds of what they index).
    """
    counted = np.zeros(weights.size, dtype=np.int64)
    for i in range(group.size):
        if not 0 <= group[i] < weights.size:
            raise ValueError("grouped_minimum_degree: a group beyond the weights")
        counted[group[i]] += 1
    if weights.size != pointers.size - 1:
        raise ValueError("grouped_minimum_degree: not a weight for each column of the pattern")
    for g in range(weights.size):
        if weights[g] < 1 or counted[g] != weights[g]:
            raise ValueError("grouped_minimum_degree: a weight below 1 or other than its rows")
    pivots, first_member, next_member, absorber = _pivots(pointers, rows, weights)
    groups = _rows_of(_assembly_postorder(pivots, absorber), first_member, next_member)
    start = np.empty(weights.size, dtype=np.int64)          # each group's first place
    place = 0
    for g in groups:
        start[g] = place
        place += weights[g]
    order = np.empty(group.size, dtype=np.int64)
    for i in range(group.size):                 # in increasing row: each group's rows in order
        order[start[group[i]]] = i
        start[group[i]] += 1
    return order


VARIABLE, ELEMENT, GONE = 0, 1, 2
"""A row's kind in :func:`_pivots`: a (super)variable still to eliminate, an element (an eliminated
pivot standing for its clique), or neither (absorbed, merged or mass-eliminated)."""

KIND, WEIGHT, MARK, TAG, OUTSIDE, DEGREE, START, LENGTH = 0, 1, 2, 3, 4, 5, 6, 7
ELEMENTS, AFTER, BEFORE, NEW_DEGREE, HASH, BUCKET_NEXT = 8, 9, 10, 11, 12, 13
"""The fields of a row's record in :func:`_pivots` (``state[row, FIELD]``): its kind; the rows a
(super)variable stands for (0 once merged); its mark (the pivot's stamp where it is in the new
element) and its element's tag (the stamp at which ``OUTSIDE`` was set); ``|L_e \\ L_p|`` for an
element next to the new one; its approximate external degree (an element's: its weight); where
its list starts in the lists and how long it is; how many of its list's entries are elements
(they come first); its neighbours in the list of rows of its degree; its degree and hash after
the pivot; the next row in its hash bucket. One record of 16 32-bit fields a row, 64 bytes: what
the elimination reads of a neighbour comes in one cache line, where with an array a field each
every field read was a miss of its own (module docstring)."""

STAMP_LIMIT = 2**30
"""The marks and tags are 32-bit: where the stamp (one a pivot, one a row compared for a
supervariable, at most n a pivot) reaches this, they are cleared and it starts again."""


@numba.njit(cache=True)
def _compacted(lists: np.ndarray, state: np.ndarray, room: int) -> tuple[np.ndarray, int]:
    """The lists of the rows not ``GONE`` (``state``: :data:`KIND`) moved to the front of a new
    array with ``room`` more entries; their :data:`START` updated in place. Returns
    ``(lists, free)``."""
    total = 0
    for i in range(state.shape[0]):
        if state[i, KIND] != GONE:
            total += state[i, LENGTH]
    moved = np.empty(total + room, dtype=np.uint32)
    free = 0
    for i in range(state.shape[0]):
        if state[i, KIND] != GONE:
            first = state[i, START]
            for k in range(state[i, LENGTH]):
                moved[free + k] = lists[first + k]
            state[i, START] = free
            free += state[i, LENGTH]
    return moved, free


@numba.njit(cache=True)
def _pivots(pointers: np.ndarray, rows: np.ndarray, weights: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The approximate minimum degree's pivots (:func:`approximate_minimum_degree`'s arguments
    and errors; ``weights``: the rows each of the pattern's rows stands for from the start, a
    supervariable given, :func:`grouped_minimum_degree`), in the order it picked them.

    Returns
    -------
    tuple of ndarray of int32
        ``(pivots, first_member, next_member, absorber)``: the pivots (supervariables, each
        named by one of the pattern's rows, which are groups where ``weights`` are not all 1);
        the pattern's rows each stands for, linked from ``first_member[p]`` through
        ``next_member`` (-1 ends the chain), its own row first; per pivot, the pivot whose
        element absorbed its element (-1: none, a root of the assembly tree).
    """
    if 4 * rows.size + 4 * pointers.size + 16 >= 2**30:
        raise ValueError("approximate_minimum_degree: more than 2^30 entries in the lists "
                         "(32-bit)")
    pointers, neighbours = _both_triangles(pointers, rows)
    n = pointers.size - 1
    if n == 0:
        empty = np.empty(0, dtype=np.int32)
        return empty, empty, empty, empty
    represented = 0             # the rows the pattern's rows stand for: degrees count them
    for i in range(n):
        represented += weights[i]
    lists = np.empty(2 * neighbours.size + 4 * n + 16, dtype=np.uint32)
    lists[:neighbours.size] = neighbours
    state = np.zeros((n, 16), dtype=np.int32)     # a record a row: the fields above
    for i in range(n):
        state[i, START] = pointers[i]
        state[i, LENGTH] = pointers[i + 1] - pointers[i]
        degree = 0
        for k in range(pointers[i], pointers[i + 1]):
            degree += weights[neighbours[k]]
        state[i, DEGREE] = degree
        state[i, WEIGHT] = weights[i]
        state[i, MARK] = -1
        state[i, TAG] = -1
        state[i, AFTER] = -1
        state[i, BEFORE] = -1
        state[i, BUCKET_NEXT] = -1
    free = neighbours.size
    head = np.full(represented + 1, -1, dtype=np.int32)   # rows by degree, doubly linked
    for i in range(n):
        d = state[i, DEGREE]
        state[i, AFTER] = head[d]
        if head[d] >= 0:
            state[head[d], BEFORE] = i
        head[d] = i
    stamp = 0
    bucket_head = np.full(n, -1, dtype=np.int32)
    copy = np.empty(n + 1, dtype=np.uint32)
    first_member = np.arange(n, dtype=np.int32)     # the rows a (super)variable stands for,
    last_member = np.arange(n, dtype=np.int32)      # linked
    next_member = np.full(n, -1, dtype=np.int32)
    pivots = np.empty(n, dtype=np.int32)
    absorber = np.full(n, -1, dtype=np.int32)
    n_pivots = eliminated = least = 0
    while eliminated < represented:
        while least <= represented and head[least] < 0:
            least += 1
        if least > represented:
            raise ValueError("approximate_minimum_degree: no row left of any degree")
        p = head[least]
        head[least] = state[p, AFTER]
        if state[p, AFTER] >= 0:
            state[state[p, AFTER], BEFORE] = -1
        eliminated += state[p, WEIGHT]
        state[p, KIND] = ELEMENT
        pivots[n_pivots] = p
        n_pivots += 1
        if stamp >= STAMP_LIMIT:
            state[:, MARK] = -1
            state[:, TAG] = -1
            stamp = 0
        stamp += 1
        state[p, MARK] = stamp
        # the new element's rows, at the end of the lists
        bound = state[p, LENGTH] - state[p, ELEMENTS]
        for k in range(state[p, ELEMENTS]):
            bound += state[lists[state[p, START] + k], LENGTH]
        if free + bound > lists.size:
            lists, free = _compacted(lists, state, bound + lists.size // 2)
        new = free
        size = new_weight = 0
        for k in range(state[p, LENGTH]):
            adjacent = lists[state[p, START] + k]
            if k < state[p, ELEMENTS]:
                if state[adjacent, KIND] != ELEMENT:
                    continue
                for q in range(state[adjacent, START], state[adjacent, START] + state[adjacent, LENGTH]):
                    j = lists[q]
                    if state[j, KIND] == VARIABLE and state[j, WEIGHT] > 0 and state[j, MARK] != stamp:
                        state[j, MARK] = stamp
                        lists[new + size] = j
                        size += 1
                        new_weight += state[j, WEIGHT]
                state[adjacent, KIND] = GONE         # absorbed by the new element
                absorber[adjacent] = p
            elif state[adjacent, KIND] == VARIABLE and state[adjacent, WEIGHT] > 0 \
                    and state[adjacent, MARK] != stamp:
                state[adjacent, MARK] = stamp
                lists[new + size] = adjacent
                size += 1
                new_weight += state[adjacent, WEIGHT]
        free += size
        state[p, START], state[p, LENGTH], state[p, ELEMENTS] = new, size, 0
        for q in range(new, new + size):            # out of the degree lists
            i = lists[q]
            if state[i, BEFORE] >= 0:
                state[state[i, BEFORE], AFTER] = state[i, AFTER]
            else:
                head[state[i, DEGREE]] = state[i, AFTER]
            if state[i, AFTER] >= 0:
                state[state[i, AFTER], BEFORE] = state[i, BEFORE]
            state[i, AFTER] = state[i, BEFORE] = -1
        for q in range(new, new + size):            # |L_e \ L_p|
            i = lists[q]
            for k in range(state[i, START], state[i, START] + state[i, ELEMENTS]):
                e = lists[k]
                if state[e, KIND] != ELEMENT or e == p:
                    continue
                if state[e, TAG] != stamp:
                    state[e, TAG] = stamp
                    state[e, OUTSIDE] = state[e, DEGREE]
                state[e, OUTSIDE] -= state[i, WEIGHT]
        for q in range(new, new + size):            # each row's lists pruned, its degree
            i = lists[q]
            s, count, n_elements = state[i, START], state[i, LENGTH], state[i, ELEMENTS]
            for k in range(count):
                copy[k] = lists[s + k]
            lists[s] = p                            # the new element first
            end = s + 1
            external = 0
            hashed = p
            for k in range(n_elements):
                e = copy[k]
                if state[e, KIND] != ELEMENT or e == p:
                    continue
                if state[e, OUTSIDE] <= 0:          # all its rows in L_p: absorbed
                    state[e, KIND] = GONE
                    absorber[e] = p
                    continue
                lists[end] = e
                end += 1
                external += state[e, OUTSIDE]
                hashed += e
            kept_elements = end - s
            for k in range(n_elements, count):
                j = copy[k]
                if state[j, KIND] != VARIABLE or state[j, WEIGHT] == 0 or state[j, MARK] == stamp:
                    continue
                lists[end] = j
                end += 1
                external += state[j, WEIGHT]
                hashed += j
            if end - s > count:
                raise ValueError("approximate_minimum_degree: a list grew")
            state[i, LENGTH], state[i, ELEMENTS] = end - s, kept_elements
            if external == 0 and kept_elements == 1:    # next to the new element only
                state[p, WEIGHT] += state[i, WEIGHT]
                eliminated += state[i, WEIGHT]
                next_member[last_member[p]] = first_member[i]
                last_member[p] = last_member[i]
                state[i, WEIGHT] = 0
                state[i, KIND] = GONE
                continue
            others = new_weight - state[i, WEIGHT]
            d = min(state[i, DEGREE] + others, external + others)
            state[i, NEW_DEGREE] = min(d, represented - eliminated - state[i, WEIGHT])
            state[i, HASH] = hashed % n
        for q in range(new, new + size):            # supervariables: the same lists
            i = lists[q]
            if state[i, WEIGHT] > 0:
                state[i, BUCKET_NEXT] = bucket_head[state[i, HASH]]
                bucket_head[state[i, HASH]] = i
        for q in range(new, new + size):
            b = state[lists[q], HASH]
            while bucket_head[b] >= 0:
                i = bucket_head[b]
                bucket_head[b] = state[i, BUCKET_NEXT]
                if state[i, WEIGHT] == 0 or bucket_head[b] < 0:     # no other row left to compare
                    continue
                stamp += 1
                for k in range(state[i, START], state[i, START] + state[i, LENGTH]):
                    state[lists[k], MARK] = stamp
                previous, j = -1, bucket_head[b]
                while j >= 0:
                    following = state[j, BUCKET_NEXT]
                    same = state[j, WEIGHT] > 0 and state[j, LENGTH] == state[i, LENGTH] \
                        and state[j, ELEMENTS] == state[i, ELEMENTS]
                    if same:
                        for k in range(state[j, START], state[j, START] + state[j, LENGTH]):
                            if state[lists[k], MARK] != stamp:
                                same = False
                                break
                    if same:                        # j merged into i, out of the bucket
                        state[i, WEIGHT] += state[j, WEIGHT]
                        state[i, NEW_DEGREE] -= state[j, WEIGHT]
                        next_member[last_member[i]] = first_member[j]
                        last_member[i] = last_member[j]
                        state[j, WEIGHT] = 0
                        state[j, KIND] = GONE
                        if previous >= 0:
                            state[previous, BUCKET_NEXT] = following
                        else:
                            bucket_head[b] = following
                    else:
                        previous = j
                    j = following
        count = total = 0
        for q in range(new, new + size):            # the element's rows, back by degree
            i = lists[q]
            if state[i, WEIGHT] == 0:
                continue
            lists[new + count] = i
            count += 1
            total += state[i, WEIGHT]
            d = max(state[i, NEW_DEGREE], 0)
            state[i, DEGREE] = d
            state[i, AFTER], state[i, BEFORE] = head[d], -1
            if head[d] >= 0:
                state[head[d], BEFORE] = i
            head[d] = i
            least = min(least, d)
        state[p, LENGTH], state[p, DEGREE] = count, total
    return pivots[:n_pivots], first_member, next_member, absorber


@numba.njit(cache=True)
def _assembly_postorder(pivots: np.ndarray, absorber: np.ndarray) -> np.ndarray:
    """``pivots`` (:func:`_pivots`) in a postorder of their assembly tree: each subtree a
    contiguous run ending at its root, children in the order they were picked, roots too."""
    first_child = np.full(absorber.size, -1, dtype=np.int32)
    next_sibling = np.full(absorber.size, -1, dtype=np.int32)
    for t in range(pivots.size - 1, -1, -1):
        child = pivots[t]
        if absorber[child] >= 0:
            next_sibling[child] = first_child[absorber[child]]
            first_child[absorber[child]] = child
    post = np.empty(pivots.size, dtype=np.int32)
    stack = np.empty(pivots.size, dtype=np.int32)
    count = 0
    for root in pivots:
        if absorber[root] >= 0:
            continue
        top = 0
        stack[0] = root
        while top >= 0:
            pivot = stack[top]
            child = first_child[pivot]
            if child == -1:                         # every child done: the pivot follows them
                top -= 1
                post[count] = pivot
                count += 1
            else:
                first_child[pivot] = next_sibling[child]
                top += 1
                stack[top] = child
    return post


@numba.njit(cache=True)
def _rows_of(pivots: np.ndarray, first_member: np.ndarray, next_member: np.ndarray
             ) -> np.ndarray:
    """The rows ``pivots`` stand for (:func:`_pivots`), pivot after pivot: an elimination order,
    int64, shape (n,)."""
    order = np.empty(first_member.size, dtype=np.int64)
    k = 0
    for pivot in pivots:
        row = first_member[pivot]
        while row >= 0:
            order[k] = row
            k += 1
            row = next_member[row]
    return order
