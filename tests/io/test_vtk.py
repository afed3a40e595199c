"""ParaView export: VTU frames read back with meshio carry the grains and contact fields."""
import meshio
import numpy as np

from lubcontact import GlueyCoulomb, Simulation, scenes
from lubcontact.io.vtk import write_pvd, write_vtu


def test_a_frame_opens_with_meshio_and_carries_the_fields(tmp_path):
    law = GlueyCoulomb(0.3, gamma_min=-0.5)
    sim = Simulation(scenes.settling_pile(40, seed=2), law, dt=0.05, solver="apgd", tol=1e-8)
    sim.run(30)
    report = sim.step()
    contacts = report.contacts
    normal, _ = report.problem.cones.split(report.result.forces)
    frames = []
    for k in range(2):
        path = write_vtu(tmp_path / f"frame_{k}.vtu", sim.scene, contacts, gamma=report.gamma,
                         normal_force=normal, gamma_min=law.gamma_min(contacts))
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
    assert set(np.unique(state)) <= {0.0, 1.0, 2.0}
    assert np.all((state > 0) == (gamma < 0)) and np.any(state == 2.0) == np.any(gamma <= -0.5)
    assert (tmp_path / "flow.pvd").read_text().count("<DataSet") == 2
    assert not list(tmp_path.glob("*.tmp*"))
