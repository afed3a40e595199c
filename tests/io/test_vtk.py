"""ParaView export: VTU frames read back with meshio carry the grains and contact fields."""
import meshio
import numpy as np

from lubcontact import Coulomb, GlueyCoulomb, Simulation, scenes
from lubcontact.io.vtk import write_pvd, write_vtu


def test_a_frame_opens_with_meshio_and_carries_the_fields(tmp_path):
    law = GlueyCoulomb(0.3, gamma_min=-0.5)
    sim = Simulation(scenes.settling_pile(40, seed=2), law, dt=0.05, solver="apgd", tol=1e-8)
    sim.run(30)
    report = sim.step()
    contacts = report.contacts
    normal, _ = report.problem.cones.split(report.result.forces)
    states = law.contact_states(contacts, report.gamma, (report.gamma < 0) | (normal > 0))
    frames = []
    for k in range(2):
        path = write_vtu(tmp_path / f"frame_{k}.vtu", sim.scene, contacts, gamma=report.gamma,
                         normal_force=normal, states=states)
        frames.append((sim.scene.time + k, path))
    write_pvd(tmp_path / "flow.pvd", frames)

    mesh = meshio.read(tmp_path / "frame_0.vtu")
    grains = sim.scene.grains
    np.testing.assert_allclose(mesh.points[:, :2], grains.positions)
    np.testing.assert_allclose(mesh.point_data["radius"], grains.radii)
    np.testing.assert_allclose(mesh.point_data["velocity"][:, :2], grains.velocities)
    lines = mesh.cells_dict["line"]
    pairs = contacts.a_is_free
    assert lines.shape == (np.count_nonzero(pairs), 2)
    block = [c.type for c in mesh.cells].index("line")
    gamma = mesh.cell_data["gamma"][block]
    np.testing.assert_allclose(gamma, report.gamma[pairs])
    state = mesh.cell_data["state"][block]
    np.testing.assert_array_equal(state, (states[1] + 2 * states[2])[pairs])
    assert np.all((state > 0) == (gamma < 0)) and np.any(state == 2.0) == np.any(gamma <= -0.5)
    assert (tmp_path / "flow.pvd").read_text().count("<DataSet") == 2
    assert not list(tmp_path.glob("*.tmp*"))


def test_a_dry_frame_marks_its_contacts_frictional(tmp_path):
    """Dry Coulomb contacts carry no glue but are frictional: state 2 (the frame's own rule,
    from gamma and gamma_min, called them unglued)."""
    law = Coulomb(0.3)
    sim = Simulation(scenes.settling_pile(40, seed=2), law, dt=0.05, solver="apgd", tol=1e-8)
    sim.run(40)
    contacts, gamma, normal = sim.last_contacts()
    active = (gamma < 0) | (normal > 0)
    write_vtu(tmp_path / "dry.vtu", sim.scene, contacts, gamma=gamma, normal_force=normal,
              states=law.contact_states(contacts, gamma, active))
    mesh = meshio.read(tmp_path / "dry.vtu")
    state = mesh.cell_data["state"][[c.type for c in mesh.cells].index("line")]
    pairs = contacts.a_is_free
    assert np.count_nonzero(active[pairs]) >= 5
    np.testing.assert_array_equal(state, np.where(active[pairs], 2.0, 0.0))
