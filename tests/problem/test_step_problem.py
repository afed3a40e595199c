"""StepProblem's matrices: the scaled copies by value, the Delassus factor (and its transpose) with
duplicate entries."""
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from lubcontact.problem.cones import ConeKind, Cones
from lubcontact.problem.step import StepProblem, diagonal_scaled
from lubcontact.solvers.dual_data import jacobi_scale


@pytest.mark.parametrize("seed", range(20))
def test_diagonal_scaled_equals_the_scipy_products_and_leaves_its_input_alone(seed):
    rng = np.random.default_rng(seed)
    matrix = sp.random(30, 20, density=0.3, random_state=seed, format="csr")
    matrix.data[::7] = 0.0                                   # explicit zeros
    before = matrix.copy()
    rows, columns = rng.normal(size=30), rng.normal(size=20)
    rows[::5] = 0.0
    columns[::4] = 0.0
    for r, c in ((rows, columns), (rows, None), (None, columns), (None, None)):
        expected = sp.diags(np.ones(30) if r is None else r) @ matrix \
            @ sp.diags(np.ones(20) if c is None else c)
        scaled = diagonal_scaled(matrix, r, c)
        assert np.array_equal(scaled.toarray(), expected.toarray())
        assert np.all(scaled.data != 0.0)
    assert np.array_equal(matrix.data, before.data) and np.array_equal(matrix.indices, before.indices)


def test_a_jacobian_with_duplicate_entries_gives_the_same_delassus_and_jacobi_scale():
    """An entry stored as two halves (COO-style duplicates) is one entry of H: W and the Jacobi
    scale of the problem must not see the split (the scale summed the halves' squares)."""
    masses = np.random.default_rng(1).uniform(1.0, 2.0, 8)
    dense = sp.random(6, 8, density=0.5, random_state=2).toarray()
    rows, cols = np.nonzero(dense)
    split = sp.csr_matrix(_with_duplicates(dense[rows, cols], rows, cols, dense.shape),
                          shape=dense.shape)

    def problem(jacobian):
        return StepProblem(mass=masses, free_velocity=np.ones(8), jacobian=jacobian,
                           gaps=np.zeros(6), dt=0.1,
                           cones=Cones.frictionless(np.full(6, ConeKind.NONNEG), 1))

    whole, halves = problem(sp.csr_matrix(dense)), problem(split)
    assert halves.jacobian.nnz == 2 * whole.jacobian.nnz       # stored twice
    assert np.allclose(halves.delassus.toarray(), whole.delassus.toarray(), rtol=1e-14, atol=0)
    assert np.allclose(jacobi_scale(halves), jacobi_scale(whole), rtol=1e-14, atol=0)


@pytest.mark.parametrize("duplicates", [False, True])
def test_the_factor_transpose_is_the_factor_transposed_and_copies_share_it(duplicates):
    """``delassus_factor_transpose`` is ``L^T`` (``W = L^T L``) in CSR form, in physical units and
    normalised (where it is ``H`` itself, no copy), also from a Jacobian whose entries are stored
    twice as halves (which ``L^T`` keeps and a product sums); ``W`` is ``L^T L``; a copy with
    another shift shares it."""
    problem = _frictional_problem(11)
    if duplicates:
        source = problem.jacobian.tocoo()
        problem = replace(problem, jacobian=sp.csr_matrix(
            _with_duplicates(source.data, source.row, source.col, source.shape),
            shape=source.shape))
    for case in (problem, problem.normalized()):
        transpose, factor = case.delassus_factor_transpose, case.delassus_factor
        assert sp.isspmatrix_csr(transpose)
        assert np.allclose(transpose.toarray(), factor.T.toarray(), rtol=1e-15, atol=0)
        assert np.allclose(case.delassus.toarray(), (factor.T @ factor).toarray(), rtol=1e-14,
                           atol=1e-14 * abs(case.delassus).max())
        shifted = case.with_shift(np.zeros(case.n_contacts))
        assert shifted.delassus_factor_transpose is transpose
    scaled = problem.normalized()
    assert scaled.delassus_factor_transpose is scaled.jacobian
    assert problem.delassus_factor_transpose.nnz == problem.jacobian.nnz


def _with_duplicates(values, rows, cols, shape):
    """CSR arrays storing each entry as two halves, side by side in its row."""
    order = np.lexsort((cols, rows))
    rows, cols, values = rows[order], cols[order], values[order]
    data = np.repeat(values / 2, 2)
    indices = np.repeat(cols, 2)
    indptr = np.concatenate([[0], np.cumsum(2 * np.bincount(rows, minlength=shape[0]))])
    return data, indices, indptr


def _frictional_problem(seed: int, n_contacts: int = 12, n_dof: int = 30) -> StepProblem:
    """A random step problem with friction (one tangential row per contact) and moving obstacles."""
    rng = np.random.default_rng(seed)
    jacobian = sp.random(2 * n_contacts, n_dof, density=min(1.0, 6.0 / n_dof), random_state=seed,
                         format="csr")
    cones = Cones(kinds=np.full(n_contacts, ConeKind.COULOMB, dtype=np.int8),
                  mu=np.full(n_contacts, 0.3), tangential=np.arange(n_contacts), tangent_dim=1)
    return StepProblem(mass=rng.uniform(1.0, 3.0, n_dof), free_velocity=rng.normal(size=n_dof),
                       jacobian=jacobian, gaps=rng.uniform(0.0, 0.1, n_contacts), cones=cones,
                       dt=0.05, shift=rng.uniform(0.0, 0.01, n_contacts),
                       obstacle_offset=rng.uniform(-0.01, 0.01, 2 * n_contacts))


@pytest.mark.parametrize("seed, n_dof", [(0, 30), (1, 30), (2, 30), (3, 2000), (4, 2000)])
def test_a_normalised_problem_on_the_dense_lane_never_builds_its_sparse_jacobian(seed, n_dof):
    """The dense lane of a small problem (``dense_delassus`` first) computes ``b``, ``v(lam)``,
    ``g(v)`` and the gaps after the step from the dense Jacobian, also on copies with another
    shift: the sparse one, built on first use only, is never asked for. The values are those of
    the sparse products (to rounding); the Jacobian built when asked is the source's with its
    columns scaled, exactly; and the dense block holds only the columns that some row involves
    (2000 degrees of freedom, a few dozen of them in contact)."""
    problem = _frictional_problem(seed, n_dof=n_dof)
    forces = np.random.default_rng(seed).normal(size=problem.n_rows)
    dense = problem.normalized()
    dense.dense_delassus       # noqa: B018  (the dense lane's first request)
    shifted = dense.with_shift(np.zeros(problem.n_contacts))
    velocity = dense.velocity(forces)
    values = (dense.offset, velocity, dense.constraint_values(velocity), dense.gaps_after(velocity),
              shifted.offset, shifted.dense_delassus)
    assert "jacobian" not in dense.__dict__ and "jacobian" not in shifted.__dict__
    sparse = problem.normalized()
    unshifted = sparse.with_shift(np.zeros(problem.n_contacts))
    expected = (sparse.offset, sparse.velocity(forces), sparse.constraint_values(velocity),
                sparse.gaps_after(velocity), unshifted.offset, unshifted.delassus.toarray())
    assert "jacobian" in sparse.__dict__                   # the sparse products built it
    for got, want in zip(values, expected):
        assert np.allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
    columns = dense.scaling.velocity / np.sqrt(np.mean(problem.mass * problem.free_velocity**2)
                                                / np.mean(problem.mass))
    assert np.array_equal(sparse.jacobian.toarray(), diagonal_scaled(problem.jacobian,
                                                                      columns=columns).toarray())
    touched, block = dense.dense_jacobian
    assert np.array_equal(touched, np.unique(problem.jacobian.indices))
    assert np.array_equal(block, sparse.jacobian.toarray()[:, touched])
    assert touched.size <= problem.jacobian.nnz and (n_dof == 30 or 10 * touched.size < n_dof)


def test_the_dense_forms_sum_entries_stored_twice_and_weight_the_columns():
    """A Jacobian with each entry stored twice, as two halves: the dense block holds their sums
    (as the sparse ``H`` does), and the dense ``W`` of the problem in physical units (columns
    weighted by ``dt M^-1/2``), summed over each column's nonzeros, is the sparse ``W`` to
    rounding and exactly symmetric."""
    problem = _frictional_problem(5, n_dof=40)
    source = problem.jacobian
    counts = np.diff(source.indptr)
    rows = np.repeat(np.arange(source.shape[0]), counts)
    order = np.argsort(np.concatenate([rows, rows]), kind="stable")
    twice = sp.csr_matrix((np.concatenate([source.data, source.data])[order] / 2.0,
                           np.concatenate([source.indices, source.indices])[order],
                           np.concatenate([[0], np.cumsum(2 * counts)])), shape=source.shape)
    assert twice.nnz == 2 * source.nnz and not twice.has_canonical_format
    doubled = replace(problem, jacobian=twice)
    columns, block = doubled.dense_jacobian
    assert np.array_equal(columns, np.unique(source.indices))
    assert np.array_equal(block, source.toarray()[:, columns])
    dense, sparse = doubled.dense_delassus, problem.delassus.toarray()
    assert np.array_equal(dense, dense.T)
    assert np.allclose(dense, sparse, rtol=1e-14, atol=1e-14 * np.abs(sparse).max())


@pytest.mark.parametrize("seed, doubled", [(6, False), (7, True)])
def test_dense_normalising_builds_the_lazy_dense_forms_at_once_none_on_the_source(seed, doubled):
    """``normalized(dense=True)`` gives the dense Jacobian and ``W`` that the lazy properties
    build, to the bit (a Jacobian with entries stored twice too), without caching a dense form
    on the problem normalised; where that problem holds its dense Jacobian, or is itself
    normalised (its sparse Jacobian built on first use), the forms come on first use as without
    ``dense``."""
    problem = _frictional_problem(seed, n_dof=40)
    if doubled:
        source = problem.jacobian
        twice = sp.csr_matrix((np.repeat(source.data / 2.0, 2), np.repeat(source.indices, 2),
                               2 * source.indptr), shape=source.shape)
        problem = replace(problem, jacobian=twice)
    eager = problem.normalized(dense=True)
    assert {"dense_jacobian", "dense_delassus"} <= set(eager.__dict__)
    assert "dense_jacobian" not in problem.__dict__
    lazy = problem.normalized()
    (columns, block), (lazy_columns, lazy_block) = eager.dense_jacobian, lazy.dense_jacobian
    assert np.array_equal(columns, lazy_columns) and np.array_equal(block, lazy_block)
    assert np.array_equal(eager.dense_delassus, lazy.dense_delassus)
    assert "dense_jacobian" in problem.__dict__          # the lazy forms' source block
    held = problem.normalized(dense=True)
    assert "dense_jacobian" not in held.__dict__
    assert np.array_equal(held.dense_delassus, lazy.dense_delassus)
    again = eager.normalized(dense=True)      # of a normalised problem: lazily, as without dense
    assert "dense_jacobian" not in again.__dict__ and "jacobian" not in eager.__dict__


def test_a_problem_without_rows_has_an_empty_dense_lane():
    """No contact: an empty dense Jacobian and ``W``, and the free velocity back."""
    problem = StepProblem(mass=np.ones(4), free_velocity=np.arange(4.0), jacobian=sp.csr_matrix((0, 4)),
                          gaps=np.zeros(0), cones=Cones.frictionless(np.zeros(0), 1), dt=0.1)
    scaled = problem.normalized()
    assert scaled.dense_delassus.shape == (0, 0) and scaled.dense_jacobian[1].shape == (0, 0)
    assert np.allclose(scaled.velocity(np.zeros(0)) * scaled.scaling.velocity, np.arange(4.0))


def test_a_normalised_problem_survives_copies_and_names_a_missing_attribute():
    """The lazily built Jacobian of a normalised problem: copies with another shift or other
    cones, pickling and ``copy`` carry it, a copy checks its shift, and any other missing
    attribute is an ``AttributeError`` naming it."""
    import copy
    import pickle

    problem = _frictional_problem(7)
    scaled = problem.normalized()
    shifted = scaled.with_shift(np.zeros(problem.n_contacts))
    coned = scaled.with_cones(problem.cones.with_branches(np.zeros(problem.n_contacts, bool)))
    for clone in (shifted, coned, pickle.loads(pickle.dumps(problem.normalized())),
                  copy.copy(problem.normalized())):
        assert np.array_equal(clone.jacobian.toarray(), scaled.jacobian.toarray())
    assert np.array_equal(shifted.shift, np.zeros(problem.n_contacts))
    with pytest.raises(ValueError, match="shift"):
        scaled.with_shift(np.zeros(problem.n_contacts + 1))
    with pytest.raises(AttributeError, match="no_such_field"):
        problem.normalized().no_such_field    # noqa: B018
