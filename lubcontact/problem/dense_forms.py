"""Dense forms of a small step problem's Jacobian and Delassus operator, compiled (numba).

The solvers' dense lanes (problems of at most a few hundred rows) work on ``H`` restricted to
the degrees of freedom its rows involve and on ``W = H M^-1 H^T`` as dense arrays
(:attr:`~lubcontact.problem.StepProblem.dense_jacobian`,
:attr:`~lubcontact.problem.StepProblem.dense_delassus`). A row of ``H`` has the entries of
two grains' degrees of freedom at most (six in 2D), so ``W`` is summed over the nonzeros of
each column: at 148 rows and 120 columns 10.5 us against 63 us for the BLAS product of the
dense block with its transpose, which multiplies the zeros too (docs/records/benchmarks.md,
"Small systems: the dense forms compiled"). Imported on first use: numba's import is not paid
by runs without small problems.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def dense_rows(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, n_dof: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """A CSR matrix's rows on the columns they involve.

    Parameters
    ----------
    indptr, indices, data : ndarray
        The CSR arrays of a matrix with ``indptr.size - 1`` rows and ``n_dof`` columns.
    n_dof : int
        Its number of columns.

    Returns
    -------
    (ndarray of int, ndarray)
        ``columns``, shape (k,), sorted: the columns holding an entry; and ``block``, shape
        (n_rows, k), the rows on them (entries stored twice summed).
    """
    involved = np.zeros(n_dof, dtype=np.bool_)
    for entry in range(indices.size):
        involved[indices[entry]] = True
    place = np.empty(n_dof, dtype=np.int64)
    count = 0
    for column in range(n_dof):
        if involved[column]:
            place[column] = count
            count += 1
    columns = np.empty(count, dtype=np.int64)
    for column in range(n_dof):
        if involved[column]:
            columns[place[column]] = column
    n_rows = indptr.size - 1
    block = np.zeros((n_rows, count))
    for row in range(n_rows):
        for entry in range(indptr[row], indptr[row + 1]):
            block[row, place[indices[entry]]] += data[entry]
    return columns, block


@numba.njit(cache=True)
def weighted_gram(block: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``block diag(weights)^2 block^T``, shape (n, n), summed over each column's nonzeros.

    Parameters
    ----------
    block : ndarray, shape (n, k)
        Dense, mostly zeros (C order).
    weights : ndarray, shape (k,)
        Column weights (``dt M^-1/2`` of a degree of freedom).

    Returns
    -------
    ndarray, shape (n, n)
        Exactly symmetric: entries ``(i, j)`` and ``(j, i)`` sum the same products in the same
        order (each computed once).
    """
    n, k = block.shape
    gram = np.zeros((n, n))
    rows = np.empty(n, dtype=np.int64)
    for column in range(k):
        count = 0
        for row in range(n):
            if block[row, column] != 0.0:
                rows[count] = row
                count += 1
        square = weights[column] * weights[column]
        for a in range(count):
            first = rows[a]
            for b in range(a, count):
                second = rows[b]
                value = square * (block[first, column] * block[second, column])
                gram[first, second] += value
                if second != first:
                    gram[second, first] += value
    return gram


@numba.njit(cache=True)
def scaled_forms(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, n_dof: int,
                 factors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The dense forms of a normalised problem from its source's Jacobian, in one call.

    Parameters
    ----------
    indptr, indices, data : ndarray
        The CSR arrays of the source problem's ``H`` (``n_dof`` columns).
    n_dof : int
        Its number of columns.
    factors : ndarray, shape (n_dof,)
        The normalised problem's column scale (``S_i / V``,
        :meth:`~lubcontact.problem.StepProblem.normalized`).

    Returns
    -------
    (ndarray of int, ndarray, ndarray)
        ``columns`` and ``block`` (:func:`dense_rows`, its columns scaled by ``factors``) and
        ``W = block block^T`` (:func:`weighted_gram`, unit weights): the same arrays as the
        normalised problem's ``dense_jacobian`` and ``dense_delassus`` built one by one.
    """
    columns, block = dense_rows(indptr, indices, data, n_dof)
    for row in range(block.shape[0]):
        for place in range(columns.size):
            block[row, place] *= factors[columns[place]]
    return columns, block, weighted_gram(block, np.ones(columns.size))
