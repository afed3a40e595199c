"""Sparse factorisations of a Newton system's active block, kept and reused where they can be.

Above ``DENSE_LIMIT`` rows a Newton iteration of :mod:`.newton` solves its active block through
:class:`Factorisations` (:func:`~lubcontact.solvers.newton._block_solve`), which keeps the
factors of the last blocks (reused for a block met again entry for entry) and, on 2D problems,
orders a block afresh by an approximate minimum degree (:mod:`.ordering`) or carries the last
fresh order over to it, then factorises it without pivoting on static patterns
(:class:`StaticLU`), SuperLU taking over where the pivots are not good enough.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .compiled_apgd import csr_arrays, positions
from .compiled_modules import kernels, ordering

SPARSE_LU = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, panel_size=1,
                 options=dict(SymmetricMode=True))
"""SuperLU's settings for a factorised block ordered by SuperLU (3D problems; a 2D block is
ordered by :mod:`.ordering`: :class:`Factorisations`), whose pattern is ``W_AA``'s (symmetric
but for the entries the product forming ``W`` left out as exact zeros):
a minimum-degree ordering of ``A^T + A`` with pivots preferred on the diagonal. On developed
2000-grain flows its factors hold 2.6 times the block's entries against 3.9 with COLAMD, and a
Newton step costs 15 % less (same iterations). Panels of one column (SuperLU's default is 20):
the same factors, 21-22 ms instead of 27-30 for the 22 000-27 000-row blocks of 12 000-grain
flows, whose supernodes are too small for wider panels to pay (docs/records/benchmarks.md)."""

ORDERED_LU = {**SPARSE_LU, "permc_spec": "NATURAL"}
"""SuperLU's settings for an active block already permuted by an elimination order (carried over
from an earlier block, or a 2D block's own: :class:`Factorisations`) where the static LU's
pivots were not good enough: no ordering of its own."""

KEPT_FACTORISATIONS = 2
"""Factorisations of active blocks kept for reuse (:class:`Factorisations`): two, for iterates
that cycle between two pieces."""

NEW_ROWS_LIMIT = 0.05
"""An active block whose rows are all but this fraction rows of the block last ordered afresh
is factorised in that block's elimination order (:class:`Factorisations`), not ordered again.
Against 0.01 (with :data:`FILL_GROWTH`): a quarter to a third fewer fresh orders on captured 2D
flow steps from 4 000 to 10^5 grains, the factors 1-6 % larger (docs/records/benchmarks.md,
"orders carried further")."""

STATIC_LU_BACKWARD_ERROR = 1e-11
"""A solve with :class:`StaticLU`'s factors (no pivoting) whose normwise backward error is above
this is done again by SuperLU with pivoting (a stable LU's is a few times the machine epsilon)."""

FILL_GROWTH = 1.1
"""A factorisation in a carried order whose factors hold more than this many times the ordered
block's, per entry of its block, ends the carrying: the next block is ordered afresh. With
:data:`NEW_ROWS_LIMIT` at 0.05, 1.25 let the factors of a gluey 10^5-grain flow's steps grow by
8.6 % (1.2 % at 1.1) for a third fewer fresh orders (docs/records/benchmarks.md, "orders
carried further")."""


class Factorisations:
    """The factorisations of the :data:`KEPT_FACTORISATIONS` active blocks used last, reused for
    a block equal to one of them entry for entry (the same factors, so the same direction), and
    the elimination order of the last block ordered afresh, carried over.

    In 2D the generalised Jacobian is constant on each piece of the Alart-Curnier function: on
    the hard steps of developed flows most Newton iterations after the first twenty keep the
    active block of the one before, or of the one before that (the iterates cycling between
    two pieces), and the factorisation was two thirds of their time.

    The minimum-degree ordering is a third of a factorisation (8 of 22 ms on the 23 000-row blocks
    of 12 000-grain gluey flows), and late Newton iterations change a few rows of the block. A
    block whose rows are all but :data:`NEW_ROWS_LIMIT` of them rows of the last ordered block is
    permuted by that block's order, each new row placed just after the other row of its contact
    where that one is in it (``partner``: a tangential row that stopped sliding next to its normal
    row, as a supervariable), else just after the last of its neighbours in it, and factorised
    without ordering (:data:`ORDERED_LU`): 14-16 ms with 0-10 % more fill on those blocks
    (docs/records/benchmarks.md; next to its contact's other row, 1.4-3.1 % fewer factor entries
    and 0-7 % fewer fresh orders on captured 2D flow steps from 4 000 to 10^5 grains, "a new row of
    a carried order next to its contact's other row"). Rows of the ordered block that the new one
    lacks are left out of the order. Where the carried order's fill grows past :data:`FILL_GROWTH`
    times the ordered block's (on a 1 600-row grid pattern with 1 % of its rows new, scattered: 2.0
    times, 2.4 times a fresh ordering's), the next block is ordered afresh. Only where ``carry`` is
    set (2D problems, whose blocks have ``W``'s pattern, nearly symmetric): on a 3D Siconos file
    the carried orders' solves were ten times less accurate and Newton took 392 iterations instead
    of 154.

    Where ``carry`` is set a block is also ordered afresh by an approximate minimum degree, each
    contact's two rows together (:meth:`_fresh_order`), and factorised by
    :class:`StaticLU` in that order, as carried blocks are: SuperLU's own minimum degree was
    7 of its 19 ms on the 20 000-row blocks of a 12 000-grain gluey step, and SuperLU gives no
    order without factorising (12-15 ms instead, 5 % fewer factor entries:
    docs/records/benchmarks.md, "a fresh order by approximate minimum degree"). That order
    comes postordered along its elimination tree, which keeps the fill and puts the columns
    that update a column next to it: at 10^5 grains the permutation, patterns and LU took 2.6
    times less time ("the minimum-degree order postordered"). Elsewhere (3D) SuperLU orders
    and factorises with pivoting (:data:`SPARSE_LU`).

    Parameters
    ----------
    carry : bool
        Carry the elimination orders over (2D problems).
    partner : ndarray of int, shape (n_rows,), optional
        Per row of the system, the other row of its contact (-1 for none); none given: no row
        has one.
    """

    def __init__(self, carry: bool = False, partner: np.ndarray | None = None):
        self.kept: list[tuple[sp.spmatrix, spla.SuperLU | StaticLU, np.ndarray | None]] = []
        self.reused = 0
        self.carry = carry
        self.partner = np.empty(0, dtype=np.int64) if partner is None else partner
        self.carried = 0
        self.pivoted = 0            # blocks SuperLU took back from StaticLU
        self.ordered_rows: np.ndarray | None = None        # sorted
        self.positions: np.ndarray | None = None           # their places in the order
        self.fill = 0.0             # the ordered block's factor entries per block entry

    def solve(self, matrix: sp.spmatrix, rhs: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """``matrix^-1 rhs``, factorising ``matrix`` unless it is kept; ``rows``: the rows of
        the system the block's rows are, sorted. ``matrix``: CSC or CSR (a 2D block, by rows:
        :meth:`~lubcontact.solvers.newton.AlartCurnier.newton_direction`; SuperLU's own order
        takes CSC)."""
        for position, (kept, _, _) in enumerate(self.kept):
            if _same_matrix(kept, matrix):
                self.reused += 1
                self.kept.insert(0, self.kept.pop(position))      # the most recently used first
                return self._solved(rhs)
        order = self._carried_order(matrix, rows)
        carried = order is not None
        if not carried and self.carry:
            order = self._fresh_order(matrix, rows)
        if order is None:                   # SuperLU's own order, pivoting
            factors = spla.splu(matrix, **SPARSE_LU)
            self.ordered_rows, self.positions = rows, factors.perm_c
            self.fill = factors.nnz / matrix.nnz
        else:
            permuted, norm = _permuted(matrix, order)
            factors = StaticLU.factorise(permuted, norm)
            if factors is None:
                factors = spla.splu(permuted, **ORDERED_LU)
                self.pivoted += 1
            if carried:
                self.carried += 1
                if factors.nnz > FILL_GROWTH * self.fill * matrix.nnz:
                    self.ordered_rows = None        # the order no longer fits: order afresh
            else:
                self.ordered_rows, self.positions = rows, places_of(order)
                self.fill = factors.nnz / matrix.nnz
        self.kept = [(matrix, factors, order), *self.kept][:KEPT_FACTORISATIONS]
        return self._solved(rhs)

    def _solved(self, rhs: np.ndarray) -> np.ndarray:
        """``rhs`` solved by the factors kept first; where they are :class:`StaticLU`'s and the
        solution is not accurate, by SuperLU's (pivoting) in their place."""
        matrix, factors, order = self.kept[0]
        solved = _ordered_solve(factors, order, rhs)
        if isinstance(factors, StaticLU) and not factors.accurate(solved[order], rhs[order]):
            factors = spla.splu(factors.matrix, **ORDERED_LU)
            self.pivoted += 1
            self.kept[0] = (matrix, factors, order)
            solved = _ordered_solve(factors, order, rhs)
        return solved

    def _fresh_order(self, matrix: sp.spmatrix, rows: np.ndarray) -> np.ndarray:
        """An approximate minimum degree order of ``matrix`` (a 2D block by rows; ``rows``: the
        rows of the system it holds, sorted), each contact's two rows eliminated together where
        both are in it (``partner``; :func:`~lubcontact.solvers.ordering.grouped_minimum_degree`):
        on captured 10 000-grain gluey steps a fresh order took 0.83 of the time of one found
        row by row, with 0.99-1.02 times its factor entries, and the steps 0.93-0.98 of theirs
        (docs/records/benchmarks.md, "the minimum-degree order by contacts")."""
        compiled = kernels()
        indptr, indices = csr_arrays(matrix)[:2]
        group, weights = compiled.contact_groups(rows, self.partner)
        return ordering().grouped_minimum_degree(
            *compiled.grouped_pattern(indptr, indices, group, weights.size), group, weights)

    def _carried_order(self, matrix: sp.spmatrix, rows: np.ndarray) -> np.ndarray | None:
        """The last ordered block's elimination order for ``matrix`` (a permutation of its
        rows: :func:`~lubcontact.solvers.kernels.carried_order`, each new row just after its
        contact's other row where that one is old, else just after the last of its old
        neighbours, its column's rows in ``W``'s symmetric pattern; placed before the first of
        them instead, the carried 12 000-grain blocks took +0-13 % fill against +0-10 %), or
        None when more than :data:`NEW_ROWS_LIMIT` of ``rows`` are new to it."""
        if not self.carry or self.ordered_rows is None:
            return None
        order, carried = kernels().carried_order(matrix.indptr, matrix.indices, rows,
                                                 self.ordered_rows, self.positions,
                                                 NEW_ROWS_LIMIT * rows.size, self.partner)
        return order if carried else None


class StaticLU:
    """``A = L U`` without pivoting on static patterns
    (:func:`~lubcontact.solvers.kernels.static_pattern`: those of ``A + A^T``'s Cholesky factor;
    :func:`~lubcontact.solvers.kernels.static_lu`), for the blocks :class:`Factorisations`
    factorises in an elimination order of its own (a 2D block ordered afresh) or carried over:
    on a 12 000-grain gluey step's 19 000-row block, 5.1 ms (patterns 3.0, values 2.1 with
    unsigned indices; 8.3 ms in all on the blocks of six such steps with signed ones; the
    patterns 2.0-2.3 ms since they are found in one pass) against 10.4 ms for SuperLU in the
    same order, the same fill (docs/records/benchmarks.md). ``nnz`` counts the entries of both
    factors, the diagonal twice (SuperLU's counts its supernodes' storage: the same on these
    blocks, within 1 %)."""

    def __init__(self, matrix: sp.csc_matrix, norm: float, pattern: tuple, lower: np.ndarray,
                 upper: np.ndarray):
        self.matrix, self.norm, self.pattern = matrix, norm, pattern
        self.lower, self.upper = lower, upper
        self.nnz = lower.size + upper.size

    @classmethod
    def factorise(cls, matrix: sp.csc_matrix, norm: float) -> StaticLU | None:
        """The factors of ``matrix`` (CSC, square; ``norm``: its ``|A|_inf``), or None where a
        pivot is below ``1e-14`` times its largest entry (SuperLU then factorises it, pivoting)."""
        indptr, indices, data = csr_arrays(matrix)      # unsigned: no wrap-around checks
        compiled = kernels()
        *arrays, paired = compiled.static_pattern(indptr, indices)
        pattern = tuple(positions(array) for array in arrays)
        lower, upper, failed = compiled.static_lu(indptr, indices, data, *pattern, paired)
        return None if failed >= 0 else cls(matrix, norm, pattern, lower, upper)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``matrix^-1 rhs``."""
        lower_ptr, lower_idx, upper_ptr, upper_idx = self.pattern
        return kernels().static_lu_solve(lower_ptr, lower_idx, self.lower, upper_ptr, upper_idx,
                                         self.upper, rhs)

    def accurate(self, solved: np.ndarray, rhs: np.ndarray) -> bool:
        """Whether ``solved`` solves ``matrix x = rhs`` with a normwise backward error
        ``|r|_inf / (|A|_inf |x|_inf + |b|_inf)`` of at most :data:`STATIC_LU_BACKWARD_ERROR`
        (:func:`~lubcontact.solvers.kernels.solve_is_accurate`)."""
        return bool(kernels().solve_is_accurate(*csr_arrays(self.matrix), self.norm, solved,
                                                np.asarray(rhs, dtype=float),
                                                STATIC_LU_BACKWARD_ERROR))


def _permuted(matrix: sp.spmatrix, order: np.ndarray) -> tuple[sp.csc_matrix, float]:
    """``matrix[order][:, order]`` (``order``: a permutation of its rows) in CSC form with sorted
    32-bit indices, as SuperLU takes it, and ``|matrix|_inf``, from its rows
    (:func:`~lubcontact.solvers.kernels.permuted_columns`; a 2D block comes by rows, another
    matrix is converted first)."""
    indptr, indices, data, norm = kernels().permuted_columns(*csr_arrays(sp.csr_matrix(matrix)),
                                                             positions(order))
    permuted = sp.csc_matrix((data, indices, indptr), shape=matrix.shape)
    permuted.has_sorted_indices = True
    return permuted, float(norm)


def places_of(order: np.ndarray) -> np.ndarray:
    """Each row's place in an elimination ``order`` (its inverse permutation), 32-bit as
    SuperLU's ``perm_c``, the form :class:`Factorisations` carries (and the compiled lane's
    ``AlartCurnier.elimination_places``)."""
    places = np.empty(order.size, dtype=np.int32)
    places[order] = np.arange(order.size, dtype=np.int32)
    return places


def _ordered_solve(factors: spla.SuperLU, order: np.ndarray | None, rhs: np.ndarray) -> np.ndarray:
    """The solution of ``A x = rhs`` from the factors of ``A`` (``order`` None) or of
    ``A[order][:, order]``."""
    if order is None:
        return factors.solve(rhs)
    solved = np.empty_like(rhs)
    solved[order] = factors.solve(rhs[order])
    return solved


def _same_matrix(first: sp.spmatrix, second: sp.spmatrix) -> bool:
    """Whether two compressed matrices (both CSC, or both CSR) store the same entries in the same
    order."""
    return (first.format == second.format and first.shape == second.shape
            and first.nnz == second.nnz
            and np.array_equal(first.data, second.data)
            and np.array_equal(first.indices, second.indices)
            and np.array_equal(first.indptr, second.indptr))
