"""nsgs, non-smooth Gauss-Seidel with exact local 2D Coulomb solves, against the stored references,
Clarabel's fixed point on s and its own domain; and as newton-ac's first 2D fallback."""
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from lubcontact.bench.cases.reference import CASES as REFERENCE_CASES
from lubcontact.bench.cases.reference import load as load_reference
from lubcontact.bench.hard import expected_for, load_cases
from lubcontact.problem.cones import ConeKind, Cones
from lubcontact.problem.local import LocalProblem
from lubcontact.problem.metrics import scaled_coulomb_error, scaled_velocity_error, velocity_error
from lubcontact.problem.step import StepProblem
from lubcontact.solvers import CONVERGED, MAX_ITER, solve, solve_coulomb, solver_info
from lubcontact.solvers.compiled_apgd import csr_arrays
from lubcontact.solvers.gauss_seidel import Sweeps
from lubcontact.solvers.kernels import coulomb_residual_2d, factor_rows_state, local_coulomb_2d

#: the reference cases a Gauss-Seidel method reaches to 1e-8 within its default 20 000 sweeps
#: (the jammed 200-grain piles need more: pgd needs 1.2 million iterations on one)
REACHED = sorted(name for name in REFERENCE_CASES if not name.startswith("pile"))


@pytest.mark.parametrize("name", REACHED)
def test_agrees_with_the_stored_reference(name):
    problem, solution = load_reference(name)
    result = solve_coulomb(problem, "nsgs", tol=1e-12)
    assert result.status == CONVERGED
    assert velocity_error(problem, result.velocities, solution["velocities"]) <= 1e-8


@pytest.mark.parametrize("name", ["radius_ratio_100_friction", "mu_zero_friction",
                                  "hex_box_lid_friction", "cone_apex_2d", "dt_large_friction",
                                  "gamma_states_gluey_coulomb"])
def test_exact_coulomb_and_union_contacts_natively(name):
    """Exact answers where the case has one, else Clarabel's fixed point on s with its branch
    rule (the gluey + friction case has UNION contacts on both pieces)."""
    case = load_cases()[name]
    expected = expected_for(case, case.problem, fixed_point=True)
    result = solve_coulomb(case.problem, "nsgs", tol=1e-10)
    assert result.status == CONVERGED and result.outer_iterations == 1
    assert scaled_velocity_error(case.problem, result.velocities, expected.velocities) <= 1e-8


def test_local_solve_covers_each_case_of_the_law():
    """The 2x2 local problem u = A r + b: open, stick, slide both ways, pulled (bilateral)."""
    a, c, d, mu = 2.0, 0.3, 1.5, 0.5
    assert local_coulomb_2d(a, c, c, d, 1.0, 5.0, mu, True, 0.0, 0.0) == (0.0, 0.0)   # opening
    n, t = local_coulomb_2d(a, c, c, d, -1.0, 0.1, mu, True, 0.0, 0.0)                 # stick
    assert abs(a * n + c * t - 1.0) < 1e-14 and abs(c * n + d * t + 0.1) < 1e-14
    assert n > 0 and abs(t) <= mu * n
    for b_t in (5.0, -5.0):                                                            # slide
        n, t = local_coulomb_2d(a, c, c, d, -1.0, b_t, mu, True, 0.0, 0.0)
        u_n, u_t = a * n + c * t - 1.0, c * n + d * t + b_t
        assert abs(u_n) < 1e-14 and n > 0 and t == pytest.approx(-np.sign(u_t) * mu * n)
    n, t = local_coulomb_2d(a, c, c, d, 1.0, 5.0, mu, False, 0.0, 0.0)                # pulled
    assert n == pytest.approx(-0.5) and t == 0.0


def test_three_dimensional_friction_is_rejected_and_max_iter_is_honest():
    with pytest.raises(ValueError, match="nsgs"):
        solve(load_cases()["tetrahedron_3d_friction"].problem, "nsgs")
    assert solver_info("nsgs").native_coulomb and ConeKind.UNION in solver_info("nsgs").cones
    problem, _ = load_reference("pile200_inelastic")
    result = solve(problem, "nsgs", tol=1e-12, max_iter=30)
    assert result.status == MAX_ITER and result.iterations == 30
    assert result.residual_history.size == 4          # the start and three checks


def test_a_frictionless_three_dimensional_problem_is_solved():
    """Without friction contacts a 3D problem has no cone for the 2D loops to refuse: nsgs
    solves it, directly and as exact Coulomb, as Clarabel does (2034919 had it raise
    AttributeError: no planar tangent rows on a 3D problem)."""
    rng = np.random.default_rng(0)
    root = rng.normal(size=(3, 3))
    cones = Cones.frictionless(np.full(3, ConeKind.NONNEG), 2)
    problem = LocalProblem(delassus=sp.csr_matrix(root @ root.T + np.eye(3)),
                           free_velocity=np.array([-1.0, -0.5, 0.2]), cones=cones, name="3d")
    assert problem.cones.tangent_dim == 2 and not problem.cones.has_friction
    expected = solve(problem, "clarabel-dual", tol=1e-10).forces
    for result in (solve(problem, "nsgs", tol=1e-10), solve_coulomb(problem, "nsgs", tol=1e-10)):
        assert result.status == CONVERGED
        assert np.abs(result.forces - expected).max() <= 1e-8 * np.abs(expected).max()


def test_newton_ac_falls_back_on_gauss_seidel_first_in_2d():
    """One Newton iteration cannot solve the lidded hexagonal box; the 2D fallback chain starts
    with nsgs, which solves it (apgd-jacobi is not needed)."""
    case = load_cases()["hex_box_lid_friction"]
    result = solve_coulomb(case.problem, "newton-ac", tol=1e-9, max_iter=1)
    assert result.info["newton_status"] == MAX_ITER and result.info["fallbacks"] == ["nsgs"]
    assert result.status == CONVERGED
    assert scaled_coulomb_error(case.problem, result.forces) <= 1e-9


@pytest.fixture(scope="module")
def gluey_step():
    """A 2D gluey + friction flow step (1 635 rows: NONNEG and UNION contacts), normalised, with
    its sweeps read through ``W``'s factor and through ``W``'s rows, and its warm start."""
    path = Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz"
    with np.load(path) as data:
        problem = StepProblem.from_arrays(data)
        warm_start = data["warm_start"]
    scaled = problem.normalized()
    W = scaled.delassus.tocsr()
    q = scaled.offset.copy()
    q[: scaled.n_contacts] -= scaled.shift
    projector = scaled.cones.projector
    arguments = (W, q, projector.lower, projector.upper, projector.friction_normal,
                 projector.planar_tangent, projector.friction_mu, ~projector.friction_union)
    through_factor = Sweeps(*arguments, factor=scaled.delassus_factor,
                            factor_transpose=scaled.delassus_factor_transpose)
    return through_factor, Sweeps(*arguments), warm_start / scaled.scaling.force


def test_sweeps_through_the_factor_are_the_sweeps_through_w(gluey_step):
    """The same forces to rounding, whether a row's velocity is read from ``F r`` (updated after
    each change) or from its row of ``W``: over every row (nsgs's: None, or all of them given)
    and over some."""
    through_factor, through_w, start = gluey_step
    n = start.size
    for rows in (None, np.arange(n), np.arange(0, n, 3)):
        first, second = through_factor(start, 10, rows), through_w(start, 10, rows)
        assert np.abs(first - start).max() > 1e-3 * np.abs(start).max()     # they moved
        assert np.abs(first - second).max() <= 1e-11 * np.abs(first).max()


def test_sweeps_over_some_rows_read_f_r_where_those_rows_hold_it(gluey_step):
    """Sweeps over some rows through the factor compute ``F r`` only at the degrees of freedom
    those rows of ``F^T`` hold (:func:`~lubcontact.solvers.kernels.factor_rows_state`): there
    it is the product's to the bit, elsewhere untouched; and sweeps over every row given as
    rows take the forces of sweeps over all (``None``, the whole product) to the bit."""
    through_factor, _, start = gluey_step
    factor, transpose = through_factor.factor, through_factor.rows
    rows = np.arange(0, start.size, 7)
    state = np.full(factor.shape[0], np.nan)
    factor_rows_state(*csr_arrays(factor), *transpose[:2], start, rows, state)
    held = np.unique(np.concatenate([transpose[1][transpose[0][i]:transpose[0][i + 1]] for i in rows]))
    assert 0 < held.size < state.size
    assert np.array_equal(state[held], (factor @ start)[held])
    assert np.isnan(np.delete(state, held)).all()
    assert np.array_equal(through_factor(start, 10, np.arange(start.size)), through_factor(start, 10, None))


def test_sweeps_over_some_rows_solve_their_contacts_laws_and_leave_the_others(gluey_step):
    """Sweeps over a few rows, the seeds and their neighbours in ``W``'s pattern: the forces of
    every other contact stay as they were, and the swept contacts' laws hold to rounding (the
    FCLIB residual of their rows, with the others' forces frozen) once the sweeps converge."""
    sweeps, _, start = gluey_step
    W, q = sweeps.W, sweeps.q
    n = start.size
    seeds = np.argsort(np.abs(W @ start + q))[-5:]
    rows = np.unique(W[seeds].indices)
    swept = sweeps(start, 500, rows)
    contact = sweeps.contact
    touched = np.isin(np.arange(n), rows) | np.isin(contact, contact[rows][contact[rows] >= 0])
    assert np.array_equal(swept[~touched], start[~touched])
    assert np.abs(swept[touched] - start[touched]).max() > 0
    def residual(forces):
        return coulomb_residual_2d(forces, W @ forces + q, sweeps.lower, sweeps.upper,
                                   sweeps.cone_n, sweeps.cone_t, sweeps.mu, sweeps.unilateral)
    scale = np.abs(start).max()
    assert np.abs(residual(start)[touched]).max() > 1e-3 * scale
    assert np.abs(residual(swept)[touched]).max() <= 1e-10 * scale
