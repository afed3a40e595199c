"""Global frictional contact problems (FCLIB ``fclib_global``, Siconos ``gfc2d``/``gfc3d``).

The global form, over generalised velocities ``v`` (n_dof), contact forces
``r`` and local velocities ``u`` (``m = dim nc`` each, contact-major: per
contact the normal component, then the tangential ones)::

    M v = H r + f,   u = H^T v + w,   C*_mu  ∋  u + [mu_c |u_T,c|, 0]  ⟂  r  ∈  C_mu

(FCLIB's ``fclib.h``; Siconos' ``GlobalFrictionContactProblem`` writes the same
thing as ``M v = q + H r``, ``u = H^T v + b``, and its FCLIB interface maps
``f <-> q``, ``w <-> b`` with no sign change). Eliminating ``v`` gives the
local problem ``u = W r + q_loc`` with ``W = H^T M^-1 H`` and
``q_loc = H^T M^-1 f + w`` (:func:`global_to_local`, Siconos'
``globalFrictionContact_reformulation_FrictionContact``).

A :class:`~lubcontact.problem.StepProblem` is a global problem
(:func:`global_from_step`). Its step ``v = U + dt M^-1 J^T lam`` and constraint
values ``g = [D + s, 0] + dt J v`` (``J``: our jacobian, normal rows then
tangential rows) are FCLIB's equations with::

    r = E lam,   u = E g (s = 0),   H = dt J^T E^T,   f = M U,   w = E [D, 0]

where ``E`` (m x n_rows) sends each of our rows to its contact-major row. Then
``W_loc = E (dt^2 J M^-1 J^T) E^T = E W E^T`` and ``q_loc = E b``: the step's
own ``W`` and ``b`` (with ``s = 0``: FCLIB's De Saxce term ``mu |u_T|`` *is*
the shift of our fixed point), re-ordered and with no scaling. ``r`` is the
contact force, ``u`` a length (the gap after the step, ``D + dt u_n``, and
``dt u_T``), ``v`` the velocity after the step.

FCLIB and Siconos know only Coulomb cones with ``dim`` rows per contact:

- COULOMB contacts with tangential rows are written as they are;
- NONNEG (frictionless) contacts, and any contact without tangential rows,
  get ``mu = 0`` and zero tangential columns in ``H`` (so ``u_T = 0``,
  ``r_T = 0``): the cone ``{r_T = 0, r_n >= 0}`` is exactly their half-line;
- FREE (bilateral), NONPOS (pulled) and UNION (gluey) contacts have no FCLIB
  equivalent: :func:`global_from_step` and :func:`local_from_step` raise
  ``ValueError`` naming them.

:func:`delassus_diagnostics` reports how far a Delassus matrix read from a
file is from symmetric positive semi-definite (real files are not always).
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import checks
from .cones import ConeKind, Cones
from .local import LocalProblem, contact_major_permutation
from .step import StepProblem

DENSE_EIGEN_LIMIT = 3000
"""Below this many rows :func:`delassus_diagnostics` uses a dense eigensolver."""


@dataclass
class GlobalProblem:
    """``M v = H r + f``, ``u = H^T v + w`` with Coulomb cones (FCLIB layout, contact-major).

    Attributes
    ----------
    M : scipy.sparse.csr_matrix, shape (n_dof, n_dof)
        Mass matrix (invertible; symmetric positive definite in FCLIB).
    H : scipy.sparse.csr_matrix, shape (n_dof, m)
        Transposed contact jacobian, ``m = dim * nc``.
    f : ndarray, shape (n_dof,)
        Force term (Siconos ``q``).
    w : ndarray, shape (m,)
        Local offset (Siconos ``b``).
    mu : ndarray, shape (nc,)
        Friction coefficients, >= 0.
    dim : int
        2 or 3.
    name : str
        Where the problem came from.
    """

    M: sp.csr_matrix
    H: sp.csr_matrix
    f: np.ndarray
    w: np.ndarray
    mu: np.ndarray
    dim: int
    name: str = ""

    def __post_init__(self):
        checks.require(self.dim in (2, 3), "dim", "must be 2 or 3", self.dim)
        self.dim = int(self.dim)
        self.M, self.H = canonical_csr(self.M), canonical_csr(self.H)
        n_dof = self.M.shape[0]
        checks.require(self.M.shape == (n_dof, n_dof), "M", "must be square", self.M.shape)
        checks.as_array("M", self.M.data)
        checks.as_array("H", self.H.data)
        self.mu = checks.nonnegative("mu", self.mu, shape=(None,))
        m = self.dim * self.mu.shape[0]
        checks.require(self.H.shape == (n_dof, m), "H",
                       f"expected shape {(n_dof, m)} (rows of M, dim x {self.mu.shape[0]} contacts)",
                       self.H.shape)
        self.f = checks.as_array("f", self.f, shape=(n_dof,))
        self.w = checks.as_array("w", self.w, shape=(m,))

    @property
    def n_dof(self) -> int:
        return self.M.shape[0]

    @property
    def n_contacts(self) -> int:
        return self.mu.shape[0]

    def to_local(self) -> LocalProblem:
        """The local problem ``u = W r + q`` (``W = H^T M^-1 H``), in our force layout."""
        delassus, q = global_to_local(self.M, self.H, self.f, self.w)
        return LocalProblem.from_contact_major(canonical_csr(delassus), q, self.mu, self.dim,
                                               name=self.name)

    def velocity(self, forces: np.ndarray) -> np.ndarray:
        """``v = M^-1 (H r + f)`` for forces ``r`` in FCLIB layout, shape (n_dof,)."""
        forces = checks.as_array("r", forces, shape=(self.H.shape[1],))
        return _solve(self.M, np.reshape(self.H @ forces + self.f, (-1, 1)))[:, 0]

    def local_velocity(self, forces: np.ndarray) -> np.ndarray:
        """``u = H^T v + w`` for forces ``r`` in FCLIB layout, shape (m,)."""
        return self.H.T @ self.velocity(forces) + self.w


def canonical_csr(matrix: sp.spmatrix | np.ndarray) -> sp.csr_matrix:
    """A CSR copy with duplicates summed, indices sorted and stored zeros dropped.

    Two matrices with the same entries then have the same arrays, so that a
    product with them rounds the same way (readers return this form).
    """
    out = sp.csr_matrix(matrix, dtype=float, copy=True)
    out.sum_duplicates()
    out.eliminate_zeros()
    out.sort_indices()
    return out


def _solve(mass: sp.spmatrix, rhs: np.ndarray | sp.spmatrix) -> np.ndarray | sp.csc_matrix:
    """``M^-1 rhs`` (rhs dense (n, k) or sparse); ``ValueError`` naming M when it is singular."""
    mass = sp.csc_matrix(mass)
    diagonal = mass.diagonal()
    if (mass - sp.diags(diagonal)).count_nonzero() == 0:
        if np.any(diagonal == 0):
            raise ValueError(f"M: singular (zero diagonal entry at index {np.flatnonzero(diagonal == 0)[0]})")
        if sp.issparse(rhs):
            return sp.csc_matrix(sp.diags(1.0 / diagonal) @ rhs)
        return np.asarray(rhs, dtype=float) / diagonal[:, None]
    try:
        factor = spla.splu(mass)
    except RuntimeError as exc:
        raise ValueError(f"M: singular ({exc})") from None
    if sp.issparse(rhs):
        rhs = rhs.toarray()
    out = factor.solve(np.asarray(rhs, dtype=float))
    if not np.all(np.isfinite(out)):
        raise ValueError("M: singular (non-finite solve)")
    return out


def global_to_local(mass: sp.spmatrix, jacobian: sp.spmatrix, force: np.ndarray,
                    offset: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """``W = H^T M^-1 H`` and ``q = H^T M^-1 f + w`` of ``M v = H r + f``, ``u = H^T v + w``.

    Parameters
    ----------
    mass : sparse or dense, shape (n_dof, n_dof)
        ``M``, invertible (a diagonal ``M`` is inverted entry-wise, otherwise LU).
    jacobian : sparse or dense, shape (n_dof, m)
        ``H``.
    force, offset : ndarray, shapes (n_dof,), (m,)
        ``f`` and ``w``.

    Returns
    -------
    (scipy.sparse.csr_matrix (m, m), ndarray (m,))
    """
    mass, jacobian = sp.csc_matrix(mass), sp.csc_matrix(jacobian)
    n_dof, n_rows = jacobian.shape
    checks.require(mass.shape == (n_dof, n_dof), "M", f"expected shape {(n_dof, n_dof)} (rows of H)",
                   mass.shape)
    force = checks.as_array("f", force, shape=(n_dof,))
    offset = checks.as_array("w", offset, shape=(n_rows,))
    diagonal = (mass - sp.diags(mass.diagonal())).count_nonzero() == 0
    if diagonal or n_dof * n_rows > 20_000_000:
        inverse_h = sp.csc_matrix(_solve(mass, jacobian)) if diagonal else \
            sp.csc_matrix(spla.spsolve(mass, jacobian))
        if not np.all(np.isfinite(inverse_h.data)):
            raise ValueError("M: singular (non-finite solve)")
    else:
        inverse_h = sp.csc_matrix(_solve(mass, jacobian.toarray()))
    inverse_f = _solve(mass, force.reshape(-1, 1))[:, 0]
    delassus = sp.csr_matrix(jacobian.T @ inverse_h)
    return delassus, jacobian.T @ inverse_f + offset


# -- step problems in FCLIB form ------------------------------------------------------------------
def _step_expansion(step: StepProblem) -> tuple[sp.csr_matrix, np.ndarray]:
    """``E`` (dim nc x n_rows) from our rows to contact-major rows, and FCLIB's ``mu``."""
    cones = step.cones
    nc, tangent_dim = cones.count, cones.tangent_dim
    checks.require(tangent_dim in (1, 2), "cones.tangent_dim",
                   "must be 1 or 2 (FCLIB problems are 2D or 3D)", tangent_dim)
    for kind in (ConeKind.FREE, ConeKind.NONPOS, ConeKind.UNION):
        bad = np.flatnonzero(cones.mask(kind))
        if bad.size:
            raise ValueError(f"cones: contact {bad[0]} is {kind.name} ({bad.size} such contacts); "
                             "FCLIB/Siconos problems have Coulomb cones only (COULOMB or NONNEG "
                             "contacts can be written)")
    dim = tangent_dim + 1
    coulomb = cones.mask(ConeKind.COULOMB)
    rows = [np.arange(nc) * dim]
    cols = [np.arange(nc)]
    tangential = np.asarray(cones.tangential, dtype=int)
    keep = coulomb[tangential]
    contacts = np.repeat(tangential[keep], tangent_dim)
    component = np.tile(np.arange(tangent_dim), int(keep.sum()))
    ours = nc + (np.flatnonzero(keep)[:, None] * tangent_dim + np.arange(tangent_dim)).ravel()
    rows.append(contacts * dim + 1 + component)
    cols.append(ours)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    expansion = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(dim * nc, cones.n_rows))
    with_rows = np.zeros(nc, dtype=bool)
    with_rows[tangential[keep]] = True
    mu = np.where(with_rows, cones.mu, 0.0)
    return expansion, mu


def global_from_step(step: StepProblem, name: str = "") -> GlobalProblem:
    """The step problem as an FCLIB global problem (module docstring for the mapping).

    Its local form (:meth:`GlobalProblem.to_local`) has ``W = E W_step E^T`` and
    ``q = E b_step`` (``b_step`` with a zero shift): no scaling.

    Raises
    ------
    ValueError
        For FREE, NONPOS or UNION (gluey) contacts, which FCLIB cannot express.
    """
    expansion, mu = _step_expansion(step)
    dim = step.cones.tangent_dim + 1
    mass = sp.diags(step.mass).tocsr()
    jacobian = sp.csr_matrix(step.dt * (expansion @ step.jacobian).T)
    constant = step.with_shift(np.zeros(step.n_contacts)).constant_rows   # [D, 0] + moving walls
    return GlobalProblem(M=mass, H=jacobian, f=step.mass * step.free_velocity,
                         w=expansion @ constant, mu=mu, dim=dim, name=name)


def local_from_step(step: StepProblem, name: str = "") -> LocalProblem:
    """The step problem as a local Coulomb problem ``u = W r + q`` (module docstring).

    ``W`` and ``q`` are the step's ``W`` and ``b`` (zero shift), with a zero
    row and column for each missing tangential row; forces map as
    :func:`step_forces_to_local`.

    Raises
    ------
    ValueError
        For FREE, NONPOS or UNION (gluey) contacts.
    """
    expansion, mu = _step_expansion(step)
    nc, dim = step.n_contacts, step.cones.tangent_dim + 1
    ours = sp.csr_matrix(expansion[contact_major_permutation(nc, dim)])
    constant = step.with_shift(np.zeros(step.n_contacts)).constant_rows   # [D, 0] + moving walls
    offset = constant + step.dt * (step.jacobian @ step.free_velocity)
    cones = Cones(kinds=np.full(nc, ConeKind.COULOMB, dtype=np.int8), mu=mu,
                  tangential=np.arange(nc), tangent_dim=dim - 1)
    return LocalProblem(delassus=sp.csr_matrix(ours @ step.delassus @ ours.T),
                        free_velocity=ours @ offset, cones=cones, name=name)


def step_forces_to_local(step: StepProblem, forces: np.ndarray, *, contact_major: bool = False
                         ) -> np.ndarray:
    """Step forces ``lam`` (n_rows,) as forces of :func:`local_from_step` (our layout) or,
    with ``contact_major=True``, as FCLIB's ``r`` of :func:`global_from_step`."""
    expansion, _ = _step_expansion(step)
    forces = checks.as_array("forces", forces, shape=(step.n_rows,))
    out = expansion @ forces
    if contact_major:
        return out
    return out[contact_major_permutation(step.n_contacts, step.cones.tangent_dim + 1)]


# -- diagnostics ----------------------------------------------------------------------------------
def delassus_diagnostics(problem: LocalProblem) -> dict:
    """How far a problem's ``W`` is from symmetric positive semi-definite.

    Parameters
    ----------
    problem : LocalProblem, StepProblem or anything with a ``delassus`` matrix

    Returns
    -------
    dict
        ``n_rows``; ``asymmetry`` ``= |W - W^T|_F / |W|_F`` (0 for ``W = 0``);
        ``min_eigenvalue`` and ``max_eigenvalue`` of the symmetric part
        ``(W + W^T) / 2``; ``relative_min_eigenvalue`` ``= min / max(|max|, tiny)``;
        ``method`` (``"dense"`` below :data:`DENSE_EIGEN_LIMIT` rows, else
        ``"eigsh"``: shift-invert Lanczos, confirmed by Sylvester's inertia);
        ``converged`` (False when the smallest eigenvalue could not be
        confirmed: it is then the best estimate, or NaN).
    """
    return matrix_diagnostics(problem.delassus)


def matrix_diagnostics(matrix: sp.spmatrix) -> dict:
    """:func:`delassus_diagnostics` of a matrix ``W`` given alone."""
    matrix = sp.csr_matrix(matrix)
    n = matrix.shape[0]
    norm = float(spla.norm(matrix)) if matrix.nnz else 0.0
    asymmetry = float(spla.norm(matrix - matrix.T)) / norm if norm > 0 else 0.0
    symmetric = (matrix + matrix.T) * 0.5
    out = dict(n_rows=n, asymmetry=asymmetry, min_eigenvalue=np.nan, max_eigenvalue=np.nan,
               relative_min_eigenvalue=np.nan, method="dense", converged=True)
    if n == 0:
        out.update(min_eigenvalue=0.0, max_eigenvalue=0.0, relative_min_eigenvalue=0.0)
        return out
    if n < DENSE_EIGEN_LIMIT:
        values = np.linalg.eigvalsh(symmetric.toarray())
        low, high = float(values[0]), float(values[-1])
    else:
        out["method"] = "eigsh"
        symmetric = sp.csc_matrix(symmetric)
        high = float(spla.eigsh(symmetric, k=1, which="LA", return_eigenvectors=False)[0])
        radius = abs(float(spla.eigsh(symmetric, k=1, which="LM", return_eigenvectors=False)[0]))
        low, out["converged"] = _lowest_eigenvalue(symmetric, radius)
    scale = max(abs(high), np.finfo(float).tiny)
    out.update(min_eigenvalue=low, max_eigenvalue=high, relative_min_eigenvalue=low / scale)
    return out


def _lowest_eigenvalue(matrix: sp.csc_matrix, radius: float) -> tuple[float, bool]:
    """The smallest eigenvalue of a large symmetric matrix, and whether it was confirmed.

    Shift-invert Lanczos finds the eigenvalue nearest a shift ``sigma < 0``
    (fast near the cluster at 0 of a rank-deficient ``W``); Sylvester's law of
    inertia on ``A - (low - margin) I = L D L^T`` then confirms that none lies
    below it. Otherwise the shift moves ten times further down, to ``-radius``
    at most (where the nearest eigenvalue is the smallest).
    """
    if radius == 0:
        return 0.0, True
    identity = sp.identity(matrix.shape[0], format="csc")
    sigma, low = -1e-6 * radius, np.nan
    while True:
        try:
            low = float(spla.eigsh(matrix, k=1, sigma=sigma, which="LM",
                                   return_eigenvectors=False)[0])
            below = _count_below(matrix - (low - 1e-9 * radius) * identity)
        except (RuntimeError, spla.ArpackError):
            below = None
        if below == 0:
            return low, True
        if sigma <= -radius:
            return low, False
        sigma = max(10 * sigma, -1.01 * radius)


def _count_below(matrix: sp.csc_matrix) -> int:
    """Negative eigenvalues of a symmetric matrix: negative pivots of its ``L D L^T`` (inertia)."""
    factor = spla.splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))
    return int(np.count_nonzero(factor.U.diagonal() < 0))


REPAIR_TOL = 1e-14
"""Relative asymmetry or negative eigenvalue above which :func:`convexified` changes ``W``."""


def convexified(problem: LocalProblem) -> tuple[LocalProblem, dict]:
    """The problem with ``W`` made symmetric positive semi-definite, and what was changed.

    Real data is not always what the Coulomb problem assumes: the Capsules files
    store a ``W`` non-symmetric by 1e-4 to 2e-3 (relative), and rounding made the
    stored ``W`` of the 2020- and 7002-contact granular files indefinite. A conic
    solver needs a symmetric positive semi-definite quadratic form, so ``W`` is
    replaced by ``(W + W^T) / 2 + delta I`` with ``delta = max(0, -lambda_min)``
    (lambda_min of the symmetric part, :func:`delassus_diagnostics`). A solution of
    the repaired problem is judged on the ORIGINAL data by its FCLIB error.

    Returns
    -------
    (LocalProblem, dict)
        The repaired problem (``problem`` itself when nothing needed repair) and
        the diagnostics with ``repaired`` (bool), ``shift`` (``delta``) and
        ``perturbation`` ``= |W' - W|_F / |W|_F``.
    """
    repaired, report = _repaired_delassus(problem.delassus)
    if repaired is None:
        return problem, dict(report)
    fixed = LocalProblem(delassus=repaired, free_velocity=problem.free_velocity, cones=problem.cones,
                         shift=problem.shift, name=problem.name, scaling=problem.scaling)
    return fixed, dict(report)


_LAST_REPAIR: list = [None, None, None]
"""``[weak reference to W, repaired W or None, report]`` of the last :func:`convexified` call:
the fixed point on s re-solves with the same ``W`` (only the shift changes), so its
eigenvalues are computed once, not at every outer iteration."""


def _repaired_delassus(matrix: sp.spmatrix) -> tuple[sp.csr_matrix | None, dict]:
    """``(W', report)`` for :func:`convexified` (``W' = None``: nothing to repair), cached by identity."""
    known = _LAST_REPAIR[0]() if _LAST_REPAIR[0] is not None else None
    if known is matrix:
        return _LAST_REPAIR[1], _LAST_REPAIR[2]
    report = matrix_diagnostics(matrix)
    low = report["min_eigenvalue"] if np.isfinite(report["min_eigenvalue"]) else 0.0
    negative = report["relative_min_eigenvalue"] < -REPAIR_TOL and low < 0
    report.update(repaired=False, shift=0.0, perturbation=0.0)
    repaired = None
    if report["asymmetry"] > REPAIR_TOL or negative:
        csr = sp.csr_matrix(matrix)
        shift = -low if negative else 0.0
        repaired = sp.csr_matrix((csr + csr.T) * 0.5 + shift * sp.identity(csr.shape[0]))
        norm = float(spla.norm(csr))
        report.update(repaired=True, shift=shift,
                      perturbation=float(spla.norm(repaired - csr)) / norm if norm else 0.0)
    _LAST_REPAIR[:] = [weakref.ref(matrix), repaired, report]
    return repaired, report
