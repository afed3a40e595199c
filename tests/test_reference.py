"""The stored reference cases: same problems rebuilt, same solutions found."""
import numpy as np
import pytest

from lubcontact import solve
from reference.cases import CASES, load


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_code_still_builds_the_stored_problem(name):
    stored, _ = load(name)
    rebuilt = CASES[name].problem()
    for key, value in stored.to_arrays().items():
        np.testing.assert_allclose(rebuilt.to_arrays()[key], value, rtol=1e-12, atol=1e-14,
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
