"""Worker script of the Siconos peer: solve one friction-contact problem with Siconos numerics.

Run by the interpreter that has Siconos' Python bindings (Debian's
``python3-siconos`` installs them for the system interpreter ``/usr/bin/python3``,
built against its numpy 1.x), never imported by lubcontact: this file uses
only the standard library, numpy and ``siconos.numerics``, so that it runs
next to a numpy that lubcontact's own environment (numpy 2) cannot share.
:mod:`lubcontact.solvers.siconos_peer` starts it and reads its answer.

Usage::

    python3 -I siconos_worker.py --probe            # JSON on stdout: versions, solvers
    python3 -I siconos_worker.py INPUT.npz OUTPUT.npz

``INPUT.npz`` (written by the peer; Siconos' contact-major layout: per
contact the normal component, then the ``dim - 1`` tangential ones):

==============  ============================  ===========================================
key             shape, type                   meaning
==============  ============================  ===========================================
``indptr``      (n + 1,) int64                CSR row pointers of ``W``
``indices``     (nnz,) int64                  CSR column indices of ``W``
``data``        (nnz,) float64                CSR values of ``W`` (velocity per force)
``q``           (n,) float64                  free velocity ``q`` (``u = W r + q``)
``mu``          (nc,) float64                 friction coefficients, >= 0
``dim``         () int64                      2 or 3 (``n = nc dim``)
``solver``      () str                        a key of :data:`SOLVERS`
``tol``         () float64                    Siconos' tolerance (``SICONOS_DPARAM_TOL``)
``max_iter``    () int64                      ``SICONOS_IPARAM_MAX_ITER`` (<= 0: default)
``reaction``    (n,) float64                  initial reaction (zeros: cold start)
``rho``         () float64, optional          step of ``desaxce-fp`` (<= 0 or absent: default)
``fclib_tol``   () float64, optional          target of FCLIB's error (<= 0 or absent: none)
==============  ============================  ===========================================

``OUTPUT.npz``: ``reaction`` and ``velocity`` (n,), ``info`` (Siconos' return
code of the last driver call, 0: converged), ``iterations`` (all calls'
``SICONOS_IPARAM_ITER_DONE``), ``max_iter`` (the cap used), ``error``
(Siconos' own error, ``SICONOS_DPARAM_RESIDU``), ``fclib_error`` (FCLIB's,
:func:`fclib_error`), ``siconos_tol`` (the last tolerance given to Siconos),
``rounds`` (one row per driver call: tolerance, info, iterations, Siconos'
error, FCLIB's error), ``build_time`` (seconds to build the matrix and the
problem), ``solve_time`` (seconds of the driver calls only), ``solver_name``
(Siconos' name of the solver), ``siconos_version`` and ``numpy_version``.
A Python exception exits with status 1 and its traceback on stderr.

The Delassus matrix goes to Siconos in its sparse-block storage (blocks of
``dim x dim``, one row of blocks per contact, every diagonal block present),
which ``fc2d_driver`` requires (it has dense and sparse-block NSGS only) and
which is the storage of Siconos' own local problems. The bindings build a
sparse matrix only from scipy objects, and the system interpreter need not
have scipy, so the matrix is written in Siconos' text format
(``NM_write_in_file``: storage 1, the block structure, then each block
column-major, values printed with 17 significant digits, which round-trip
exactly) and read back with ``NM_new_from_filename``.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
import time

import numpy as np

SOLVERS = {
    # key: (dimension, name of the solver constant in siconos.numerics, driver)
    "nsgs-2d": (2, "SICONOS_FRICTION_2D_NSGS", "fc2d_driver"),
    "nsgs": (3, "SICONOS_FRICTION_3D_NSGS", "fc3d_driver"),
    "nsn-ac": (3, "SICONOS_FRICTION_3D_NSN_AC", "fc3d_driver"),
    "prox": (3, "SICONOS_FRICTION_3D_PROX", "fc3d_driver"),
    "desaxce-fp": (3, "SICONOS_FRICTION_3D_DSFP", "fc3d_driver"),
}
"""Solvers this worker can run, by the key the peer sends."""


def probe() -> dict:
    """Versions and the solvers of :data:`SOLVERS` this Siconos build has, as a dict."""
    import siconos
    import siconos.numerics as sn

    found = sorted(key for key, (_, constant, driver) in SOLVERS.items()
                   if hasattr(sn, constant) and hasattr(sn, driver))
    return {"siconos_version": str(getattr(siconos, "version", "unknown")),
            "numpy_version": np.__version__, "python": sys.version.split()[0],
            "solvers": found}


def sparse_block_text(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, dim: int) -> str:
    """``W`` (CSR arrays, contact-major) as the text of a Siconos sparse-block NumericsMatrix.

    Every diagonal block is present (zero if absent from ``W``): Siconos' block
    solvers read the diagonal block of each contact.
    """
    n = indptr.size - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    block_row, block_col = rows // dim, indices // dim
    n_contacts = n // dim
    keys = np.concatenate([block_row * n_contacts + block_col,
                           np.arange(n_contacts) * (n_contacts + 1)])
    unique, where = np.unique(keys, return_inverse=True)
    blocks = np.zeros((unique.size, dim, dim))
    np.add.at(blocks, (where[: rows.size], rows % dim, indices % dim), data)
    unique_rows, unique_cols = unique // n_contacts, unique % n_contacts
    row_pointer = np.searchsorted(unique_rows, np.arange(n_contacts + 1))
    ends = " ".join(str(dim * (c + 1)) for c in range(n_contacts))
    lines = ["1", str(n), str(n), str(unique.size), str(n_contacts), str(n_contacts), ends, ends,
             str(n_contacts + 1), str(unique.size),
             " ".join(map(str, row_pointer)), " ".join(map(str, unique_cols))]
    for number, block in enumerate(blocks):
        lines.append(str(number))
        lines.extend(f"{value:.17e}" for value in block.ravel(order="F"))
    return "\n".join(lines) + "\n"


def build_matrix(sn: object, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                 dim: int) -> object:
    """A Siconos NumericsMatrix in sparse-block storage (through a temporary text file)."""
    handle, path = tempfile.mkstemp(suffix=".txt", prefix="lubcontact-siconos-W-")
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(sparse_block_text(indptr, indices, data, dim))
        matrix = sn.NM_new_from_filename(path)
    finally:
        os.unlink(path)
    if matrix is None or matrix.storageType != sn.NM_SPARSE_BLOCK or matrix.size0 != indptr.size - 1:
        raise RuntimeError("siconos did not read the sparse-block matrix back")
    return matrix


def fclib_error(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, q: np.ndarray,
                mu: np.ndarray, dim: int, reaction: np.ndarray) -> float:
    """FCLIB's error of ``reaction``: ``|r - P_K(r - (u + mu |u_T| e_n))| / (1 + |q|)``, ``u = W r + q``.

    The measure lubcontact applies to every solver (``coulomb_error``);
    Siconos' own divides the same residual by ``max(|q|, |r|, |u|)``.
    """
    n = q.size
    rows = np.repeat(np.arange(n), np.diff(indptr))
    u = np.bincount(rows, weights=data * reaction[indices], minlength=n) + q
    r, u = reaction.reshape(-1, dim), u.reshape(-1, dim)
    slip = np.linalg.norm(u[:, 1:], axis=1)
    x = r.copy()
    x[:, 0] -= u[:, 0] + mu * slip
    x[:, 1:] -= u[:, 1:]
    normal, tangent = x[:, 0], x[:, 1:]
    size = np.linalg.norm(tangent, axis=1)
    inside = (size <= mu * normal) & (normal >= 0)
    polar = mu * size <= -normal
    scale = (normal + mu * size) / (1 + mu * mu)
    ratio = np.divide(mu * scale, size, out=np.zeros_like(size), where=size > 0)
    projected = np.where(inside[:, None], x, np.where(polar[:, None], 0.0,
                         np.column_stack([scale, ratio[:, None] * tangent])))
    return float(np.linalg.norm(r - projected) / (1.0 + np.linalg.norm(q)))


MAX_RESUMES = 4
"""Resumes with a tighter Siconos tolerance when FCLIB's error misses its target."""


def solve(arrays: dict) -> dict:
    """Solve the problem of ``arrays`` (the INPUT keys); returns the OUTPUT dict.

    With ``fclib_tol > 0`` the stopping test is FCLIB's error <= ``fclib_tol``:
    when Siconos stops on its own test (``info == 0``, or no iteration because
    the start already met it) short of it, the driver is called again from the
    reaction reached, Siconos' tolerance multiplied by
    ``min(0.5, 0.5 fclib_tol / error)``, at most :data:`MAX_RESUMES` times,
    within the one iteration budget.
    """
    import siconos
    import siconos.numerics as sn

    dim = int(arrays["dim"])
    key = str(arrays["solver"])
    if key not in SOLVERS:
        raise ValueError(f"solver: unknown key {key!r}; known: {', '.join(sorted(SOLVERS))}")
    needed, constant, driver_name = SOLVERS[key]
    if needed != dim:
        raise ValueError(f"dim: solver {key!r} needs dimension {needed}, got {dim}")
    q = np.ascontiguousarray(arrays["q"], dtype=float)
    mu = np.ascontiguousarray(arrays["mu"], dtype=float)
    if q.size != mu.size * dim:
        raise ValueError(f"q: expected {mu.size * dim} values for {mu.size} contacts, got {q.size}")
    rho = float(arrays["rho"]) if "rho" in arrays else 0.0
    if rho > 0 and key != "desaxce-fp":
        raise ValueError(f"rho: only the De Saxce fixed point takes a step, not {key!r}")
    indptr = np.asarray(arrays["indptr"], dtype=np.int64)
    indices = np.asarray(arrays["indices"], dtype=np.int64)
    data = np.asarray(arrays["data"], dtype=float)
    target = float(arrays["fclib_tol"]) if "fclib_tol" in arrays else 0.0
    start = time.perf_counter()
    matrix = build_matrix(sn, indptr, indices, data, dim)
    problem = sn.FrictionContactProblem(dim, matrix, q, mu)
    solver_id = getattr(sn, constant)
    cap = int(sn.SolverOptions(solver_id).iparam[sn.SICONOS_IPARAM_MAX_ITER])
    if int(arrays["max_iter"]) > 0:                      # else Siconos' default cap
        cap = int(arrays["max_iter"])
    reaction = np.array(arrays["reaction"], dtype=float)
    velocity = np.zeros_like(reaction)
    driver = getattr(sn, driver_name)
    build_time = time.perf_counter() - start
    tol, done, solve_time, rounds = float(arrays["tol"]), 0, 0.0, []
    while True:
        options = sn.SolverOptions(solver_id)            # fresh options: no state carried over
        options.iparam[sn.SICONOS_IPARAM_MAX_ITER] = cap - done
        options.dparam[sn.SICONOS_DPARAM_TOL] = tol
        if rho > 0:                                      # else Siconos' default step
            options.dparam[sn.SICONOS_FRICTION_3D_NSN_RHO] = rho
        clock = time.perf_counter()
        info = driver(problem, reaction, velocity, options)
        solve_time += time.perf_counter() - clock
        iterations = int(options.iparam[sn.SICONOS_IPARAM_ITER_DONE])
        own = float(options.dparam[sn.SICONOS_DPARAM_RESIDU])
        done += iterations
        error = fclib_error(indptr, indices, data, q, mu, dim, reaction)
        rounds.append((tol, info, iterations, own, error))
        stopped_on_own_test = info == 0 or (iterations == 0 and own < tol)
        if (target <= 0 or error <= target or not stopped_on_own_test or done >= cap
                or len(rounds) > MAX_RESUMES):
            break
        tol *= min(0.5, 0.5 * target / error)
    return {"reaction": reaction, "velocity": velocity, "info": np.int64(info),
            "iterations": np.int64(done), "max_iter": np.int64(cap),
            "error": np.float64(own), "fclib_error": np.float64(error),
            "siconos_tol": np.float64(tol), "rounds": np.array(rounds, dtype=float),
            "build_time": np.float64(build_time), "solve_time": np.float64(solve_time),
            "solver_name": np.str_(sn.solver_options_id_to_name(solver_id)),
            "siconos_version": np.str_(getattr(siconos, "version", "unknown")),
            "numpy_version": np.str_(np.__version__)}


def main(argv: list) -> int:
    if argv == ["--probe"]:
        print(json.dumps(probe()))
        return 0
    if len(argv) != 2:
        sys.stderr.write("usage: siconos_worker.py --probe | INPUT.npz OUTPUT.npz\n")
        return 2
    with np.load(argv[0], allow_pickle=False) as stored:
        arrays = {name: stored[name] for name in stored.files}
    result = solve(arrays)
    with open(argv[1], "wb") as stream:
        np.savez(stream, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
