"""StepProblem's matrices: the scaled copies by value, the Delassus factor with duplicate entries."""
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


def _with_duplicates(values, rows, cols, shape):
    """CSR arrays storing each entry as two halves, side by side in its row."""
    order = np.lexsort((cols, rows))
    rows, cols, values = rows[order], cols[order], values[order]
    data = np.repeat(values / 2, 2)
    indices = np.repeat(cols, 2)
    indptr = np.concatenate([[0], np.cumsum(2 * np.bincount(rows, minlength=shape[0]))])
    return data, indices, indptr
