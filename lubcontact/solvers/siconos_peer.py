"""Siconos numerics as an optional peer: its friction-contact solvers in lubcontact's registry.

Siconos (github.com/siconos/siconos) is the reference C library of the
field: FCLIB's error measure is its own, and its NSGS, nonsmooth Newton
(Alart-Curnier), proximal point and De Saxce fixed point solvers are the
baselines of the literature. :func:`register_siconos` registers them as
ordinary methods, so that ``lubcontact compare`` puts them and lubcontact's
solvers in one report, measured alike.

Why a worker process. Debian's ``python3-siconos`` installs the bindings for
the system interpreter (``/usr/bin/python3``) only, built against its numpy
1.x; they cannot be imported next to lubcontact's numpy 2. Each solve
therefore writes ``W`` (CSR arrays), ``q``, ``mu``, the dimension, the solver,
``tol``, ``max_iter`` and the warm start to a temporary ``.npz``, runs
:mod:`lubcontact.solvers.siconos_worker` (a script that imports only the
standard library, numpy and ``siconos.numerics``) under that interpreter
(``python -I``: no ``PYTHONPATH`` from this environment reaches it) and reads
the reaction, velocity, Siconos' return code, iterations, own error and
timings back. The interpreter is ``$LUBCONTACT_SICONOS_PYTHON``, else
:data:`DEFAULT_PYTHON`. Nothing happens at import time: the interpreter is
probed on the first :func:`siconos_status` call (cached per interpreter path).

Registered methods (:data:`METHODS`; those the installed build has):

==========================  =================================================================
name                        Siconos solver
==========================  =================================================================
``siconos-nsgs``            ``SICONOS_FRICTION_2D_NSGS`` (``fc2d_driver``) on 2D problems,
                            ``SICONOS_FRICTION_3D_NSGS`` (``fc3d_driver``) on 3D ones
``siconos-nsn-ac``          ``SICONOS_FRICTION_3D_NSN_AC``: nonsmooth Newton on Alart-Curnier
``siconos-prox``            ``SICONOS_FRICTION_3D_PROX``: proximal point (inner NSN)
``siconos-desaxce-fp``      ``SICONOS_FRICTION_3D_DSFP``: De Saxce fixed point (projection)
==========================  =================================================================

The 3D-only solvers also take 2D problems, embedded in 3D: each contact gets
a second tangential direction, decoupled (its ``W`` row and column zero but
the diagonal, ``q = 0``). On it ``u_t2 = w r_t2``, so a sticking contact
(``u_T = 0``) and a sliding one (``r_T = -mu r_n u_T / |u_T|``, whence
``r_t2 (1 + mu r_n / (w |u_T|)) = 0``) both have ``r_t2 = 0``: every 3D
solution is the 2D solution, and the 3D cone cut at ``r_t2 = 0`` is the 2D
cone. The largest ``|r_t2|`` returned is reported (``info["padding_force"]``).
Frictionless contacts (``NONNEG``, or a friction contact without tangential
rows) go to Siconos with ``mu = 0`` and padded tangential rows the same way.

What the peer solves: exact Coulomb friction, not the convex relaxation.
Registry methods solve the convex problem with the shift ``s`` frozen
(``min 1/2 r.W r + r.(q + [s, 0])`` over the cones); Siconos' friction-contact
solvers solve Coulomb's problem itself (``r`` in ``K``, ``u + mu |u_T| e_n``
in ``K*``, orthogonal, ``u = W r + q``), and no Siconos friction-contact
problem has the relaxed solution for an arbitrary ``s`` (its second-order
cone complementarity solvers do, but they are not the reference solvers this
peer is for; feeding ``q + [s, 0]`` to them would pose a third problem,
shifted *and* with De Saxce's term). So a peer method reads its input as the
Coulomb problem with ``q = b - [s, 0]`` (the offset without the shift) and
returns the exact Coulomb solution ``r*``, whatever ``s``. Its forces solve
the convex problem posed exactly when ``s = mu |u_T(r*)|``, the fixed point
of :func:`~lubcontact.solvers.solve_coulomb`; for any other ``s``, ``solve``
measures the relaxed natural residual of ``r*``, of order ``|s - mu |u_T||``
on sliding contacts (and on separating ones with ``u_n < mu |u_T|``), and
downgrades the claim when it exceeds its check.

Measured (``docs/guide/siconos-peer.md``; ``tests/solvers/test_siconos_peer.py``
locks it): ``solve_coulomb(problem, "siconos-nsgs")`` from ``s = 0`` does
**not** converge in one outer iteration. Its first inner solve already
returns ``r*`` (FCLIB error 4.8e-13 on ``Box_Stacks-i0122-82-5``), but
``solve`` checks it at ``s = 0``: relaxed residual 0.67 against the check's
0.016 there (4 of 82 contacts slide; 7.1 against 0.037 on
``fc2d_granularflowonwall_00667_00000``, 349 of 667), so it is downgraded to
``inaccurate`` and the fixed point stops after that one solve. Started at
``s* = mu |u_T(r*)|`` (``shift=``) it converges in one outer iteration. Use
:func:`~lubcontact.solvers.coulomb.solve_native_coulomb` (what ``solve_coulomb`` does for these
methods, registered with ``native_coulomb=True``): one Siconos run, then the forces go through the
registry's check at ``s*`` (:func:`~lubcontact.solvers.registry.checked`: the check and unit
mapping of every result), where the relaxed residual is Coulomb's; it returns a
:class:`~lubcontact.solvers.CoulombResult` with ``shift = s*``, one outer
iteration and shift change 0 (``g_T`` does not depend on ``s``). It is what
``compare`` should call for these methods.

The De Saxce fixed point has a fixed step ``rho`` (Siconos' default 1, in
the units of the problem it is given). On the normalised problems it ran out
of 100000 iterations on both test files with ``rho = 1`` (Siconos' error 0.71
and 0.12); the peer therefore passes ``rho = 1 / lambda_max(W)``
(:func:`default_rho`) unless the ``rho`` option is given.

Tolerance and units. Methods see the normalised problem (as every registry
method does). FCLIB's error, the measure lubcontact applies to every solver,
is ``|r - P_K(r - (u + mu |u_T| e_n))| / (1 + |q|)``; Siconos 4.4's own
(``fc3d_compute_error``, ``SICONOS_DPARAM_RESIDU``) divides the same residual
by ``max(|q|, |r|, |u|)`` (measured: the ratio of the two errors equals
``|r| / (1 + |q|)`` on the test files), so its test at ``tol`` can stop short
of FCLIB's by ``|r| / (1 + |q|)``: 52 times on ``local_problem_test.hdf5``, 6 on
``LMGC_100_PR_PerioBox`` (with Siconos NSN-AC). With ``criterion="fclib"`` (the default, for
comparisons at equal accuracy) the worker checks FCLIB's error after Siconos
stops on its own test and, while it misses ``tol``, calls the driver again
from the reaction reached with Siconos' tolerance tightened by the ratio
(``siconos_worker.solve``; at most 4 resumes, one iteration budget);
``criterion="siconos"`` is Siconos' own test at ``tol``, one call.
``max_iter`` None keeps Siconos' default cap of each solver.

Statuses: ``converged`` when the stopping test holds (FCLIB's error <= ``tol``;
or, with ``criterion="siconos"``, Siconos' ``info == 0``, or no iteration
done because the start already met Siconos' tolerance: PROX then leaves the
driver's ``info = -1`` untouched, noted in ``info["message"]``); ``max_iter``
when the iteration cap is spent; ``inaccurate`` when Siconos kept stopping
on its own test short of FCLIB's error; ``failed`` for any other non-zero
``info``, and for a worker that crashes, exits non-zero or outlives
``timeout`` (killed; the tail of its stderr in ``info["stderr"]``). Timings:
``solve_time`` is the driver calls alone, timed inside the worker;
``setup_time`` is the conversion here (and :func:`default_rho`) plus the
Siconos matrix and problem build in the worker; everything else (interpreter
start, imports, ``.npz`` files, the FCLIB error checks) is
``info["process_overhead_s"]``.
"""
from __future__ import annotations

import json
import os
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .. import checks
from ..problem.cones import ConeKind
from ..problem.conic import ConicProblem
from .registry import FIRST_ORDER, methods, register, unregister
from .result import CONVERGED, FAILED, INACCURATE, MAX_ITER, MethodOutput

PYTHON_ENV = "LUBCONTACT_SICONOS_PYTHON"
"""Environment variable naming the interpreter that has ``siconos.numerics``."""

DEFAULT_PYTHON = "/usr/bin/python3"
"""The interpreter Debian's ``python3-siconos`` installs the bindings for."""

WORKER = Path(__file__).with_name("siconos_worker.py")
"""The worker script (run, never imported)."""

PROBE_TIMEOUT = 60.0
"""Seconds the probe of the interpreter may take (starting Python and importing Siconos)."""

DEFAULT_TIMEOUT = 3600.0
"""Seconds one solve's worker may run before it is killed (``timeout`` option)."""

STDERR_TAIL = 2000
"""Characters of a failed worker's stderr kept in ``info["stderr"]``."""

CRITERIA = ("fclib", "siconos")
"""Stopping tests of the peer (``criterion`` option; module docstring)."""

SICONOS_CONES = frozenset({ConeKind.COULOMB, ConeKind.NONNEG})
"""Contact kinds a Siconos friction-contact problem expresses (NONNEG as ``mu = 0``)."""


@dataclass(frozen=True)
class PeerMethod:
    """One registered Siconos solver.

    Attributes
    ----------
    name : str
        Registered name.
    key_2d, key_3d : str or None
        Worker solver keys (``siconos_worker.SOLVERS``) for 2D and 3D problems;
        None for 2D: the problem is embedded in 3D and ``key_3d`` solves it.
    description : str
        One line for tables.
    """

    name: str
    key_2d: str | None
    key_3d: str
    description: str


METHODS = (
    PeerMethod("siconos-nsgs", "nsgs-2d", "nsgs",
               "Siconos NSGS (nonsmooth Gauss-Seidel; fc2d_driver in 2D, fc3d_driver in 3D), exact Coulomb"),
    PeerMethod("siconos-nsn-ac", None, "nsn-ac",
               "Siconos NSN-AC (nonsmooth Newton, Alart-Curnier; 2D embedded in 3D), exact Coulomb"),
    PeerMethod("siconos-prox", None, "prox",
               "Siconos PROX (proximal point, inner NSN-AC; 2D embedded in 3D), exact Coulomb"),
    PeerMethod("siconos-desaxce-fp", None, "desaxce-fp",
               "Siconos DSFP (De Saxce fixed point projection; 2D embedded in 3D), exact Coulomb"),
)
"""The peer's methods, in registration order."""


@dataclass(frozen=True)
class SiconosStatus:
    """Whether the peer can run, and with what.

    Attributes
    ----------
    available : bool
        The interpreter runs and imports ``siconos.numerics``.
    python : str
        The interpreter probed.
    reason : str
        Why not (empty when available).
    siconos_version, numpy_version : str
        As the worker reports them (empty when unavailable).
    solvers : tuple of str
        Worker solver keys the build has.
    """

    available: bool
    python: str
    reason: str = ""
    siconos_version: str = ""
    numpy_version: str = ""
    solvers: tuple = field(default_factory=tuple)


def siconos_python() -> str:
    """The interpreter the peer runs: ``$LUBCONTACT_SICONOS_PYTHON``, else :data:`DEFAULT_PYTHON`."""
    return os.environ.get(PYTHON_ENV) or DEFAULT_PYTHON


def siconos_status() -> SiconosStatus:
    """Probe :func:`siconos_python` (once per interpreter path; cached).

    Never raises: an interpreter that is missing, fails, times out or lacks
    Siconos gives ``available=False`` with the reason.
    """
    return _probe(siconos_python())


def siconos_available() -> bool:
    """Whether the peer can run (:func:`siconos_status` says why not)."""
    return siconos_status().available


def clear_probe_cache() -> None:
    """Forget the probes (after installing Siconos or changing the interpreter)."""
    _probe.cache_clear()


@cache
def _probe(python: str) -> SiconosStatus:
    command = [python, "-I", str(WORKER), "--probe"]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=PROBE_TIMEOUT,
                              stdin=subprocess.DEVNULL)
    except FileNotFoundError:
        return SiconosStatus(False, python, f"interpreter {python} not found (install Debian's "
                                            f"python3-siconos or set ${PYTHON_ENV})")
    except (OSError, subprocess.SubprocessError) as exc:
        return SiconosStatus(False, python, f"interpreter {python} could not run: {exc}")
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        return SiconosStatus(False, python, f"{python} cannot import siconos.numerics (or numpy): {last}")
    try:
        found = json.loads(done.stdout.strip().splitlines()[-1])
        solvers = tuple(found["solvers"])
        versions = str(found["siconos_version"]), str(found["numpy_version"])
    except (IndexError, KeyError, TypeError, ValueError):
        return SiconosStatus(False, python, f"{python}: unreadable probe answer {done.stdout[-200:]!r}")
    if not solvers:
        return SiconosStatus(False, python, f"siconos {versions[0]} under {python} has none of the "
                                            f"friction-contact solvers used", *versions)
    return SiconosStatus(True, python, "", *versions, solvers=solvers)


# -- registration ---------------------------------------------------------------------------------
def available_methods(status: SiconosStatus | None = None) -> list[str]:
    """Names of :data:`METHODS` the installed Siconos can run (empty when it is absent)."""
    status = siconos_status() if status is None else status
    if not status.available:
        return []
    return [m.name for m in METHODS if m.key_3d in status.solvers]


def is_peer_method(name: str) -> bool:
    """Whether ``name`` is one of the peer's methods (registered or not)."""
    return name in {m.name for m in METHODS}


def register_siconos() -> list[str]:
    """Register the available Siconos methods; returns their names (empty without Siconos).

    Idempotent: names already registered are kept and returned. Capabilities:
    ``kind="first-order"`` (the registry's families have no nonsmooth-Newton
    one), contacts COULOMB and NONNEG, 2D and 3D, warm start (Siconos starts
    from the reaction it is given), no polishing, local and step problems.
    """
    status = siconos_status()
    names = available_methods(status)
    present = set(methods())
    for method in METHODS:
        if method.name in names and method.name not in present:
            key_2d = method.key_2d if method.key_2d in status.solvers else None
            register(method.name, kind=FIRST_ORDER, cones=SICONOS_CONES, second_order=True,
                     warm_start=True, polishing=False, step_only=False, native_coulomb=True,
                     description=method.description)(_make_method(method.name, key_2d, method.key_3d))
    return names


def unregister_siconos() -> list[str]:
    """Remove every registered Siconos method; returns the names removed."""
    removed = [m.name for m in METHODS if m.name in methods()]
    for name in removed:
        unregister(name)
    return removed


def _make_method(name: str, key_2d: str | None, key_3d: str) -> Callable[..., MethodOutput]:
    def method(problem: ConicProblem, *, tol: float, max_iter: int | None = None,
               warm_start: np.ndarray | None = None, timeout: float = DEFAULT_TIMEOUT,
               rho: float | None = None, criterion: str = "fclib") -> MethodOutput:
        return solve_with_siconos(problem, key_2d, key_3d, tol=tol, max_iter=max_iter,
                                  warm_start=warm_start, timeout=timeout, rho=rho,
                                  criterion=criterion)

    method.__name__ = name.replace("-", "_")
    method.__doc__ = f"""{name}: exact Coulomb friction by Siconos (lubcontact.solvers.siconos_peer).

    Parameters
    ----------
    problem : ConicProblem
        Normalised; read as Coulomb's problem with ``q = b - [s, 0]``.
    tol : float
        FCLIB's error of the normalised problem to reach (criterion ``"fclib"``),
        or Siconos' tolerance on its own error (``"siconos"``).
    max_iter : int, optional
        Siconos' iteration cap (its default when None).
    warm_start : ndarray, shape (n_rows,), optional
        Initial reaction (normalised).
    timeout : float
        Seconds before the worker is killed (status ``failed``).
    rho : float, optional
        Step of ``siconos-desaxce-fp`` only (default ``1 / lambda_max(W)``).
    criterion : str
        ``"fclib"`` (default) or ``"siconos"``: the stopping test.
    """
    return method


# -- one solve ----------------------------------------------------------------------------------
@dataclass
class SiconosLayout:
    """A problem in Siconos' layout (contact-major, ``dim`` rows per contact) and the way back.

    Attributes
    ----------
    delassus : scipy.sparse.csr_matrix, shape (nc * dim, nc * dim)
        ``W`` with padded rows (decoupled, diagonal ``padding``).
    free_velocity : ndarray, shape (nc * dim,)
        ``q`` (0 on padded rows).
    mu : ndarray, shape (nc,)
        Friction coefficients (0 for frictionless contacts).
    dim : int
        2 or 3.
    rows : ndarray of int, shape (n_rows,)
        Siconos row of each of our rows: ``ours = siconos[rows]``.
    padded : ndarray of int
        Siconos rows with no row of ours.
    """

    delassus: sp.csr_matrix
    free_velocity: np.ndarray
    mu: np.ndarray
    dim: int
    rows: np.ndarray
    padded: np.ndarray

    @classmethod
    def of(cls, problem: ConicProblem, dim: int | None = None) -> SiconosLayout:
        """Siconos' Coulomb problem of ``problem``: ``q = b - [s, 0]``, in ``dim`` (default: its own).

        Raises
        ------
        ValueError
            For contacts Siconos cannot express (FREE, NONPOS, UNION) or a
            ``dim`` below the problem's.
        """
        cones = problem.cones
        own = cones.tangent_dim + 1
        dim = own if dim is None else int(dim)
        checks.require(dim in (2, 3) and dim >= own, "dim", f"must be 2 or 3 and >= {own}", dim)
        kinds = {ConeKind(k).name for k in np.unique(cones.kinds)} - {k.name for k in SICONOS_CONES}
        checks.require(not kinds, "cones", "Siconos solves COULOMB and NONNEG contacts only, got "
                       + " and ".join(sorted(kinds)))
        nc, n = cones.count, cones.n_rows
        rows = np.empty(n, dtype=np.int64)
        rows[:nc] = np.arange(nc) * dim
        tangential = np.asarray(cones.tangential, dtype=np.int64)
        td = cones.tangent_dim
        if tangential.size:
            rows[nc:] = (tangential[:, None] * dim + 1 + np.arange(td)).ravel()
        padded = np.setdiff1d(np.arange(nc * dim), rows)
        q = np.asarray(problem.offset, dtype=float).copy()
        q[:nc] -= problem.shift
        free_velocity = np.zeros(nc * dim)
        free_velocity[rows] = q
        frictional = np.zeros(nc, dtype=bool)
        frictional[tangential] = cones.mask(ConeKind.COULOMB)[tangential]
        mu = np.where(frictional, cones.mu, 0.0)
        W = sp.coo_matrix(problem.delassus)
        diagonal = W.diagonal()
        padding = float(np.mean(diagonal)) if diagonal.size and np.mean(diagonal) > 0 else 1.0
        delassus = sp.csr_matrix(
            (np.concatenate([W.data, np.full(padded.size, padding)]),
             (np.concatenate([rows[W.row], padded]), np.concatenate([rows[W.col], padded]))),
            shape=(nc * dim, nc * dim))
        delassus.sum_duplicates()
        delassus.sort_indices()
        return cls(delassus=delassus, free_velocity=free_velocity, mu=mu, dim=dim, rows=rows,
                   padded=padded)

    def to_siconos(self, vector: np.ndarray) -> np.ndarray:
        """One of our vectors in Siconos' layout (0 on padded rows)."""
        out = np.zeros(self.free_velocity.size)
        out[self.rows] = vector
        return out


def run_worker(delassus: sp.spmatrix, free_velocity: np.ndarray, mu: np.ndarray, dim: int,
               solver: str, *, tol: float, max_iter: int | None = None,
               reaction: np.ndarray | None = None, rho: float | None = None,
               fclib_tol: float | None = None, timeout: float = DEFAULT_TIMEOUT,
               python: str | None = None) -> dict:
    """Solve one problem given in Siconos' layout in the worker process.

    Parameters
    ----------
    delassus : sparse, shape (nc * dim, nc * dim)
        ``W`` (velocity per force), contact-major.
    free_velocity : ndarray, shape (nc * dim,)
        ``q``.
    mu : ndarray, shape (nc,)
    dim : int
        2 or 3.
    solver : str
        A worker solver key (``siconos_worker.SOLVERS``).
    tol : float
        Siconos' (first) tolerance on its own error, > 0.
    max_iter : int, optional
        Siconos' iteration cap (its default when None).
    reaction : ndarray, shape (nc * dim,), optional
        Initial reaction (zeros when None).
    rho : float, optional
        Step of the De Saxce fixed point (``desaxce-fp`` only), > 0; Siconos'
        default (1) when None.
    fclib_tol : float, optional
        Target of FCLIB's error, > 0: the worker resumes Siconos with a tighter
        tolerance while its own test stops short of it
        (``siconos_worker.solve``); None: Siconos' own test only.
    timeout : float
        Seconds before the worker is killed.
    python : str, optional
        The interpreter (default :func:`siconos_python`).

    Returns
    -------
    dict
        ``ok`` (bool); when True the worker's outputs (``reaction``,
        ``velocity``, ``info``, ``iterations``, ``error``, ``build_time``,
        ``solve_time``, ``solver_name``, versions); when False ``message``,
        ``returncode`` and ``stderr`` (tail). Always ``worker_wall_s``.

    Raises
    ------
    ValueError
        For inconsistent shapes or a bad ``tol``, ``max_iter`` or ``timeout``.
    """
    dim = checks.integer("dim", dim, minimum=2)
    checks.require(dim in (2, 3), "dim", "must be 2 or 3", dim)
    mu = checks.nonnegative("mu", mu, shape=(None,))
    n = mu.size * dim
    W = sp.csr_matrix(delassus, dtype=float)
    checks.require(W.shape == (n, n), "W", f"expected shape {(n, n)}", W.shape)
    q = checks.as_array("q", free_velocity, shape=(n,))
    tol = checks.positive_scalar("tol", tol)
    timeout = checks.positive_scalar("timeout", timeout)
    cap = -1 if max_iter is None else checks.integer("max_iter", max_iter, minimum=1)
    start = np.zeros(n) if reaction is None else checks.as_array("reaction", reaction, shape=(n,))
    step = 0.0 if rho is None else checks.positive_scalar("rho", rho)
    target = 0.0 if fclib_tol is None else checks.positive_scalar("fclib_tol", fclib_tol)
    W.sort_indices()
    python = python or siconos_python()
    clock = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="lubcontact-siconos-") as folder:
        given, answer = Path(folder) / "problem.npz", Path(folder) / "solution.npz"
        np.savez(given, indptr=W.indptr.astype(np.int64), indices=W.indices.astype(np.int64),
                 data=W.data, q=q, mu=mu, dim=np.int64(dim), solver=np.str_(solver),
                 tol=np.float64(tol), max_iter=np.int64(cap), reaction=start,
                 rho=np.float64(step), fclib_tol=np.float64(target))
        try:
            done = subprocess.run([python, "-I", str(WORKER), str(given), str(answer)],
                                  capture_output=True, text=True, timeout=timeout,
                                  stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired as exc:
            return _failure(f"worker timed out after {timeout:g} s (killed)", None, exc.stderr, clock)
        except OSError as exc:
            return _failure(f"worker could not start ({python}): {exc}", None, "", clock)
        if done.returncode != 0 or not answer.exists():
            return _failure(f"worker exited with status {done.returncode}", done.returncode,
                            done.stderr, clock)
        with np.load(answer, allow_pickle=False) as stored:
            out = {name: stored[name] for name in stored.files}
    out = {name: (value.item() if value.ndim == 0 else value) for name, value in out.items()}
    out.update(ok=True, worker_wall_s=time.perf_counter() - clock)
    return out


def _failure(message: str, returncode: int | None, stderr: str | bytes | None, clock: float) -> dict:
    if isinstance(stderr, bytes):
        stderr = stderr.decode(errors="replace")
    return dict(ok=False, message=message, returncode=returncode,
                stderr=(stderr or "")[-STDERR_TAIL:], worker_wall_s=time.perf_counter() - clock)


def solve_with_siconos(problem: ConicProblem, key_2d: str | None, key_3d: str, *, tol: float,
                       max_iter: int | None = None, warm_start: np.ndarray | None = None,
                       timeout: float = DEFAULT_TIMEOUT, rho: float | None = None,
                       criterion: str = "fclib") -> MethodOutput:
    """The body of every peer method: exact Coulomb of ``problem`` (``q = b - [s, 0]``) by Siconos.

    Parameters
    ----------
    problem : ConicProblem
        Normalised (as the registry passes it).
    key_2d, key_3d : str or None, str
        Worker solver keys (see :class:`PeerMethod`).
    tol, max_iter, warm_start, timeout
        As for every method; ``warm_start`` in our layout (normalised forces).
    rho : float, optional
        Step of the De Saxce fixed point (``desaxce-fp``), > 0; default
        ``1 / lambda_max(W)`` (see :func:`default_rho`).
    criterion : str
        ``"fclib"`` (default): converged when FCLIB's error of the normalised
        problem is <= ``tol``, Siconos resumed with a tighter tolerance while
        its own test stops short of that; ``"siconos"``: Siconos' own test at
        ``tol``, one driver call (see the module docstring).

    Returns
    -------
    MethodOutput
        Forces in our layout; ``info`` has ``siconos_info``, ``siconos_error``,
        ``fclib_error``, ``siconos_tol``, ``siconos_calls``, ``criterion``,
        ``siconos_solver``, ``siconos_version``, ``worker_numpy``,
        ``exact_coulomb`` (True), ``padding_force``, ``dim``,
        ``process_overhead_s``, ``conversion_s``, ``worker_build_s`` and,
        on failure, ``message``, ``returncode`` and ``stderr``.
    """
    clock = time.perf_counter()
    dim = problem.cones.tangent_dim + 1
    key, solve_dim = (key_2d, 2) if dim == 2 and key_2d is not None else (key_3d, 3)
    layout = SiconosLayout.of(problem, solve_dim)
    start = None if warm_start is None else layout.to_siconos(warm_start)
    checks.require(criterion in CRITERIA, "criterion", f"must be one of {CRITERIA}, got {criterion!r}")
    checks.require(rho is None or key == "desaxce-fp", "rho",
                   f"only the De Saxce fixed point takes a step, not {key!r}")
    if key == "desaxce-fp" and rho is None:
        rho = default_rho(layout.delassus)
    converted = time.perf_counter() - clock
    out = run_worker(layout.delassus, layout.free_velocity, layout.mu, layout.dim, key, tol=tol,
                     max_iter=max_iter, reaction=start, rho=rho, timeout=timeout,
                     fclib_tol=tol if criterion == "fclib" else None)
    info = dict(exact_coulomb=True, dim=solve_dim, siconos_key=key, conversion_s=converted,
                python=siconos_python(), criterion=criterion)
    if rho is not None:
        info["rho"] = float(rho)
    if not out["ok"]:
        info.update(message=out["message"], returncode=out["returncode"], stderr=out["stderr"],
                    worker_wall_s=out["worker_wall_s"],
                    process_overhead_s=time.perf_counter() - clock - converted)
        return MethodOutput(np.zeros(problem.n_rows), FAILED, 0, setup_time=converted,
                            solve_time=0.0, info=info)
    reaction = np.asarray(out["reaction"], dtype=float)
    code, iterations = int(out["info"]), int(out["iterations"])
    cap, error, fclib = int(out["max_iter"]), float(out["error"]), float(out["fclib_error"])
    rounds = np.atleast_2d(out["rounds"])
    started_solved = code != 0 and int(rounds[-1, 2]) == 0 and error < float(out["siconos_tol"])
    own_test = code == 0 or started_solved
    if criterion == "fclib" and fclib <= tol or criterion == "siconos" and own_test:
        status = CONVERGED
    elif iterations >= cap:
        status = MAX_ITER
    else:                        # Siconos failed, or stopped on its test short of FCLIB's
        status = INACCURATE if own_test else FAILED
    setup = converted + float(out["build_time"])
    solve_time = float(out["solve_time"])
    info.update(siconos_info=code, siconos_error=error, fclib_error=fclib,
                siconos_tol=float(out["siconos_tol"]), siconos_calls=int(rounds.shape[0]),
                siconos_solver=str(out["solver_name"]), siconos_max_iter=cap,
                siconos_version=str(out["siconos_version"]),
                worker_numpy=str(out["numpy_version"]), worker_build_s=float(out["build_time"]),
                padding_force=float(np.max(np.abs(reaction[layout.padded]), initial=0.0)),
                worker_wall_s=float(out["worker_wall_s"]),
                process_overhead_s=max(time.perf_counter() - clock - setup - solve_time, 0.0))
    if status == INACCURATE:
        info["message"] = (f"Siconos {info['siconos_solver']} stopped on its own test "
                           f"{rounds.shape[0]} times (last tolerance {info['siconos_tol']:.1e}) "
                           f"with FCLIB's error still {fclib:.3e} > tol")
    elif started_solved:                  # PROX leaves info as the driver set it (-1) then
        info["message"] = (f"Siconos {info['siconos_solver']} did no iteration: the initial "
                           f"reaction met its tolerance (its error {error:.3e}); info={code} left unset")
    elif code != 0:
        info["message"] = (f"Siconos {info['siconos_solver']} returned info={code} after "
                           f"{iterations} iterations, its error {error:.3e}, FCLIB's {fclib:.3e}")
    return MethodOutput(reaction[layout.rows], status, iterations, setup_time=setup,
                        solve_time=solve_time, info=info)


def default_rho(delassus: sp.spmatrix) -> float:
    """The De Saxce fixed point's step given to Siconos: ``1 / lambda_max(W)``.

    Siconos' DSFP uses a fixed step, by default 1 in the problem's units,
    which only converges when ``lambda_max(W)`` is below about 2; on the
    normalised problems (mean diagonal of ``W`` 1) it ran out of 100000
    iterations on both files of the tests (``docs/guide/siconos-peer.md``).
    ``1 / lambda_max`` is the projected-gradient step of the monotone part
    (largest eigenvalue of the symmetric part of ``W``, Lanczos; dense below
    50 rows).
    """
    W = sp.csr_matrix(delassus, dtype=float)
    symmetric = 0.5 * (W + W.T)
    if W.shape[0] < 50:
        largest = float(np.linalg.eigvalsh(symmetric.toarray())[-1])
    else:
        from scipy.sparse.linalg import eigsh
        largest = float(eigsh(symmetric, k=1, which="LA", return_eigenvectors=False,
                              v0=np.ones(W.shape[0]))[0])
    return 1.0 / largest if largest > 0 else 1.0


# -- exact Coulomb in one call ----------------------------------------------------------------------
