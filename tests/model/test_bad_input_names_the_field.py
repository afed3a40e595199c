"""Bad input raises ValueError naming the field and the value (no numpy broadcast or reshape error,
no AttributeError, no silent acceptance)."""
import numpy as np
import pytest

from lubcontact import GlueyLubrication, Grains, Inelastic, Scene, Simulation, scenes
from lubcontact.model.contacts import find_contacts

TWO = [[0.0, 0.5], [2.0, 0.5]]


def _grains(**kwargs):
    return Grains.create(TWO, 0.5, **{"masses": 1.0, **kwargs})


CASES = {
    "masses of the wrong length": (lambda: _grains(masses=[1.0, 2.0, 3.0]), r"^masses: .*\(2,\)"),
    "densities of the wrong length": (lambda: Grains.create(TWO, 0.5, densities=[1.0, 2.0, 3.0]),
                                      r"^densities: .*\(2,\)"),
    "inertias of the wrong length": (lambda: _grains(inertias=[1.0]), r"^inertias: .*\(2,\)"),
    "radii of the wrong length": (lambda: Grains.create(TWO, [0.5, 0.5, 0.5], masses=1.0),
                                  r"^radii: .*\(2,\)"),
    "spins of the wrong shape": (lambda: _grains(spins=[[0.0, 1.0, 2.0]]), r"^spins: "),
    "no grain": (lambda: Grains.create(np.zeros((0, 2)), 0.5, masses=1.0), r"^positions: .*0"),
    "a 3-vector plane normal in 2D": (
        lambda: Scene.create(_grains(), plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0, 0.0]),
        r"^planes.normals: .*dimension 2"),
    "a 3-vector plane point in 2D": (
        lambda: Scene.create(_grains(), plane_points=[0.0, 0.0, 0.0], plane_normals=[0.0, 1.0]),
        r"^planes.points: .*dimension 2"),
    "fixed positions without radii": (
        lambda: Scene.create(_grains(), fixed_positions=[[5.0, 0.0]]), r"^fixed_radii: .*required"),
    "law None": (lambda: Simulation(scenes.push_pull(), None, dt=0.1), r"^law: .*None"),
    "law a string": (lambda: Simulation(scenes.push_pull(), "gluey", dt=0.1), r"^law: .*'gluey'"),
    "a fractional step count": (lambda: Simulation(scenes.push_pull(), Inelastic(), 0.1).run(2.7),
                                r"^n_steps: .*2.7"),
    "an unknown solver": (lambda: Simulation(scenes.push_pull(), Inelastic(), 0.1, solver="foo"),
                          r"^solver: .*'foo'"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input_names_the_field(name):
    build, message = CASES[name]
    with pytest.raises(ValueError, match=message):
        build()


def test_roughness_at_least_the_effective_radius_is_rejected():
    """gamma_min = k ln(eps / r_eff) >= 0 would switch the glue off silently."""
    law = GlueyLubrication(viscosity=1e-3, roughness=0.5)
    scene = Scene.create(_grains(), plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0])
    contacts = find_contacts(scene, 0.1)
    assert contacts.count == 2                      # two grains of radius 0.5 on the floor
    with pytest.raises(ValueError, match=r"^roughness: .*0.5.*effective radius"):
        law.gamma_min(contacts)
