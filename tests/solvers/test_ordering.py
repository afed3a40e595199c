"""The approximate-minimum-degree order of newton-ac's fresh 2D blocks (solvers.ordering)."""
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from lubcontact.problem import StepProblem
from lubcontact.solvers import factorisations, kernels, ordering
from lubcontact.solvers.newton import AlartCurnier
from lubcontact.solvers.ordering import _both_triangles, _pivots, _rows_of, approximate_minimum_degree


def grid(m: int) -> sp.csr_matrix:
    """The 5-point pattern of an m x m grid, with its diagonal."""
    line = sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], shape=(m, m))
    return (sp.kron(line, sp.identity(m)) + sp.kron(sp.identity(m), line)).tocsr()


def order_of(matrix: sp.spmatrix) -> np.ndarray:
    """The approximate-minimum-degree order of ``matrix`` (compressed), as newton-ac asks for it:
    from the part of its symmetrised pattern above the diagonal."""
    matrix = sp.csr_matrix(matrix)
    return approximate_minimum_degree(*kernels.symmetrised_pattern(matrix.indptr, matrix.indices))


def factor_entries(matrix: sp.spmatrix, order: np.ndarray) -> int:
    """Entries of the lower factor of ``matrix[order][:, order]`` without pivoting (its
    symmetrised pattern's Cholesky factor: kernels.static_pattern)."""
    permuted = sp.csc_matrix(matrix)[order][:, order].tocsc()
    permuted.sort_indices()
    return kernels.static_pattern(permuted.indptr.astype(np.int64),
                                  permuted.indices.astype(np.uint32))[1].size


def unit_weights(upper: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """A weight of one for each row of a pattern (``_pivots``' third argument: no group given)."""
    return np.ones(upper[0].size - 1, dtype=np.int32)


def is_permutation(order: np.ndarray, n: int) -> bool:
    return order.dtype == np.int64 and np.array_equal(np.sort(order), np.arange(n))


@pytest.mark.parametrize("pattern", ["empty", "one", "diagonal", "path", "star", "complete",
                                     "two_components", "twins", "asymmetric", "random",
                                     "compacted"])
def test_the_order_is_a_permutation_of_the_rows(pattern):
    """Every row once, whatever the pattern: none, isolated rows, a path, a star (one row next
    to all: mass elimination), a complete graph (one supervariable), two components, rows with
    the same neighbours (supervariables), an entry without its mirror, a random pattern, one
    whose element lists outgrow the first workspace (compacted once, 2 000 rows); with 32-bit
    indices as scipy stores them."""
    rng = np.random.default_rng(0)
    n = {"empty": 0, "one": 1, "compacted": 2000}.get(pattern, 40)
    patterns = {
        "empty": lambda: sp.csr_matrix((0, 0)), "one": lambda: sp.identity(1),
        "diagonal": lambda: sp.identity(n),
        "path": lambda: sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], shape=(n, n)),
        "star": lambda: sp.csr_matrix((np.ones(2 * n - 1),
                                       (np.r_[np.zeros(n, int), np.arange(1, n)],
                                        np.r_[np.arange(n), np.zeros(n - 1, int)]))),
        "complete": lambda: np.ones((n, n)),
        "two_components": lambda: sp.block_diag([grid(4), np.ones((24, 24))]),
        "twins": lambda: sp.kron(grid(4), sp.csr_matrix(np.ones((2, 2)))),
        "asymmetric": lambda: sp.triu(sp.random(n, n, 0.1, random_state=1)) + sp.identity(n),
        "random": lambda: sp.random(n, n, 0.05, random_state=2) + sp.identity(n),
        "compacted": lambda: sp.random(n, n, 0.0025, random_state=0),
    }
    matrix = patterns[pattern]()
    matrix = sp.csr_matrix(matrix)
    assert matrix.indices.dtype == np.int32
    order = order_of(matrix)
    assert is_permutation(order, matrix.shape[0])
    if pattern == "random":                     # a seeded random pattern of another density too
        dense = sp.csr_matrix(sp.random(n, n, 0.3, random_state=rng.integers(100)))
        assert is_permutation(order_of(dense), n)


def test_the_adjacency_has_both_triangles_of_the_symmetrised_pattern_without_its_diagonal():
    matrix = sp.csr_matrix(sp.random(30, 30, 0.1, random_state=3) + sp.identity(30))
    pointers, neighbours = _both_triangles(*kernels.symmetrised_pattern(matrix.indptr,
                                                                         matrix.indices))
    expected = ((abs(matrix) + abs(matrix.T)) != 0).astype(float).tolil()
    expected.setdiag(0)
    expected = sp.csr_matrix(expected)
    expected.eliminate_zeros()
    assert np.array_equal(pointers, expected.indptr)
    for row in range(30):
        assert np.array_equal(np.sort(neighbours[pointers[row]:pointers[row + 1]]),
                              expected.indices[expected.indptr[row]:expected.indptr[row + 1]])


def factor_tree(matrix: sp.spmatrix, order: np.ndarray) -> np.ndarray:
    """The elimination tree of ``matrix[order][:, order]``'s factor, read from its static pattern
    (kernels.static_pattern): the parent of each place is the least row below the diagonal of
    its column of ``L`` (-1: a root)."""
    permuted = sp.csc_matrix(matrix)[order][:, order].tocsc()
    permuted.sort_indices()
    lower_ptr, lower_idx, *_ = kernels.static_pattern(permuted.indptr.astype(np.int64),
                                                      permuted.indices.astype(np.uint32))
    return np.array([lower_idx[lower_ptr[k] + 1:lower_ptr[k + 1]].min()
                     if lower_ptr[k + 1] - lower_ptr[k] > 1 else -1 for k in range(order.size)])


def flow_system() -> tuple[AlartCurnier, np.ndarray, sp.csr_matrix, np.ndarray]:
    """A gluey + friction flow step's reduced Newton system (some 700 rows, the sparse lane) at
    its warm start, the weight 1e-3: ``(function, kept rows, block, right-hand side)``."""
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        problem = StepProblem.from_arrays(data).normalized()
        start = data["warm_start"] / problem.scaling.force
    function = AlartCurnier(problem)
    function.set_proximal(1e-3 * function.typical, start)
    phi, y, _ = function.residual(start)
    kept, block, rhs, *_ = function.reduced_system(y, phi)
    return function, kept, block, rhs


PATTERNS = {"grid": lambda: grid(30),
            "random": lambda: sp.random(150, 150, 0.02, random_state=4) + sp.identity(150),
            "two_components": lambda: sp.block_diag([grid(5), np.ones((9, 9))]),
            "twins": lambda: sp.kron(grid(6), sp.csr_matrix(np.ones((2, 2)))),
            "flow_block": lambda: flow_system()[2]}


@pytest.mark.parametrize("pattern", PATTERNS)
def test_the_postorder_keeps_the_fill_of_the_pivots_order(pattern):
    """Rearranged along the elimination's assembly tree, the order factorises with exactly as
    many entries as the rows in the order the pivots were picked, and is another order of them
    (a grid, a random pattern, two components, twin rows, a flow step's block)."""
    matrix = sp.csr_matrix(PATTERNS[pattern]())
    upper = kernels.symmetrised_pattern(matrix.indptr, matrix.indices)
    pivots, first_member, next_member, _ = _pivots(*upper, unit_weights(upper))
    picked = _rows_of(pivots, first_member, next_member)
    order = approximate_minimum_degree(*upper)
    assert is_permutation(picked, matrix.shape[0]) and is_permutation(order, matrix.shape[0])
    assert not np.array_equal(order, picked)             # the postorder moved rows
    assert factor_entries(matrix, order) == factor_entries(matrix, picked)


@pytest.mark.parametrize("pattern", ["grid", "flow_block"])
def test_the_order_is_postordered(pattern):
    """The minimum-degree order of a 30 x 30 grid and of a flow step's block comes postordered:
    each subtree of its factor's elimination tree a contiguous run of places ending at its root
    (the same fill; a column's descendants next to it in memory)."""
    matrix = PATTERNS[pattern]()
    order = order_of(matrix)
    parent = factor_tree(matrix, order)
    n = order.size
    assert np.all((parent == -1) | (parent > np.arange(n)))
    size = np.ones(n, dtype=int)                    # each subtree's rows (children come first)
    for k in range(n):
        if parent[k] >= 0:
            size[parent[k]] += size[k]
    for k in range(n):                              # the subtree of k: the places k - size + 1 .. k
        for j in range(k - size[k] + 1, k):
            while 0 <= j < k:                       # up the tree: a root (-1) ends it too
                j = parent[j]
            assert j == k


def test_the_order_keeps_the_fill_of_a_grid_near_superlu_s_minimum_degree():
    """On a 30 x 30 grid the factor's entries in this order are within 5 % of those in
    SuperLU's minimum-degree order (10 231 against 10 098) and far below the natural order's
    (27 029)."""
    matrix = grid(30)
    order = order_of(matrix)
    spd = (sp.identity(900) * 10 - matrix + sp.identity(900)).tocsc()
    superlu = spla.splu(spd, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                        options=dict(SymmetricMode=True))
    mine = factor_entries(matrix, order)
    theirs = factor_entries(matrix, np.argsort(superlu.perm_c))
    assert mine <= 1.05 * theirs
    assert mine <= 0.5 * factor_entries(matrix, np.arange(900))


def test_a_fresh_2d_block_is_factorised_in_this_order_by_the_static_lu(monkeypatch):
    """A gluey + friction flow step's reduced Newton block (some 700 rows, the sparse lane):
    factorised afresh in this order without pivoting, no SuperLU call, and solved to a
    backward error below 1e-13; its fill within 10 % of SuperLU's own order's (which took a
    third of SuperLU's factorisation on 20 000-row blocks)."""
    function, kept, block, rhs = flow_system()
    assert function.compiled_rows and not function.dense
    calls = []
    monkeypatch.setattr(factorisations.spla, "splu", lambda *args, **kwargs: calls.append(1))
    kept_factors = factorisations.Factorisations(carry=True)
    solved = kept_factors.solve(block, rhs, kept)
    assert calls == [] and kept_factors.pivoted == 0
    matrix, factors, order = kept_factors.kept[0]
    assert isinstance(factors, factorisations.StaticLU) and is_permutation(order, kept.size)
    scale = abs(block).max() * np.abs(solved).max() + np.abs(rhs).max()
    assert np.abs(block @ solved - rhs).max() <= 1e-13 * scale
    monkeypatch.undo()
    superlu = spla.splu(block.tocsc(), **factorisations.SPARSE_LU)
    assert factors.nnz <= 1.1 * superlu.nnz


def test_the_marks_cleared_at_the_stamp_limit_leave_the_pivots_as_they_are(monkeypatch):
    """The 32-bit marks and tags are cleared where the stamp reaches its limit: with a limit of
    5 (cleared every few pivots) the elimination of a 12 x 12 grid and of a pattern with twin
    rows (supervariables compared) picks the same pivots, merges and absorptions as without."""
    for matrix in (grid(12), sp.kron(grid(5), sp.csr_matrix(np.ones((2, 2))))):
        matrix = sp.csr_matrix(matrix)
        upper = kernels.symmetrised_pattern(matrix.indptr, matrix.indices)
        expected = _pivots(*upper, unit_weights(upper))
        monkeypatch.setattr(ordering, "STAMP_LIMIT", 5)
        cleared = _pivots.py_func(*upper, unit_weights(upper))  # reads the limit at run time
        monkeypatch.undo()
        for got, wanted in zip(cleared, expected):
            assert np.array_equal(got, wanted)


def test_contact_groups_pair_a_contact_s_two_rows_where_both_are_in_the_block():
    """Rows 0-3 are normal rows, 4-7 their contacts' tangential rows (4 with 0, ...); the block
    holds 0, 1, 3, 4, 5 and 9 (a row beyond ``partner``: none): 0 with 4 and 1 with 5 grouped,
    3 alone (7 is not in the block), 9 alone; groups numbered by their first rows."""
    partner = np.array([4, 5, 6, 7, 0, 1, 2, 3], dtype=np.int64)
    rows = np.array([0, 1, 3, 4, 5, 9], dtype=np.int64)
    group, weights = kernels.contact_groups(rows, partner)
    assert group.tolist() == [0, 1, 2, 0, 1, 3]
    assert weights.tolist() == [2, 2, 1, 1] and weights.dtype == np.int32


def test_the_grouped_pattern_is_the_groups_graph_of_the_symmetrised_pattern():
    """On a random 40-row pattern with rows paired at random (and some alone): each group next
    to exactly the groups one of its rows is next to in ``A + A^T``; with a group a row, the
    symmetrised pattern itself."""
    matrix = sp.csr_matrix(sp.random(40, 40, 0.08, random_state=5) + sp.identity(40))
    group = np.random.default_rng(6).permutation(np.r_[np.arange(15), np.arange(15), np.arange(15, 25)])
    pointers, rows = kernels.grouped_pattern(matrix.indptr, matrix.indices, group, 25)
    coupling = sp.csr_matrix((np.ones(40), (group, np.arange(40))), shape=(25, 40))
    expected = sp.triu(coupling @ (abs(matrix) + abs(matrix.T)) @ coupling.T, k=1).tocsc()
    assert np.array_equal(pointers, expected.indptr)
    for column in range(25):
        assert np.array_equal(np.sort(rows[pointers[column]:pointers[column + 1]]),
                              np.sort(expected.indices[expected.indptr[column]:expected.indptr[column + 1]]))
    identity = kernels.grouped_pattern(matrix.indptr, matrix.indices, np.arange(40), 40)
    for got, wanted in zip(identity, kernels.symmetrised_pattern(matrix.indptr, matrix.indices)):
        assert np.array_equal(got, wanted)


def test_the_grouped_order_eliminates_each_group_s_rows_together_with_the_fill_of_the_rows_order():
    """On the flow step's reduced block with its contacts' rows grouped (a normal row and its
    sticking tangential row): a permutation whose groups' rows are consecutive, each group's in
    increasing row, and its factor within 3 % of the order found row by row (on the fresh
    blocks of captured 10 000-grain gluey steps 0.988-1.019 times). On twin rows (a grid's rows
    doubled, each twin pair a group) exactly the fill of the rows' order, which merges the twins
    itself."""
    function, kept, block, _ = flow_system()
    group, weights = kernels.contact_groups(kept, function.factorisations.partner)
    assert weights.max() == 2 and weights.size < 0.9 * kept.size
    upper = kernels.grouped_pattern(block.indptr, block.indices, group, weights.size)
    order = ordering.grouped_minimum_degree(*upper, group, weights)
    assert is_permutation(order, kept.size)
    places = np.empty(kept.size, dtype=int)
    places[order] = np.arange(kept.size)
    for g in np.flatnonzero(weights == 2):
        first, second = np.flatnonzero(group == g)
        assert places[second] == places[first] + 1
    assert factor_entries(block, order) <= 1.03 * factor_entries(block, order_of(block))
    twins = sp.csr_matrix(sp.kron(grid(6), sp.csr_matrix(np.ones((2, 2)))))
    pairs = np.arange(72) // 2
    upper = kernels.grouped_pattern(twins.indptr, twins.indices, pairs, 36)
    grouped = ordering.grouped_minimum_degree(*upper, pairs, np.full(36, 2, dtype=np.int32))
    assert factor_entries(twins, grouped) == factor_entries(twins, order_of(twins))


def test_a_fresh_2d_block_is_ordered_by_contacts():
    """``Factorisations`` orders a fresh 2D block with each contact's two rows together: the
    order is the grouped one (:func:`grouped_minimum_degree` on the block's contact groups)."""
    function, kept, block, rhs = flow_system()
    kept_factors = factorisations.Factorisations(carry=True, partner=function.factorisations.partner)
    kept_factors.solve(block, rhs, kept)
    group, weights = kernels.contact_groups(kept, function.factorisations.partner)
    expected = ordering.grouped_minimum_degree(
        *kernels.grouped_pattern(block.indptr, block.indices, group, weights.size), group, weights)
    assert np.array_equal(kept_factors.kept[0][2], expected)


def test_weighted_degrees_may_exceed_the_pattern_s_rows():
    """Six groups of three rows, all next to each other: every degree is 15, above the six rows
    of the pattern; the elimination (plain Python, whose indexing is checked) still orders them,
    as one supervariable, every row once."""
    upper = kernels.symmetrised_pattern(*csr_arrays_of(np.ones((6, 6))))
    pivots, first_member, next_member, _ = _pivots.py_func(*upper, np.full(6, 3, dtype=np.int32))
    assert is_permutation(_rows_of(pivots, first_member, next_member), 6)


@pytest.mark.parametrize("case", ["swapped", "zero", "beyond", "short"])
def test_groups_that_do_not_match_their_weights_raise(case):
    """``grouped_minimum_degree`` refuses groups whose weights are not their rows' counts
    (``[2, 0, 2, 1, 0]`` given ``[2, 2, 1]``), a weight of 0, a group beyond the weights and
    weights fewer than the pattern's columns, where it would write past its arrays."""
    upper = kernels.symmetrised_pattern(*csr_arrays_of(sp.identity(3)))
    group, weights = np.array([2, 0, 2, 1, 0]), np.array([2, 1, 2], dtype=np.int32)
    group, weights = {"swapped": (group, np.array([2, 2, 1], dtype=np.int32)),
                      "zero": (np.array([0, 0, 1, 1, 1]), np.array([2, 3, 0], dtype=np.int32)),
                      "beyond": (np.array([0, 1, 2, 3, 0]), weights),
                      "short": (group, weights)}[case]
    if case == "short":
        upper = kernels.symmetrised_pattern(*csr_arrays_of(sp.identity(4)))
    with pytest.raises(ValueError, match="grouped_minimum_degree"):
        ordering.grouped_minimum_degree(*upper, group, weights)
    if case == "swapped":                         # the matching weights order every row
        matching = np.array([2, 1, 2], dtype=np.int32)
        assert is_permutation(ordering.grouped_minimum_degree(*upper, group, matching), 5)


def csr_arrays_of(matrix) -> tuple[np.ndarray, np.ndarray]:
    """The compressed pattern of ``matrix``: ``(indptr, indices)``."""
    matrix = sp.csr_matrix(matrix)
    return matrix.indptr, matrix.indices
