"""The stored reference cases: same problems rebuilt, same solutions found."""
import numpy as np
import pytest

from lubcontact import solve
from lubcontact.bench.cases.reference import CASES, load


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_code_still_builds_the_stored_problem(name):
    """The piles come out of 80 solver steps: the solver's last bits (e.g. the exact linear solve
    that polishes each step) move them by up to 2.4e-11 of each array's scale (measured);
    building a problem differently moves them by far more. Hence an absolute tolerance of 1e-10
    of the scale for the piles; the other cases are built without a solver and must be exact."""
    stored, _ = load(name)
    rebuilt = CASES[name].problem()
    relative_drift = 1e-10 if name.startswith("pile") else 0.0
    for key, value in stored.to_arrays().items():
        scale = float(np.max(np.abs(value))) if np.size(value) else 0.0
        np.testing.assert_allclose(rebuilt.to_arrays()[key], value, rtol=1e-12,
                                   atol=max(1e-14, relative_drift * scale),
                                   err_msg=f"{name}: {key} changed")


@pytest.mark.parametrize("method", ["clarabel", "clarabel-dual"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_reference_solvers_reproduce_the_stored_velocities(name, method):
    problem, solution = load(name)
    result = solve(problem, method, tol=1e-10)
    assert result.status == "converged"
    scale = max(np.linalg.norm(solution["velocities"]), 1e-300)
    assert np.linalg.norm(result.velocities - solution["velocities"]) / scale <= 1e-9
    gaps = problem.gaps_after(result.velocities)
    assert gaps.min() >= -1e-9 * max(1.0, np.abs(problem.gaps).max())


@pytest.mark.parametrize("name", sorted(CASES))
def test_stored_solutions_satisfy_the_optimality_conditions(name):
    problem, solution = load(name)
    scaled = problem.normalized()
    forces = solution["forces"] / scaled.scaling.force
    assert scaled.natural_residual(forces) <= 1e-10 * (1 + np.linalg.norm(scaled.offset))
    np.testing.assert_allclose(problem.velocity(solution["forces"]), solution["velocities"],
                               rtol=1e-12, atol=1e-14)


# -- active-set polishing (solvers/polish.py) --------------------------------------------------------
@pytest.fixture(scope="module")
def hard_cases():
    from lubcontact.bench.hard import load_cases
    return load_cases()


@pytest.mark.parametrize("name", ["cone_apex_2d", "cone_apex_3d", "radius_ratio_100_friction",
                                  "dt_large_friction", "gamma_states_gluey_coulomb",
                                  "tetrahedron_3d_friction"])
@pytest.mark.parametrize("method", ["clarabel", "clarabel-dual", "clarabel-direct"])
def test_frictional_and_mixed_solutions_are_polished_to_rounding(hard_cases, name, method):
    """Friction contacts open, sticking and sliding (2D, 3D by Newton), NONNEG/FREE/UNION mixed:
    the polished solution satisfies the optimality conditions to rounding (the interior point
    alone leaves 1e-7 to 1e-5)."""
    problem = hard_cases[name].problem
    if method == "clarabel-direct" and not problem.cones.is_convex:
        pytest.skip("clarabel-direct takes convex cones only")
    polished = solve(problem, method, tol=1e-9)
    assert polished.status == "converged" and polished.info["polished"]
    assert polished.residual <= 1e-12
    if method == "clarabel-direct":
        raw = solve(problem, method, tol=1e-9, polish=False)
        assert not raw.info["polished"] and raw.residual > 1e3 * polished.residual


def test_contacts_touching_with_zero_force_do_not_stop_the_polish():
    """The stored inelastic pile with its contacts in other orders: in two of 20 random orders
    the solve on the active set gave contacts that touch with zero force (gap and force both 0)
    a force of -2e-16 (of a largest 7.3): they opened, two more opened in the next round, and
    the polish gave up as not settling, leaving clarabel-dual's interior point (natural
    residual 1.5e-5 at tol 1e-10, velocities 3.6e-6 off). A force condition is now broken only
    beyond rounding: every order is polished and reproduces the stored velocities."""
    import scipy.sparse as sp

    from lubcontact.problem.step import StepProblem

    problem, solution = load("pile200_inelastic")
    arrays = problem.to_arrays()
    jacobian = sp.csr_matrix((arrays["h_data"], arrays["h_indices"], arrays["h_indptr"]),
                             shape=tuple(arrays["h_shape"]))
    rng = np.random.default_rng(0)
    orders = [rng.permutation(problem.n_contacts) for _ in range(20)][18:]   # the two
    for order in orders:
        reordered = dict(arrays)
        rows = jacobian[order]
        reordered.update(h_data=rows.data, h_indices=rows.indices, h_indptr=rows.indptr,
                         **{key: arrays[key][order] for key in
                            ("gaps", "shift", "cone_kinds", "cone_mu", "keys")})
        result = solve(StepProblem.from_arrays(reordered), "clarabel-dual", tol=1e-10)
        assert result.status == "converged" and result.info["polished"]
        assert result.residual <= 1e-12
        scale = np.linalg.norm(solution["velocities"])
        assert np.linalg.norm(result.velocities - solution["velocities"]) / scale <= 1e-9


@pytest.mark.parametrize("name", ["mass_ratio_1e6_collision", "radius_ratio_100"])
def test_clarabel_direct_is_polished_like_the_cvxpy_reference(hard_cases, name):
    """Unpolished, clarabel-direct was 3-5e-6 off on these cases (docs/records/hard_cases.md, finding 4)."""
    from lubcontact.problem.metrics import scaled_velocity_error

    problem = hard_cases[name].problem
    reference = solve(problem, "clarabel", tol=1e-10).velocities
    raw = solve(problem, "clarabel-direct", tol=1e-9, polish=False)
    polished = solve(problem, "clarabel-direct", tol=1e-9)
    assert scaled_velocity_error(problem, raw.velocities, reference) > 1e-6
    assert scaled_velocity_error(problem, polished.velocities, reference) <= 1e-12


@pytest.mark.parametrize("name", ["glued_chain_free", "hex_box_glued"])
def test_scs_solves_problems_without_inequality_rows(hard_cases, name):
    """Every contact FREE: no row in the conic form; SCS gets one empty row and solves it."""
    from lubcontact.problem.metrics import scaled_velocity_error

    problem = hard_cases[name].problem
    result = solve(problem, "scs", tol=1e-9)
    reference = solve(problem, "clarabel", tol=1e-10)
    assert result.status == "converged"
    assert scaled_velocity_error(problem, result.velocities, reference.velocities) <= 1e-8


@pytest.mark.parametrize("max_iter", [None, 4])
@pytest.mark.parametrize("method", ["clarabel", "clarabel-direct"])
def test_a_badly_conditioned_problem_is_polished_to_rounding(hard_cases, method, max_iter):
    """``mass_ratio_1e6_sandwich`` (``W``'s eigenvalues 0.25 and 1e6): at a proximal weight of
    1e-6 alone the small eigenvalue sits below the weight, the refinement stalls, and the polish
    was rejected (clarabel-direct at its default budget: velocity error 5.6e-10) or accepted far
    from the answer (four interior-point iterations: 1.1e-4 for clarabel, 7.9e-4 for
    clarabel-direct). Polished at 1e-12 first, every answer is at rest to 1e-11 of the free
    velocity's scale, and ``converged`` (after four iterations by its polish: polished_status)."""
    case = hard_cases["mass_ratio_1e6_sandwich"]
    problem = case.problem
    result = solve(problem, method, tol=1e-9, **({} if max_iter is None else {"max_iter": max_iter}))
    assert result.info["polished"] and result.status == "converged"
    exact = np.asarray(case.exact(problem), dtype=float)
    scale = max(float(np.abs(problem.free_velocity).max()), 1.0)
    assert np.abs(result.velocities - exact).max() <= 1e-11 * scale


def test_the_polish_keeps_dependent_contacts_forces_along_their_null_space():
    """A 17-row local problem cut from a 10 000-grain gluey step's reference (the contacts one
    step from two pairs of sticking contacts whose rows are dependent in ``W``'s pattern, the
    other contacts' forces folded into ``q``), with Clarabel's forces there. The active set's
    ``G`` has two null directions, along which the forces' residual holds the interior point's
    inaccuracy (1.8e-12). At a proximal weight of 1e-12 the solve moved the pairs' normal forces
    by that over the weight, to -0.3. The pairs then cycled between sticking and open, and the
    polish gave up. Now it is accepted, the residual falls (1.6e-11 to 1.8e-12) and the pairs
    stick with the interior point's positive forces."""
    from lubcontact.solvers.polish import polish

    problem, forces = _dependent_contacts_block()
    cones = problem.cones
    before = problem.natural_residual(forces)
    polished, accepted = polish(problem, forces)
    assert accepted
    assert problem.natural_residual(polished) <= 0.2 * before
    sticking = forces[: cones.count] > 1e-3 * np.abs(forces).max()
    assert sticking.sum() == 4 and np.all(polished[: cones.count][sticking] > 0)


def test_an_interior_point_stopped_short_whose_polish_is_accepted_is_converged_where_it_meets_tol():
    """polished_status: an interior point's answer that stopped short of tol (Clarabel's
    ``AlmostSolved``, ``inaccurate``, or out of iterations, ``max_iter``) and whose polish is
    accepted is ``converged`` where the polished natural residual per row meets the solve's
    tol, and keeps its status where it does not; a polish not accepted, and any other status,
    change nothing. (On a 10 000-grain gluey step's reference Clarabel's fixed point on s stopped
    after four outer iterations on an ``inaccurate`` inner solve whose polished residual was
    1.7e-12 per row.)"""
    from lubcontact.solvers.polish import polish, polished_status
    from lubcontact.solvers.result import residual_per_row

    problem, forces = _dependent_contacts_block()
    polished, accepted = polish(problem, forces)
    assert accepted
    per_row = residual_per_row(problem.natural_residual(polished), polished.size)
    for status in ("inaccurate", "max_iter"):
        assert polished_status(status, problem, polished, True, 10 * per_row) == "converged"
        assert polished_status(status, problem, polished, True, per_row / 10) == status
        assert polished_status(status, problem, forces, False, 1.0) == status
    for status in ("converged", "diverged", "failed"):
        assert polished_status(status, problem, polished, True, 1.0) == status


def _dependent_contacts_block():
    """The stored 17-row block of a 10 000-grain gluey step's reference and Clarabel's forces
    there (tests/solvers/data/README.md, ``dependent-contacts-block.npz``)."""
    from pathlib import Path

    import scipy.sparse as sp

    from lubcontact.problem.cones import Cones
    from lubcontact.problem.local import LocalProblem

    path = Path(__file__).parents[1] / "solvers" / "data" / "dependent-contacts-block.npz"
    with np.load(path) as data:
        n = data["q"].size
        delassus = sp.csr_matrix((data["W_data"], data["W_indices"], data["W_indptr"]), shape=(n, n))
        cones = Cones(kinds=data["kinds"], mu=data["mu"], tangential=data["tangential"], tangent_dim=1)
        problem = LocalProblem(delassus=delassus, free_velocity=data["q"], cones=cones)
        forces = data["forces"]
    return problem, forces
