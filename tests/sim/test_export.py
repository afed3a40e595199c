"""Simulation(export_every=k): every k-th step problem written with its scene and reference."""
import numpy as np
import pytest

from lubcontact import Coulomb, GlueyLubrication, Simulation, scenes
from lubcontact.bench.verify import main as verify_main
from lubcontact.io import read_fclib_solution, read_problem
from lubcontact.problem import StepProblem
from lubcontact.problem.global_form import local_from_step
from lubcontact.problem.metrics import coulomb_error, velocity_error


def test_a_frictional_run_exports_fclib_and_npz_steps(tmp_path):
    sim = Simulation(scenes.settling_pile(30, seed=1), Coulomb(0.3), dt=0.05, solver="apgd-jacobi",
                     tol=1e-9, export_every=20, export_dir=tmp_path)
    sim.run(40)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "step_00000020.hdf5", "step_00000020.npz", "step_00000040.hdf5", "step_00000040.npz"]
    with np.load(tmp_path / "step_00000040.npz") as data:
        problem = StepProblem.from_arrays(dict(data))
        assert int(data["step"]) == 40 and float(data["time"]) == pytest.approx(sim.scene.time - 0.05)
        assert str(data["reference_status"]) == "converged"
        reference_forces = data["reference_forces"]
        np.testing.assert_array_equal(data["scene.grains.radii"], sim.scene.grains.radii)
        applied = data["velocities"]
    assert problem.cones.has_friction and problem.n_contacts > 10
    local = read_problem(tmp_path / "step_00000040.hdf5")
    expected = local_from_step(problem)
    np.testing.assert_allclose(local.delassus.toarray(), expected.delassus.toarray(), rtol=0,
                               atol=1e-12 * abs(expected.delassus).max())
    np.testing.assert_allclose(local.free_velocity, expected.free_velocity, rtol=0, atol=1e-12)
    stored = read_fclib_solution(tmp_path / "step_00000040.hdf5")
    assert coulomb_error(local, local.from_contact_major_vector(stored["r"])) <= 1e-9
    scaled = problem.normalized()
    assert coulomb_error(scaled, reference_forces / scaled.scaling.force) <= 1e-9
    assert velocity_error(problem, applied, problem.velocity(reference_forces)) <= 1e-3
    assert verify_main([str(tmp_path / "step_00000040.npz"), str(tmp_path / "step_00000040.npz"),
                        "--reference", "none", "--tol", "1e-6"]) == 0


def test_a_gluey_run_exports_npz_only(tmp_path):
    sim = Simulation(scenes.settling_pile(30, seed=1), GlueyLubrication(gamma_min=-2.0), dt=0.05,
                     solver="apgd-as", export_every=15, export_dir=tmp_path)
    sim.run(15)
    assert [p.name for p in tmp_path.iterdir()] == ["step_00000015.npz"]
