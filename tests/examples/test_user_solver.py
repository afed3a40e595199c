"""A user's solver, registered from outside the package, runs through Simulation, verify,
compare and check-hard (examples/user_solver.py)."""
import json
import runpy
from pathlib import Path

import numpy as np
import pytest

from lubcontact import Inelastic, Simulation, scenes, solve
from lubcontact.bench import compare, hard, verify
from lubcontact.problem import ConeKind
from lubcontact.problem.metrics import velocity_error
from lubcontact.solvers import methods, solver_info, unregister

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "user_solver.py"


@pytest.fixture(scope="module")
def user_solver():
    """Run the example's module body (it registers ``my-pgd``); unregister afterwards."""
    namespace = runpy.run_path(str(EXAMPLE))
    assert "my-pgd" in methods(kind="first-order")
    yield namespace
    unregister("my-pgd")


def test_the_example_solver_is_short(user_solver):
    source = EXAMPLE.read_text().split("@register")[1].split("\n\n\ndef main")[0]
    assert len(source.strip().splitlines()) <= 13          # decorator + a dozen lines
    info = solver_info("my-pgd")
    assert info.kind == "first-order"
    assert ConeKind.UNION not in info.cones        # the convex sets only, as the guide says


def test_it_steps_a_simulation_and_matches_clarabel(user_solver):
    sim = Simulation(scenes.settling_pile(30, seed=1), Inelastic(), dt=0.05, solver="my-pgd",
                     tol=1e-10)
    sim.run(20)
    assert set(sim.trajectory.status) == {"converged"}
    report = sim.step()
    reference = solve(report.problem, "clarabel", tol=1e-10)
    assert velocity_error(report.problem, report.result.velocities, reference.velocities) <= 1e-8


def test_it_runs_through_verify_compare_and_check_hard(user_solver, tmp_path, capsys):
    problem = scenes.settling_pile(30, seed=1)
    sim = Simulation(problem, Inelastic(), dt=0.05, solver="my-pgd", tol=1e-10)
    report = sim.run(15) and sim.step()
    np.savez(tmp_path / "step.npz", **report.problem.to_arrays())
    np.savez(tmp_path / "solution.npz", forces=report.result.forces)
    assert verify.main([str(tmp_path / "step.npz"), str(tmp_path / "solution.npz"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["passed"]

    assert compare.main(["--set", "tiny", "--solvers", "my-pgd", "--tolerances", "1e-8",
                         "--repeats", "1", "--quiet", "--out", str(tmp_path / "cmp")]) == 0
    results = json.loads((tmp_path / "cmp" / "tiny" / "results.json").read_text())["results"]
    rows = [row for row in results if row["method"] == "my-pgd"]
    assert rows and all(row["status"] == "converged" for row in rows)
    assert max(row["velocity_error"] for row in rows) <= 1e-6
    capsys.readouterr()

    assert hard.main(["--solvers", "my-pgd", "--cases", "single_contact,wedge_planes,hex_box_jammed"]) == 0
    out = capsys.readouterr().out
    assert "my-pgd" in out and "wrong: 0" in out and "crash: 0" in out
