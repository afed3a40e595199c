"""``lubcontact verify``: an outside solution judged against the problem and the reference."""
import json

import numpy as np
import pytest

from lubcontact import solve_coulomb
from lubcontact.bench.problem_sets import data_dir
from lubcontact.bench.verify import main, verify_files
from lubcontact.io import read_problem

PROBLEM = data_dir() / "siconos-fc2d" / "fc2d_granularflowonwall_00667_00000.dat"


@pytest.fixture(scope="module")
def solutions(tmp_path_factory):
    """Our fast solution, and the same with one force outside its cone and one load removed."""
    folder = tmp_path_factory.mktemp("solutions")
    problem = read_problem(PROBLEM)
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-9, max_iter=100000)
    assert result.success
    forces = result.forces.copy()
    nc = problem.n_contacts
    normal = forces[:nc]
    loaded = np.argsort(-normal)
    outside, unloaded = int(loaded[0]), int(loaded[5])
    row = nc + int(np.flatnonzero(problem.cones.tangential == outside)[0])
    forces[row] = 3.0 * problem.cones.mu[outside] * normal[outside]     # |r_T| = 3 mu r_n
    forces[unloaded] = 0.0                                            # lets its grains overlap
    np.savez(folder / "good.npz", r=problem.to_contact_major(result.forces))
    np.savetxt(folder / "good.txt", problem.to_contact_major(result.forces))
    np.savez(folder / "bad.npz", r=problem.to_contact_major(forces))
    return folder, outside, unloaded


def test_our_fast_solution_passes(solutions, capsys):
    folder, _, _ = solutions
    assert main([str(PROBLEM), str(folder / "good.npz")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("verdict: PASS") and "FCLIB/Siconos error" in out
    assert main([str(PROBLEM), str(folder / "good.txt"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["passed"] and report["coulomb_error"] <= 1e-8
    assert report["reference"]["method"] == "clarabel-dual"


def test_a_perturbed_solution_fails_and_names_its_contacts(solutions, capsys):
    folder, outside, unloaded = solutions
    assert main([str(PROBLEM), str(folder / "bad.npz"), "--worst", "10"]) == 1
    assert capsys.readouterr().out.startswith("verdict: FAIL")
    report = verify_files(PROBLEM, folder / "bad.npz", tol=1e-8, reference=None,
                          layout="contact-major", worst=10)
    assert not report.passed and {"cone", "penetration", "coulomb_error"} <= set(report.failed)
    by_index = {c.index: c for c in report.worst}
    assert by_index[outside].amounts["cone"] > 1.0                 # 2 mu r_n outside, scaled
    assert by_index[unloaded].amounts["penetration"] > 1.0
    assert report.penetration > 1.0 and report.cone > 1.0


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / "empty.npz").write_bytes(b"")
    np.savez(tmp_path / "short.npz", r=np.zeros(5))
    assert main([str(PROBLEM), str(tmp_path / "missing.npz")]) == 2
    assert main([str(PROBLEM), str(tmp_path / "short.npz")]) == 2
    err = capsys.readouterr().err
    assert "SOLUTION: no file" in err and "forces: expected 1334 values" in err
    with pytest.raises(SystemExit):
        main([str(PROBLEM), str(tmp_path / "short.npz"), "--tol", "-1"])
    assert "--tol" in capsys.readouterr().err


def test_velocities_alone_verify_a_local_problem():
    """Forces are recovered by the reference that accepts the problem (clarabel-dual here: the
    primal form needs a step problem; it raised before)."""
    from lubcontact.solvers.verify import verify

    problem = read_problem(PROBLEM)
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-9, max_iter=100000)
    report = verify(problem, velocities=problem.velocity(result.forces), tol=1e-6, reference=None)
    assert report.forces_recovered and report.passed and report.penetration <= 1e-6
