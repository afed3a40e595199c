"""Bad input raises ValueError naming the field; good input builds consistent scenes."""
import numpy as np
import pytest

from lubcontact import GlueyLubrication, Grains, Inelastic, Scene, Schedule, Simulation
from lubcontact.model.laws import gamma_min_from_roughness


def two_disks(**overrides):
    kwargs = dict(positions=[[0.0, 1.0], [3.0, 1.0]], radii=[0.5, 0.5], masses=[1.0, 2.0])
    kwargs.update(overrides)
    positions, radii = kwargs.pop("positions"), kwargs.pop("radii")
    return Grains.create(positions, radii, **kwargs)


@pytest.mark.parametrize("overrides, field", [
    (dict(radii=[0.5, 0.0]), "radii"),
    (dict(radii=[0.5, -1.0]), "radii"),
    (dict(masses=[1.0, 0.0]), "masses"),
    (dict(masses=[1.0, -2.0]), "masses"),
    (dict(masses=None, densities=[1.0, -1.0]), "densities"),
    (dict(masses=None), "masses"),
    (dict(positions=[[0.0, np.nan], [3.0, 1.0]]), "positions"),
    (dict(positions=[[0.0, 1.0], [np.inf, 1.0]]), "positions"),
    (dict(velocities=[[0.0, np.nan], [0.0, 0.0]]), "velocities"),
    (dict(positions=[[0.0, 1.0, 2.0, 3.0]]), "positions"),
    (dict(positions=[0.0, 1.0]), "positions"),
    (dict(radii=[0.5, 0.5, 0.5]), "radii"),
    (dict(velocities=[[0.0, 0.0]]), "velocities"),
])
def test_bad_grains_name_the_field(overrides, field):
    with pytest.raises(ValueError, match=field):
        two_disks(**overrides)


def test_bad_time_step_names_dt():
    scene = Scene.create(two_disks())
    for dt in (0.0, -1e-3, np.nan, np.inf):
        with pytest.raises(ValueError, match="dt"):
            Simulation(scene, Inelastic(), dt)


def test_unknown_fallback_solver_is_refused_before_any_step():
    scene = Scene.create(two_disks())
    with pytest.raises(ValueError, match=r"^fallback_solver: .*got 'clarabell'"):
        Simulation(scene, Inelastic(), 1e-2, on_failure="fallback", fallback_solver="clarabell")


@pytest.mark.parametrize("kwargs, field", [
    (dict(gravity=[0.0, np.nan]), "gravity"),
    (dict(gravity=[0.0, -1.0, 0.0]), "gravity"),
    (dict(plane_points=[0.0, 0.0], plane_normals=[0.0, 0.0]), "planes.normals"),
    (dict(plane_points=[0.0, np.inf], plane_normals=[0.0, 1.0]), "planes.points"),
    (dict(fixed_positions=[[10.0, 0.0]], fixed_radii=[-0.5]), "fixed_radii"),
    (dict(fluid_density=-1.0), "fluid_density"),
    (dict(fluid_density=1.0), "fluid_density"),        # buoyancy without grain densities
    (dict(external_force=np.ones((3, 2))), "external_force"),
    (dict(external_force=lambda t: np.array([np.nan, 0.0])), "external_force"),
])
def test_bad_scene_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Scene.create(two_disks(), **kwargs)


def test_initial_overlap_beyond_tolerance_is_rejected():
    overlapping = two_disks(positions=[[0.0, 1.0], [0.99, 1.0]])          # overlap 0.01
    with pytest.raises(ValueError, match="overlap"):
        Scene.create(overlapping)
    touching = two_disks(positions=[[0.0, 1.0], [1.0 - 1e-8, 1.0]])       # within 1e-6 x r
    assert Scene.create(touching).grains.count == 2
    below_plane = two_disks(positions=[[0.0, 0.4], [3.0, 1.0]])
    with pytest.raises(ValueError, match="overlap"):
        Scene.create(below_plane, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0])
    assert Scene.create(overlapping, overlap_tolerance=0.03).grains.count == 2


def test_bad_law_parameters_name_the_field():
    with pytest.raises(ValueError, match="gamma_min"):
        GlueyLubrication(gamma_min=0.5)
    with pytest.raises(ValueError, match="viscosity"):
        GlueyLubrication(viscosity=1e-3)
    with pytest.raises(ValueError, match="roughness"):
        GlueyLubrication(viscosity=1e-3, roughness=-1.0)
    with pytest.raises(ValueError, match="Schedule.times"):
        Schedule(times=(1.0, 0.0), values=([0.0, 0.0], [1.0, 0.0]))


def test_buoyant_weight_uses_the_density_difference():
    grains = Grains.create([[0.0, 2.0]], 1e-3, densities=2500.0)
    scene = Scene.create(grains, gravity=[0.0, -9.81], fluid_density=1500.0)
    area = np.pi * 1e-6
    assert grains.masses[0] == pytest.approx(2500.0 * area)
    assert grains.inertias[0] == pytest.approx(0.5 * 2500.0 * area * 1e-6)
    assert scene.weights()[0, 1] == pytest.approx(-(2500.0 - 1500.0) * area * 9.81)


def test_schedule_switches_at_its_times():
    schedule = Schedule(times=(0.0, 2.0), values=([0.0, -1.0], [0.0, 1.0]))
    assert schedule(1.999)[1] == -1.0 and schedule(2.0)[1] == 1.0 and schedule(50.0)[1] == 1.0


def test_gamma_min_from_roughness_matches_the_lubrication_formula():
    eta, eps, r = 1e-3, 1e-6, np.array([1e-3, 5e-4])
    expected = 6 * np.pi * eta * r**2 * np.log(eps / r)
    np.testing.assert_allclose(gamma_min_from_roughness(eta, eps, r), expected, rtol=1e-14)
    assert np.all(expected < 0)
