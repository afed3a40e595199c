"""Siconos ``.dat`` frictional contact problems: read and write, local and global.

The format, as Siconos numerics writes and reads it (``FrictionContactProblem.c``,
``GlobalFrictionContactProblem.c``, ``NumericsMatrix.c``, ``SparseBlockMatrix.c``,
``NumericsSparseMatrix.c``, ``CSparseMatrix.c``). Numbers are read with
``fscanf``, so line breaks matter only inside a CSparse listing::

    local  (frictionContact_printInFile):        dim nc <W (dim nc x dim nc)> q (dim nc) mu (nc)
    global (globalFrictionContact_printInFile):  dim nc <M (n x n)> <H (n x dim nc)> q (n) b (dim nc) mu (nc)

Vectors are contact-major (per contact the normal, then the tangential
components). The global problem is ``M v = q + H r``, ``u = H^T v + b``
(Siconos' ``GlobalFrictionContactProblem``; FCLIB's ``f`` is ``q`` and ``w`` is
``b``), whose local form is ``W = H^T M^-1 H``, ``q_loc = H^T M^-1 q + b``
(:func:`lubcontact.problem.global_form.global_to_local`).

A matrix (``NM_write_in_file``) is ``storage rows columns`` and then:

- storage 0, dense: ``rows columns`` again, then the ``rows x columns``
  values in column-major order. Files without this second size pair (older
  hand-written ones) are accepted: the pair is recognised as two integers
  equal to ``rows`` and ``columns``.
- storage 1, sparse block (``SBM_write_in_file``): ``nbblocks`` (0: the zero
  matrix, nothing follows), the numbers of block rows and block columns, the
  cumulated block-row sizes, the cumulated block-column sizes, ``filled1``,
  ``filled2``, the ``filled1`` block-row pointers, the ``filled2`` block-column
  indices (block CSR), then each block in order: its number and its values in
  column-major order.
- storage 2, sparse (``NSM_write_in_file``): the origin (1 triplet, 2 csc,
  3 csr; 4, half triplet, is not supported), then ``CSparseMatrix_print_in_file``:
  a version line, a size line ``[triplet: |csr: ]m-by-n, nzmax: k nnz: z, ...``
  and the entries: csc ``col j : locations a to b`` then ``i : x`` lines; csr
  ``row i : locations a to b`` then ``j : x``; triplet ``i j : x``. Siconos
  prints these values with ``%g`` (6 digits): the file's matrix is the
  problem, rounding included.

Siconos ignores what follows ``mu``; 14 of the 26 Siconos test files end with
one more integer (``0`` or ``1``). :func:`read_siconos` ignores one trailing
integer (:data:`TRAILING_WORDS`) and rejects anything more: a longer tail means
the counts of the file are wrong (a duplicated line, for instance).

Local and global files are told apart by their structure, not their names
(``GFC3D_TwoRods1-condensed.dat`` is local): a first matrix that is not
``dim nc x dim nc``, or one followed by a second matrix header ``storage n
dim*nc``, makes a global problem.

The writers use the same layout with ``repr`` floats (the shortest decimal
that reads back to the same double), also inside CSparse listings, whose line
layout follows ``CSparseMatrix_new_from_file`` (one line per column header and
per entry, values read with ``%le``): a written problem reads back bit for bit
here, and by the rules of Siconos' readers (``frictionContact_newFromFile``,
``globalFrictionContact_newFromFile``) there too.
"""
from __future__ import annotations

import re
from bisect import bisect_left
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..problem.global_form import GlobalProblem, canonical_csr, global_from_step
from ..problem.local import LocalProblem, contact_major_permutation
from ..problem.step import StepProblem
from .files import atomic_path

DENSE, SPARSE_BLOCK, SPARSE = 0, 1, 2
STORAGES = {DENSE: "dense", SPARSE_BLOCK: "sparse block", SPARSE: "sparse"}
ORIGINS = {1: "triplet", 2: "csc", 3: "csr"}
DENSE_LIMIT = 64
"""Largest ``dim * nc`` that :func:`write_siconos` writes densely by default."""
TRAILING_WORDS = 1
"""Integers tolerated after ``mu`` (Siconos ignores them; 14 of the 26 test files have one)."""

_INTEGER = re.compile(r"[+-]?[0-9]+\Z")
_SIZE_LINE = re.compile(r"\s*(?:(triplet|csr):\s*)?([0-9]+)-by-([0-9]+),\s*nzmax:\s*([0-9]+)\s+"
                        r"nnz:\s*([0-9]+)")


# -- reading --------------------------------------------------------------------------------------
class _Words:
    """The whitespace-separated words of a file, with their line numbers, read in order."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()
        words, where = [], []
        for number, line in enumerate(self.lines):
            split = line.split()
            words += split
            where += [number] * len(split)
        self.words, self.where, self.pos = words, where, 0

    @property
    def remaining(self) -> int:
        return len(self.words) - self.pos

    def error(self, field: str, message: str, index: int | None = None) -> ValueError:
        index = self.pos if index is None else index
        where = f"line {self.where[index] + 1}" if index < len(self.words) else "end of file"
        return ValueError(f"{self.path}: {field}: {message} ({where})")

    def integer(self, field: str, minimum: int = 0, maximum: int | None = None) -> int:
        """The next word as an integer in ``[minimum, maximum]``."""
        if self.pos >= len(self.words):
            raise self.error(field, "expected an integer, the file ends")
        word = self.words[self.pos]
        if not _INTEGER.match(word):
            raise self.error(field, f"expected an integer, got {word!r}")
        value = int(word)
        if value < minimum or (maximum is not None and value > maximum):
            wanted = (f">= {minimum}" if maximum is None else f"{minimum}" if minimum == maximum
                      else f"in [{minimum}, {maximum}]")
            raise self.error(field, f"must be {wanted}, got {value}")
        self.pos += 1
        return value

    def size(self, field: str) -> int:
        """A matrix or vector size: no larger than the number of words of the file."""
        return self.integer(field, 0, len(self.words))

    def floats(self, count: int, field: str, positions: list[int] | None = None) -> np.ndarray:
        """``count`` finite numbers: the next ones, or those at word ``positions``."""
        if positions is None:
            if self.remaining < count:
                raise self.error(field, f"expected {count} numbers, the file ends after "
                                        f"{self.remaining}", len(self.words))
            positions = range(self.pos, self.pos + count)
            self.pos += count
        chunk = [self.words[k] for k in positions]
        try:
            values = np.fromiter(map(float, chunk), dtype=float, count=len(chunk))
        except ValueError:
            bad = next(k for k, word in enumerate(chunk) if not _is_float(word))
            raise self.error(field, f"expected a number, got {chunk[bad]!r}", positions[bad]) from None
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise self.error(field, f"non-finite value {chunk[bad[0]]!r}", positions[bad[0]])
        return values

    def integers(self, positions: np.ndarray, field: str, limit: int) -> np.ndarray:
        """The integers at word ``positions``, each in ``[0, limit)``."""
        chunk = [self.words[k] for k in positions]
        for k, word in enumerate(chunk):
            if not _INTEGER.match(word):
                raise self.error(field, f"expected an integer index, got {word!r}", positions[k])
        values = np.fromiter(map(int, chunk), dtype=np.int64, count=len(chunk))
        bad = np.flatnonzero((values < 0) | (values >= limit))
        if bad.size:
            raise self.error(field, f"index {values[bad[0]]} outside [0, {limit})", positions[bad[0]])
        return values

    def expect(self, word: str, field: str, what: str) -> None:
        if self.pos >= len(self.words) or self.words[self.pos] != word:
            got = repr(self.words[self.pos]) if self.pos < len(self.words) else "the end of the file"
            raise self.error(field, f"expected {word!r} ({what}), got {got}")
        self.pos += 1

    def looks_like_header(self, rows: int, cols: int) -> bool:
        """Whether the next three words read ``storage rows cols`` (a matrix, not a vector)."""
        nxt = self.words[self.pos: self.pos + 3]
        return (len(nxt) == 3 and all(_INTEGER.match(word) for word in nxt)
                and int(nxt[0]) in STORAGES and (int(nxt[1]), int(nxt[2])) == (rows, cols))


def _is_float(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _read_header(words: _Words, field: str) -> tuple[int, int, int]:
    """``storage rows columns`` of a NumericsMatrix."""
    if words.pos < len(words.words) and _INTEGER.match(words.words[words.pos]) \
            and int(words.words[words.pos]) not in STORAGES:
        raise words.error(f"{field}/storage", f"unknown matrix storage {words.words[words.pos]} "
                                              "(0 dense, 1 sparse block, 2 sparse)")
    storage = words.integer(f"{field}/storage", 0, 2)
    rows = words.size(f"{field} rows")
    cols = words.size(f"{field} columns")
    return storage, rows, cols


def _read_body(words: _Words, field: str, storage: int, rows: int, cols: int) -> sp.csr_matrix:
    if storage == DENSE:
        return _read_dense(words, field, rows, cols)
    if storage == SPARSE_BLOCK:
        return _read_sparse_block(words, field, rows, cols)
    return _read_sparse(words, field, rows, cols)


def _read_dense(words: _Words, field: str, rows: int, cols: int) -> sp.csr_matrix:
    nxt = words.words[words.pos: words.pos + 2]
    if len(nxt) == 2 and all(_INTEGER.match(word) for word in nxt) \
            and (int(nxt[0]), int(nxt[1])) == (rows, cols):
        words.pos += 2                                   # the "rows\tcols" line Siconos writes
    values = words.floats(rows * cols, field)
    return sp.csr_matrix(values.reshape(rows, cols, order="F"))


def _read_sparse_block(words: _Words, field: str, rows: int, cols: int) -> sp.csr_matrix:
    n_blocks = words.size(f"{field} nbblocks")
    if n_blocks == 0:
        return sp.csr_matrix((rows, cols))
    block_rows = words.integer(f"{field} blocknumber0", 1, max(rows, 1))
    block_cols = words.integer(f"{field} blocknumber1", 1, max(cols, 1))
    row_ends = np.array([words.integer(f"{field} blocksize0", 1, rows) for _ in range(block_rows)])
    col_ends = np.array([words.integer(f"{field} blocksize1", 1, cols) for _ in range(block_cols)])
    for ends, total, name in ((row_ends, rows, "blocksize0"), (col_ends, cols, "blocksize1")):
        if np.any(np.diff(ends) <= 0) or ends[-1] != total:
            raise words.error(f"{field} {name}", f"cumulated block sizes must increase to {total}, "
                                                 f"got {ends.tolist()[:8]}")
    filled1 = words.integer(f"{field} filled1", 1, block_rows + 1)
    filled2 = words.integer(f"{field} filled2", n_blocks, n_blocks)
    row_pointers = np.array([words.integer(f"{field} index1_data", 0, filled2)
                             for _ in range(filled1)])
    if row_pointers[0] != 0 or np.any(np.diff(row_pointers) < 0) or row_pointers[-1] != filled2:
        raise words.error(f"{field} index1_data", f"block-row pointers must rise from 0 to "
                                                  f"{filled2}, got {row_pointers.tolist()[:8]}")
    block_columns = [words.integer(f"{field} index2_data", 0, block_cols - 1)
                     for _ in range(filled2)]
    row_starts = np.concatenate([[0], row_ends[:-1]])
    col_starts = np.concatenate([[0], col_ends[:-1]])
    all_rows, all_cols, all_values = [], [], []
    for block_row in range(filled1 - 1):
        for number in range(row_pointers[block_row], row_pointers[block_row + 1]):
            words.integer(f"{field} block number", number, number)
            column = block_columns[number]
            height = row_ends[block_row] - row_starts[block_row]
            width = col_ends[column] - col_starts[column]
            values = words.floats(height * width, f"{field} block {number}")
            local_rows, local_cols = np.divmod(np.arange(height * width), height)[::-1]
            all_rows.append(row_starts[block_row] + local_rows)
            all_cols.append(col_starts[column] + local_cols)
            all_values.append(values)
    matrix = sp.coo_matrix((np.concatenate(all_values), (np.concatenate(all_rows),
                                                         np.concatenate(all_cols))),
                           shape=(rows, cols)).tocsr()
    matrix.eliminate_zeros()
    return matrix


def _read_sparse(words: _Words, field: str, rows: int, cols: int) -> sp.csr_matrix:
    origin_index = words.pos
    if words.pos < len(words.words) and words.words[words.pos] == "4":
        raise words.error(f"{field} origin", "half-triplet sparse storage (origin 4) is not supported")
    origin = words.integer(f"{field} origin", 1, 3)
    size_line = words.where[origin_index] + 2     # Siconos skips the origin line's end and a version line
    text = words.lines[size_line] if size_line < len(words.lines) else ""
    match = _SIZE_LINE.match(text)
    if not match:
        raise ValueError(f"{words.path}: {field}: expected the CSparse size line "
                         f"'[triplet: |csr: ]m-by-n, nzmax: k nnz: z' on line {size_line + 1}, "
                         f"got {text.strip()[:60]!r}")
    kind = match.group(1) or "csc"
    m, n, nnz = int(match.group(2)), int(match.group(3)), int(match.group(5))
    if kind != ORIGINS[origin]:
        raise words.error(f"{field} origin", f"origin {origin} ({ORIGINS[origin]}) but a {kind} "
                                             "listing follows", origin_index)
    if (m, n) != (rows, cols):
        raise ValueError(f"{words.path}: {field}: the CSparse listing is {m}-by-{n}, the matrix "
                         f"header says {rows} x {cols} (line {size_line + 1})")
    if nnz > len(words.words):
        raise ValueError(f"{words.path}: {field}: nnz {nnz} is more than the file holds "
                         f"(line {size_line + 1})")
    words.pos = bisect_left(words.where, size_line + 1)
    if kind == "triplet":
        return _read_triplet(words, field, rows, cols, nnz)
    outer, inner = (cols, rows) if kind == "csc" else (rows, cols)
    label = "col" if kind == "csc" else "row"
    starts, counts = np.empty(outer, dtype=np.int64), np.empty(outer, dtype=np.int64)
    filled = 0
    for j in range(outer):
        words.expect(label, field, f"{kind} listing: '{label} {j} : locations a to b'")
        words.integer(f"{field} {label} number", j, j)
        words.expect(":", field, f"{kind} listing: '{label} {j} : locations a to b'")
        words.expect("locations", field, f"{kind} listing: '{label} {j} : locations a to b'")
        words.integer(f"{field} {label} {j} first location", filled, filled)
        words.expect("to", field, f"{kind} listing: '{label} {j} : locations a to b'")
        last = words.integer(f"{field} {label} {j} last location", filled - 1, nnz - 1)
        starts[j], counts[j] = words.pos, last - filled + 1
        words.pos += 3 * counts[j]
        filled = last + 1
        if words.pos > len(words.words):
            raise words.error(field, f"{label} {j}: the file ends inside its entries", len(words.words))
    if filled != nnz:
        raise words.error(field, f"the listing has {filled} entries, its size line says nnz {nnz}")
    return _assemble(words, field, starts, counts, nnz, (outer, inner), 3, kind)


def _read_triplet(words: _Words, field: str, rows: int, cols: int, nnz: int) -> sp.csr_matrix:
    positions = words.pos + 4 * np.arange(nnz)
    if words.pos + 4 * nnz > len(words.words):
        raise words.error(field, f"triplet listing: expected {nnz} entries 'i j : x', the file ends",
                          len(words.words))
    colons = [k for k in positions if words.words[k + 2] != ":"]
    if colons:
        raise words.error(field, f"triplet listing: expected 'i j : x', got "
                                 f"{' '.join(words.words[colons[0]: colons[0] + 4])!r}", colons[0])
    row = words.integers(positions, f"{field} row index", rows)
    col = words.integers(positions + 1, f"{field} column index", cols)
    values = words.floats(nnz, field, list(positions + 3))
    words.pos += 4 * nnz
    return sp.coo_matrix((values, (row, col)), shape=(rows, cols)).tocsr()


def _assemble(words: _Words, field: str, starts: np.ndarray, counts: np.ndarray, nnz: int,
              shape: tuple[int, int], stride: int, kind: str) -> sp.csr_matrix:
    """Entries ``index : value`` of a compressed listing into a CSR matrix."""
    outer, inner = shape
    positions = np.repeat(starts, counts) + stride * (np.arange(nnz) -
                                                      np.repeat(np.cumsum(counts) - counts, counts))
    colons = [k for k in positions if words.words[k + 1] != ":"]
    if colons:
        raise words.error(field, f"{kind} listing: expected 'index : value', got "
                                 f"{' '.join(words.words[colons[0]: colons[0] + 3])!r}", colons[0])
    index = words.integers(positions, f"{field} index", inner)
    values = words.floats(nnz, field, list(positions + 2))
    pointers = np.concatenate([[0], np.cumsum(counts)])
    if kind == "csc":
        return sp.csc_matrix((values, index, pointers), shape=(inner, outer)).tocsr()
    return sp.csr_matrix((values, index, pointers), shape=(outer, inner))


def _parse(path: Path, kind: str | None) -> tuple:
    """``("local", dim, W, q, mu)`` or ``("global", dim, M, H, q, b, mu)`` from a ``.dat`` file."""
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (Siconos .dat problems are text)") from None
    words = _Words(path, text)
    if not words.remaining:
        raise ValueError(f"{path}: dim: empty file")
    dim = words.integer("dim", 2, 3)
    nc = words.size("nc")
    n = dim * nc
    storage, rows, cols = _read_header(words, "W" if kind != "global" else "M")
    guessed = kind
    if kind is None:
        kind = "local" if (rows, cols) == (n, n) else "global" if rows == cols else None
    if kind is None or (kind == "local" and (rows, cols) != (n, n)):
        raise words.error("W", f"expected shape {(n, n)} for {nc} contacts in {dim}D"
                               f"{'' if kind else ' (or a square M of a global problem)'}, "
                               f"got {(rows, cols)}")
    if kind == "global" and rows != cols:
        raise words.error("M", f"must be square, got {(rows, cols)}")
    first = _read_body(words, "W" if kind == "local" else "M", storage, rows, cols)
    if kind == "local" and words.looks_like_header(rows, n) and (rows, cols) == (n, n) \
            and words.remaining >= n + nc + 3:
        kind = "global"                                   # a global problem whose M is n x n
    if guessed is None and kind == "global" and not words.looks_like_header(rows, n):
        raise words.error("W", f"expected shape {(n, n)} for {nc} contacts in {dim}D, got "
                               f"{(rows, cols)}, and no matrix H follows as in a global problem")
    if kind == "local":
        q = words.floats(n, "q")
        mu = words.floats(nc, "mu")
        parsed = ("local", dim, first, q, mu)
    else:
        storage, h_rows, h_cols = _read_header(words, "H")
        if (h_rows, h_cols) != (rows, n):
            raise words.error("H", f"expected shape {(rows, n)} (rows of M, {dim} x {nc} contacts), "
                                   f"got {(h_rows, h_cols)}")
        jacobian = _read_body(words, "H", storage, h_rows, h_cols)
        q = words.floats(rows, "q")
        b = words.floats(n, "b")
        mu = words.floats(nc, "mu")
        parsed = ("global", dim, first, jacobian, q, b, mu)
    if np.any(mu < 0):
        bad = int(np.flatnonzero(mu < 0)[0])
        raise words.error("mu", f"must be >= 0, got {mu[bad]} for contact {bad}", words.pos - nc + bad)
    tail = words.words[words.pos:]
    if len(tail) > TRAILING_WORDS or not all(_INTEGER.match(word) for word in tail):
        raise words.error("mu", f"{len(tail)} more words follow mu, starting {tail[0]!r} (one "
                                "trailing integer is ignored): the counts do not match the file")
    return parsed


def _existing(path: str | Path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no problem file {path}")
    return path


def _named(path: Path, error: ValueError) -> ValueError:
    """``error`` with the file named first (messages from the problem constructors lack it)."""
    message = str(error)
    return ValueError(message if message.startswith(str(path)) else f"{path}: {message}")


def read_siconos(path: str | Path, kind: str | None = None) -> LocalProblem:
    """Read a Siconos ``.dat`` problem; a global one is returned in local form.

    Parameters
    ----------
    path : str or Path
    kind : {"local", "global"} or None
        The problem type; None (default) tells them apart by the file's
        structure (a global file has a second matrix, ``H``, after the first).

    Returns
    -------
    LocalProblem
        In our force layout; ``name`` is the file stem.

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        For malformed content; the message names the file, the field and the line.
    """
    path = _existing(path)
    parsed = _parse_checked(path, kind)
    try:
        if parsed[0] == "local":
            _, dim, delassus, q, mu = parsed
            return LocalProblem.from_contact_major(canonical_csr(delassus), q, mu, dim,
                                                   name=_stem(path))
        return _global(path, parsed).to_local()
    except ValueError as exc:
        raise _named(path, exc) from None


def read_siconos_global(path: str | Path) -> GlobalProblem:
    """Read a global Siconos ``.dat`` problem (``gfc2d``/``gfc3d``) as a :class:`GlobalProblem`."""
    path = _existing(path)
    parsed = _parse_checked(path, None)
    if parsed[0] != "global":
        raise ValueError(f"{path}: a local problem (W, q, mu), not a global one (M, H, q, b, mu)")
    try:
        return _global(path, parsed)
    except ValueError as exc:
        raise _named(path, exc) from None


def _parse_checked(path: Path, kind: str | None) -> tuple:
    if kind not in (None, "local", "global"):
        raise ValueError(f"kind: must be 'local', 'global' or None, got {kind!r}")
    try:
        return _parse(path, kind)
    except (IndexError, KeyError, TypeError, OverflowError) as exc:     # a gap in the checks above
        raise ValueError(f"{path}: malformed Siconos file ({type(exc).__name__}: {exc})") from None


def _global(path: Path, parsed: tuple) -> GlobalProblem:
    _, dim, mass, jacobian, q, b, mu = parsed
    return GlobalProblem(M=mass, H=jacobian, f=q, w=b, mu=mu, dim=dim, name=_stem(path))


def _stem(path: Path) -> str:
    return path.name.removesuffix(".dat")


# -- writing --------------------------------------------------------------------------------------
def _numbers(values: np.ndarray) -> str:
    """Space-separated ``repr`` floats: the shortest text that reads back to the same doubles."""
    return " ".join(map(repr, np.asarray(values, dtype=float).tolist()))


def _matrix_text(matrix: sp.spmatrix, storage: int, block: int | None = None) -> list[str]:
    """A NumericsMatrix as ``NM_write_in_file`` lays it out (values in ``repr``)."""
    rows, cols = matrix.shape
    lines = [str(storage), str(rows), str(cols)]
    if storage == DENSE:
        dense = np.asarray(sp.csr_matrix(matrix).toarray())
        lines.append(f"{rows}\t{cols}")
        lines += [_numbers(dense[:, j]) for j in range(cols)]
    elif storage == SPARSE_BLOCK:
        lines += _sparse_block_text(sp.csr_matrix(matrix), block)
    elif storage == SPARSE:
        csc = sp.csc_matrix(matrix)
        csc.sum_duplicates()
        csc.sort_indices()
        norm = float(abs(csc).sum(axis=0).max()) if csc.nnz else 0.0
        lines += ["2", "CSparse Version 3.1.9 (listing written by lubcontact)",
                  f"{rows}-by-{cols}, nzmax: {max(csc.nnz, 1)} nnz: {csc.nnz}, 1-norm: {norm:g}"]
        values, indices, pointers = csc.data.tolist(), csc.indices.tolist(), csc.indptr.tolist()
        for j in range(cols):
            start, stop = pointers[j], pointers[j + 1]
            lines.append(f"    col {j} : locations {start} to {stop - 1}")
            lines += [f"      {indices[k]} : {values[k]!r}" for k in range(start, stop)]
    else:
        raise ValueError(f"storage: must be 0 (dense), 1 (sparse block) or 2 (sparse), got {storage!r}")
    return lines


def _sparse_block_text(matrix: sp.csr_matrix, block: int) -> list[str]:
    """``SBM_write_in_file`` of a square matrix cut in ``block x block`` blocks (diagonal always kept)."""
    n = matrix.shape[0]
    count = n // block
    magnitude = abs(matrix)                             # a copy: the caller's matrix is left alone
    magnitude.eliminate_zeros()
    gather = sp.kron(sp.eye(count), np.ones((block, 1))).tocsr()       # n x count
    blocks = sp.csr_matrix(gather.T @ magnitude @ gather + sp.eye(count))    # non-zero blocks, diagonal
    blocks.sort_indices()
    dense_blocks = matrix.tocsr()
    lines = [str(blocks.nnz), str(count), str(count)]
    ends = "\t".join(str(block * (k + 1)) for k in range(count)) + "\t"
    lines += [ends, ends, str(count + 1), str(blocks.nnz),
              "\t".join(map(str, blocks.indptr.tolist())) + "\t",
              "\t".join(map(str, blocks.indices.tolist())) + "\t"]
    number = 0
    for row in range(count):
        band = dense_blocks[row * block: (row + 1) * block]
        for col in blocks.indices[blocks.indptr[row]: blocks.indptr[row + 1]].tolist():
            values = band[:, col * block: (col + 1) * block].toarray().ravel(order="F")
            lines.append(str(number))
            lines += list(map(repr, values.tolist()))
            number += 1
    return lines


def _default_storage(size: int) -> int:
    return DENSE if size <= DENSE_LIMIT else SPARSE


def write_siconos(problem: LocalProblem | GlobalProblem | StepProblem, path: str | Path, *,
                  storage: int | None = None) -> Path:
    """Write a problem in Siconos ``.dat`` format (module docstring), atomically.

    Parameters
    ----------
    problem : LocalProblem, GlobalProblem or StepProblem
        A local problem is written as ``frictionContact_printInFile`` does
        (``W`` contact-major), a global one as ``globalFrictionContact_printInFile``,
        a step problem as its global form
        (:func:`lubcontact.problem.global_form.global_from_step`).
    path : str or Path
    storage : {0, 1, 2} or None
        Matrix storage: 0 dense, 1 sparse block (``dim x dim`` blocks; local
        problems only), 2 sparse (CSparse compressed columns). Default: dense
        up to :data:`DENSE_LIMIT` rows, else sparse.

    Returns
    -------
    Path
    """
    path = Path(path)
    if isinstance(problem, StepProblem):
        problem = global_from_step(problem)
    if isinstance(problem, GlobalProblem):
        lines = _global_lines(problem, storage)
    elif isinstance(problem, LocalProblem):
        lines = _local_lines(problem, storage)
    else:
        raise ValueError(f"problem: expected a LocalProblem, GlobalProblem or StepProblem, got "
                         f"{type(problem).__name__}")
    with atomic_path(path) as temporary:
        temporary.write_text("\n".join(lines) + "\n")
    return path


def contact_major_delassus(problem: LocalProblem) -> sp.csr_matrix:
    """``W`` of a local problem in FCLIB/Siconos layout (normal first per contact)."""
    order = np.argsort(contact_major_permutation(problem.n_contacts, problem.dim))
    return sp.csr_matrix(problem.delassus[order][:, order])


def _local_lines(problem: LocalProblem, storage: int | None) -> list[str]:
    n, nc, dim = problem.n_rows, problem.n_contacts, problem.dim
    storage = _default_storage(n) if storage is None else storage
    if storage == SPARSE_BLOCK and nc == 0:
        storage = DENSE                                   # an empty SBM has no block to write
    lines = [str(dim), str(nc)]
    lines += _matrix_text(contact_major_delassus(problem), storage, block=dim)
    lines += [_numbers(problem.to_contact_major(problem.free_velocity)), _numbers(problem.cones.mu)]
    return lines


def _global_lines(problem: GlobalProblem, storage: int | None) -> list[str]:
    storage = _default_storage(max(problem.n_dof, problem.H.shape[1])) if storage is None else storage
    if storage not in (DENSE, SPARSE):
        raise ValueError(f"storage: a global problem is written dense (0) or sparse (2), got {storage!r}")
    lines = [str(problem.dim), str(problem.n_contacts)]
    lines += _matrix_text(problem.M, storage) + _matrix_text(problem.H, storage)
    lines += [_numbers(problem.f), _numbers(problem.w), _numbers(problem.mu)]
    return lines
