"""The reference on real data: a W read from a file that is not symmetric PSD is repaired, reported,
and the solution judged on the original data (Capsules: asymmetric; 2020 granular: indefinite)."""
import numpy as np
import pytest

from lubcontact import solve_coulomb
from lubcontact.bench.cases.reference import load
from lubcontact.bench.problem_sets import data_dir
from lubcontact.io import read_problem
from lubcontact.problem.global_form import convexified
from lubcontact.problem.metrics import coulomb_error
from lubcontact.solvers.direct import conic_form

CASES = {   # file: (what is wrong, FCLIB error measured on the original data after the repair)
    "siconos-testdata/Capsules-i122-1617.dat": ("asymmetry", 8.8e-7),
    "siconos-fc2d/fc2d_granularflowonwall_02020_00213.dat": ("indefinite", 1.9e-5),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_data_is_repaired_reported_and_judged_on_the_original(name):
    problem = read_problem(data_dir() / name)
    repaired, report = convexified(problem)
    assert report["repaired"]
    if CASES[name][0] == "asymmetry":
        assert 1e-4 < report["asymmetry"] < 1e-3 and report["shift"] == 0.0
    else:
        assert report["asymmetry"] == 0.0 and report["min_eigenvalue"] < -1e-3
        assert report["shift"] == pytest.approx(-report["min_eigenvalue"])
    assert np.allclose((repaired.delassus - repaired.delassus.T).data, 0.0)
    assert 0 < report["perturbation"] < 1e-3
    result = solve_coulomb(problem, "clarabel-direct", tol=1e-9, tol_fp=1e-9, max_outer=100)
    assert result.success and result.info["data_repair"]["repaired"]
    scaled = problem.normalized()
    error = coulomb_error(scaled, result.forces / scaled.scaling.force)
    assert error <= 2 * CASES[name][1]                      # limited by the repair, not the solver


def test_symmetric_psd_data_is_left_alone():
    problem, _ = load("pile200_gluey")
    assert conic_form(problem.normalized()).repair == {}
    local = read_problem(data_dir() / "fclib-local" / "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5")
    same, report = convexified(local)
    assert same is local and not report["repaired"]


def test_the_repair_is_computed_once_per_matrix():
    """The fixed point re-solves with the same W: its eigenvalues are not recomputed each time."""
    problem = read_problem(data_dir() / "siconos-testdata" / "Capsules-i122-1617.dat")
    first, _ = convexified(problem)
    again, report = convexified(problem.with_shift(np.ones(problem.n_contacts)))
    assert again.delassus is first.delassus and report["repaired"]
