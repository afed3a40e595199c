"""Figures of the flow experiment (matplotlib, Agg backend, files only).

Lengths are shown in mean diameters ``d = 2 r``, velocities in ``sqrt(g' d)``
and flow rates in ``d sqrt(g' d)`` (``g'`` the buoyant gravity), whatever the
unit system of the run; gamma keeps the run's units (impulse per unit depth).
An inclined flow's axes are the incline's (x downhill, y normal to it); a
sedimentation's are horizontal x and vertical z, with no angle.
"""
from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.collections import LineCollection, PatchCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle, Patch  # noqa: E402

from ..io.files import atomic_path  # noqa: E402
from ..model.scene import Scene  # noqa: E402
from ..scenes import inclined  # noqa: E402
from ..sim import Simulation, StepReport  # noqa: E402
from . import measure  # noqa: E402
from .config import Q_UNIT  # noqa: E402
from .sweep import run_folder  # noqa: E402

GAMMA_COLORMAP = "plasma"


def _save(fig: Figure, path: pathlib.Path) -> None:
    """Write ``fig`` atomically (format from the suffix of ``path``) and close it."""
    path = pathlib.Path(path)
    try:
        with atomic_path(path) as temporary:
            fig.savefig(temporary, format=path.suffix[1:] or None, dpi=130, bbox_inches="tight")
    finally:
        plt.close(fig)


def _disks(ax: Axes, centres: np.ndarray, radii: np.ndarray, scale: float, **style) -> None:
    """Disks of ``centres`` (n, 2) and ``radii`` (n,), lengths divided by ``scale``."""
    patches = [Circle((x / scale, y / scale), r / scale) for (x, y), r in zip(centres, radii)]
    ax.add_collection(PatchCollection(patches, **style))


def contact_segments(sim: Simulation, report: StepReport) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre-to-centre segments of the active grain-grain contacts and their gamma.

    Across the periodic boundary a segment is drawn from grain ``b`` to the
    nearest image of ``a``.

    Parameters
    ----------
    sim : Simulation
        After the step of ``report``.
    report : StepReport

    Returns
    -------
    segments : ndarray, shape (m, 2, 2)
        End points (length, the run's units).
    gamma : ndarray, shape (m,)
    gamma_floor : float
        The lowest finite gamma_min among the contacts (colour scale bottom).
    """
    scene, contacts = sim.scene, report.contacts
    n, n_fixed = scene.grains.count, len(scene.fixed_radii)
    centres = np.vstack([scene.grains.positions, scene.fixed_positions])
    normal = report.result.forces[: contacts.count]
    active = (report.gamma < 0) | (normal > 0)
    grain_pair = contacts.body_a < n + n_fixed
    use = active & grain_pair
    b = centres[contacts.body_b[use]]
    delta = b - centres[contacts.body_a[use]]
    if scene.period is not None:
        delta[:, 0] -= scene.period * np.round(delta[:, 0] / scene.period)
    segments = np.stack([b, b - delta], axis=1)
    floors = sim.law.gamma_min(contacts)
    finite = floors[np.isfinite(floors)]
    floor = float(finite.min()) if finite.size else min(float(report.gamma.min(initial=0.0)), -1e-30)
    return segments, report.gamma[use], floor


def snapshot(sim: Simulation, report: StepReport | None, path: pathlib.Path,
             title: str | None = None) -> None:
    """Grains, rough bed and contacts coloured by gamma (gamma_min frictional, 0 lubricated).

    Parameters
    ----------
    sim : Simulation
    report : StepReport or None
        The last step (None: no contacts drawn).
    path : pathlib.Path
        The image file (format from its suffix).
    title : str, optional
        Default: time, angle (an inclined flow) and number of grains.
    """
    scene = sim.scene
    d = 2.0 * float(np.mean(scene.grains.radii))
    width = scene.period or float(np.ptp(scene.grains.positions[:, 0]) + d)
    height = float(scene.grains.positions[:, 1].max() + d)
    fig, ax = plt.subplots(figsize=(10, max(3.0, 10 * height / width)))
    _disks(ax, scene.fixed_positions, scene.fixed_radii, d, facecolor="0.35", edgecolor="none")
    _disks(ax, scene.grains.positions, scene.grains.radii, d, facecolor="0.85", edgecolor="0.6",
           linewidth=0.3)
    if report is not None and report.contacts.count:
        segments, gamma, floor = contact_segments(sim, report)
        lines = LineCollection(segments / d, cmap=GAMMA_COLORMAP, linewidths=1.8)
        lines.set_array(gamma)
        lines.set_clim(floor, 0.0)
        ax.add_collection(lines)
        bar = fig.colorbar(lines, ax=ax, fraction=0.03, pad=0.01)
        bar.set_label("gamma (impulse per unit depth)\n"
                      "gamma_min: frictional  ...  0: lubricated")
    ax.set_xlim(0, width / d)
    ax.set_ylim(0, height / d)
    ax.set_aspect("equal")
    handles = [Patch(facecolor="0.85", edgecolor="0.6", label="grains")]
    if len(scene.fixed_radii):
        handles.append(Patch(facecolor="0.35", label="fixed bed (rough plane)"))
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    _gravity_arrow(ax, scene, height / d)
    if is_incline(scene):
        ax.set_xlabel("x / d (downhill, periodic)")
        ax.set_ylabel("y / d (normal to the incline)")
        where = f", theta = {scene.metadata.get('angle_deg', 0.0):g} deg"
    else:
        ax.set_xlabel("x / d (horizontal, periodic)")
        ax.set_ylabel("z / d (height above the plane)")
        where = ""
    ax.set_title(title or f"t = {scene.time:.4g}{where}, {scene.grains.count} grains")
    _save(fig, path)


def _gravity_arrow(ax: Axes, scene: Scene, height: float) -> None:
    """An arrow along gravity in the frame of the plot (tilted on an incline), labelled g."""
    direction = np.asarray(scene.gravity[:2], dtype=float)
    norm = float(np.linalg.norm(direction))
    if norm == 0:
        return
    length = 0.25 * height
    start = np.array([0.06 * ax.get_xlim()[1], 0.9 * height])
    end = start + length * direction / norm
    ax.annotate("", xy=end, xytext=start, arrowprops=dict(arrowstyle="-|>", color="tab:blue", lw=2))
    ax.text(*(start + 0.5 * (end - start) + [0.02 * height, 0.0]), "g", color="tab:blue",
            fontsize=11)


def is_incline(scene: Scene) -> bool:
    """Whether ``scene`` is an inclined flow (its metadata name; a sedimentation is not)."""
    return scene.metadata.get("name") != "sedimentation"


def profiles(curves: list[tuple[str, measure.Profile]], path: pathlib.Path,
             params: inclined.FlowParameters, incline: bool = True) -> None:
    """Velocity u(z) and packing fraction phi(z), one line per labelled profile.

    Parameters
    ----------
    curves : list of (str, Profile)
        Label and profile of each line.
    path : pathlib.Path
        The image file.
    params : FlowParameters
        The runs' parameters (units of the axes).
    incline : bool
        An inclined flow (velocity downhill, height normal to the incline);
        False: a sedimentation (horizontal velocity, vertical height).
    """
    d, speed = 2.0 * params.radius, params.velocity_scale
    fig, (ax_u, ax_phi) = plt.subplots(1, 2, figsize=(9, 4.5), sharey=True)
    for label, prof in curves:
        z = prof.centres / d
        ax_u.plot(prof.velocity / speed, z, label=label)
        ax_phi.plot(prof.packing, z, label=label)
    if incline:
        ax_u.set_xlabel("u / sqrt(g' d)  (downhill velocity)")
        ax_u.set_ylabel("z / d  (height above the plane under the bed, normal to it)")
    else:
        ax_u.set_xlabel("u_x / sqrt(g' d)  (horizontal velocity)")
        ax_u.set_ylabel("z / d  (height above the plane under the bed)")
    ax_phi.set_xlabel("packing fraction phi (-)")
    ax_u.legend(fontsize=8)
    ax_u.grid(alpha=0.3)
    ax_phi.grid(alpha=0.3)
    _save(fig, path)


def _by_model(rows: list[dict]) -> dict[str, list[dict]]:
    """Rows grouped by model, each group sorted by angle."""
    models: dict[str, list[dict]] = {}
    for row in rows:
        models.setdefault(row["model"], []).append(row)
    return {m: sorted(r, key=lambda row: float(row["angle"])) for m, r in models.items()}


def flow_rate_curve(rows: list[dict], path: pathlib.Path) -> None:
    """Q(theta) per model with its standard deviation, Q in units of ``d sqrt(g' d)``.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (``model``, ``angle``, ``flow_rate``, ``flow_rate_std``;
        the flow rates in units of ``d sqrt(g' d)``, as run summaries give them).
    path : pathlib.Path
        The image file.
    """
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for model, group in _by_model(rows).items():
        angles = [float(r["angle"]) for r in group]
        rates = [float(r["flow_rate"]) for r in group]
        errors = [float(r["flow_rate_std"]) for r in group]
        ax.errorbar(angles, rates, yerr=errors, marker="o", capsize=3, label=model)
    ax.set_xlabel("incline angle theta (degrees)")
    ax.set_ylabel(f"flow rate Q / ({Q_UNIT})")
    ax.legend()
    ax.grid(alpha=0.3)
    _save(fig, path)


def state_fractions(rows: list[dict], path: pathlib.Path) -> None:
    """Fractions of active contacts unglued / glued / frictional against the angle.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (``model``, ``angle``, ``fraction_<state>``).
    path : pathlib.Path
        The image file.
    """
    fig, ax = plt.subplots(figsize=(6, 4.5))
    styles = {"dry": "--", "gluey": "-"}
    for model, group in _by_model(rows).items():
        angles = [float(r["angle"]) for r in group]
        states = ("frictional",) if model == "dry" else measure.STATES   # dry: all Coulomb
        for state in states:
            colour = {"unglued": "tab:blue", "glued": "tab:orange", "frictional": "tab:red"}[state]
            ax.plot(angles, [float(r[f"fraction_{state}"]) for r in group], styles.get(model, ":"),
                    color=colour, marker="o", label=f"{model}: {state}")
    ax.set_xlabel("incline angle theta (degrees)")
    ax.set_ylabel("fraction of active contacts (-)")
    ax.set_ylim(-0.03, 1.03)                  # fractions of 0 and 1 stay off the frame
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, path)


def sweep_figures(rows: list[dict], out_dir: pathlib.Path, preset: str = "dimensionless") -> None:
    """Q(theta), contact-state fractions and the profiles of every run of a sweep.

    Writes ``flow_rate.png``, ``contact_states.png`` and ``profiles_<model>.png``
    (from the runs' ``measurements.npz``) in ``out_dir``.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (:func:`lubcontact.flow.sweep.sweep`).
    out_dir : pathlib.Path
        The sweep's folder.
    preset : str
        Parameter preset of the runs (units of the axes).
    """
    out_dir = pathlib.Path(out_dir)
    params = inclined.PRESETS[preset]()
    flow_rate_curve(rows, out_dir / "flow_rate.png")
    state_fractions(rows, out_dir / "contact_states.png")
    for model, group in _by_model(rows).items():
        curves = []
        for row in group:
            path = run_folder(out_dir, model, row["angle"]) / "measurements.npz"
            if path.exists():
                with np.load(path) as data:
                    curves.append((f"{float(row['angle']):g} deg", measure.Profile(
                        data["profile.edges"], data["profile.packing"], data["profile.velocity"])))
        if curves:
            profiles(curves, out_dir / f"profiles_{model}.png", params)
