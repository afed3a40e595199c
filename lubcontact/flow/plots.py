"""Figures of the flow experiment (matplotlib, Agg backend, files only).

Lengths are shown in mean diameters ``d = 2 r``, velocities in ``sqrt(g' d)``
and flow rates in ``d sqrt(g' d)`` (``g'`` the buoyant gravity), whatever the
unit system of the run; contacts show their glue level ``gamma / gamma_min``
(dimensionless).
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
from ..model.contacts import Contacts  # noqa: E402
from ..model.scene import Scene  # noqa: E402
from ..scenes import inclined  # noqa: E402
from ..sim import Simulation, StepReport  # noqa: E402
from . import measure  # noqa: E402
from .config import Q_UNIT  # noqa: E402
from .sweep import AXES, group_folder, run_folder, seed_means  # noqa: E402

GLUE_COLORMAP = "plasma_r"
"""Contacts from lubricated (0, light) to frictional (1, dark), as the poster draws them."""


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


def contact_segments(sim: Simulation, contacts: Contacts, gamma: np.ndarray, normal: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Centre-to-centre segments of the active grain-grain contacts and their glue level.

    Across the periodic boundary a segment is drawn from grain ``b`` to the
    nearest image of ``a``.

    Parameters
    ----------
    sim : Simulation
        After the step of the contacts.
    contacts : Contacts
    gamma, normal : ndarray, shape (nc,)
        Their glue state and normal impulse (impulse per unit depth, the run's units;
        :meth:`~lubcontact.sim.simulation.Simulation.last_contacts`).

    Returns
    -------
    segments : ndarray, shape (m, 2, 2)
        End points (length, the run's units).
    level : ndarray, shape (m,)
        1 for a frictional contact (at its floor gamma_min, or any contact of a dry
        Coulomb law), ``gamma / gamma_min`` for a glued one, 0 for an unglued one
        (:meth:`~lubcontact.model.laws.Law.contact_states`,
        :func:`~lubcontact.flow.measure.glue_level`).
    """
    scene = sim.scene
    n, n_fixed = scene.grains.count, len(scene.fixed_radii)
    centres = np.vstack([scene.grains.positions, scene.fixed_positions])
    active = (gamma < 0) | (normal > 0)
    _, glued, frictional = sim.law.contact_states(contacts, gamma, active)
    level = np.where(frictional, 1.0, np.where(glued, measure.glue_level(
        gamma, sim.law.gamma_min(contacts)), 0.0))
    use = active & (contacts.body_a < n + n_fixed)
    b = centres[contacts.body_b[use]]
    delta = b - centres[contacts.body_a[use]]
    if scene.period is not None:
        delta[:, 0] -= scene.period * np.round(delta[:, 0] / scene.period)
    return np.stack([b, b - delta], axis=1), level[use]


def snapshot(sim: Simulation, report: StepReport | None, path: pathlib.Path,
             title: str | None = None) -> None:
    """Grains, rough bed and contacts coloured by their glue level (1 frictional, 0 lubricated).

    Parameters
    ----------
    sim : Simulation
    report : StepReport or None
        The last step; None: the contacts of ``sim``'s state (none before its first step).
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
    drawn = sim.last_contacts(report)
    if drawn is not None and drawn[0].count:
        segments, level = contact_segments(sim, *drawn)
        lines = LineCollection(segments / d, cmap=GLUE_COLORMAP, linewidths=1.8)
        lines.set_array(level)
        lines.set_clim(0.0, 1.0)
        ax.add_collection(lines)
        bar = fig.colorbar(lines, ax=ax, fraction=0.03, pad=0.01)
        bar.set_label("glue level gamma / gamma_min (-)\n"
                      "0: unglued or lubricated  ...  1: frictional")
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


def line_colours(count: int) -> list:
    """Colours of lines drawn in order, one per line.

    Parameters
    ----------
    count : int
        Number of lines.

    Returns
    -------
    list
        Matplotlib colours: the ten-colour cycle ``C0..C9`` up to ten lines; beyond (the
        cycle would repeat) a sequential colour map from dark to light.
    """
    if count <= 10:
        return [f"C{k}" for k in range(count)]
    return list(plt.get_cmap("viridis")(np.linspace(0.0, 0.9, count)))


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
    for (label, prof), colour in zip(curves, line_colours(len(curves))):
        z = prof.centres / d
        ax_u.plot(prof.velocity / speed, z, label=label, color=colour)
        ax_phi.plot(prof.packing, z, label=label, color=colour)
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


def _curves(rows: list[dict]) -> dict[str, list[dict]]:
    """Sweep rows averaged over seeds (:func:`~lubcontact.flow.sweep.seed_means`), grouped into
    curves by model and the varied viscosity / roughness, each curve sorted by angle.

    A curve's label is its model, with ``eta`` and ``eps`` when they vary
    among the rows.

    Returns
    -------
    dict of str to list of dict
        Per label, the curve's seed means.
    """
    means = seed_means(rows)
    varied = [key for key in ("viscosity", "roughness")
              if len({mean.get(key) for mean in means}) > 1]
    curves: dict[str, list[dict]] = {}
    for mean in means:
        label = " ".join([mean["model"]] + [f"{AXES[key]} {mean[key]:g}" for key in varied])
        curves.setdefault(label, []).append(mean)
    return {label: sorted(c, key=lambda row: float(row["angle"])) for label, c in curves.items()}


def flow_rate_curve(rows: list[dict], path: pathlib.Path) -> None:
    """Q(theta) per model (and varied viscosity / roughness), Q in units of ``d sqrt(g' d)``.

    With several seeds a point is the mean over seeds and its error bar the
    standard deviation over seeds; with one seed, the standard deviation of
    Q over the run's averaging window.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (``model``, ``angle``, ``seed``, ``viscosity``,
        ``roughness``, ``flow_rate``, ``flow_rate_std``; the flow rates in
        units of ``d sqrt(g' d)``, as run summaries give them).
    path : pathlib.Path
        The image file.
    """
    fig, ax = plt.subplots(figsize=(6, 4.5))
    counts = set()
    for label, curve in _curves(rows).items():
        counts |= {int(row["seeds"]) for row in curve}
        errors = [row["flow_rate_sd"] if row["seeds"] > 1 else row["flow_rate_std"]
                  for row in curve]
        ax.errorbar([float(r["angle"]) for r in curve], [r["flow_rate"] for r in curve],
                    yerr=errors, marker="o", capsize=3, label=label)
    ax.set_xlabel("incline angle theta (degrees)")
    ax.set_ylabel(f"flow rate Q / ({Q_UNIT})")
    seeds = f"{min(counts)}-{max(counts)}" if len(counts) > 1 else str(max(counts, default=1))
    failed = sum(int(row.get("state") == "failed") for row in rows)
    ax.set_title((f"mean over {seeds} seeds, bars: standard deviation over seeds" if
                  max(counts, default=1) > 1 else
                  "bars: standard deviation of Q over the averaging window")
                 + (f"; {failed} failed run(s) left out" if failed else ""), fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, path)


STATE_COLOURS = {"unglued": "tab:blue", "glued": "tab:orange", "frictional": "tab:red"}


def _state_plot(rows: list[dict], quantity: str, ylabel: str) -> tuple[Figure, Axes]:
    """``<quantity>_<state>`` per state against the angle, one line style per curve of
    :func:`_curves`, seed means with their standard deviation over seeds as error bars."""
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    styles = ["-", "--", ":", "-."]
    for index, (label, curve) in enumerate(_curves(rows).items()):
        for state in measure.STATES:
            values = [r[f"{quantity}_{state}"] for r in curve]
            if np.all(np.asarray(values, dtype=float) == 0.0):
                continue              # a state no run has (a dry law's glued ones) is not drawn
            errors = [r[f"{quantity}_{state}_sd"] for r in curve]
            ax.errorbar([float(r["angle"]) for r in curve], values,
                        yerr=None if np.all(np.isnan(errors)) else errors,
                        linestyle=styles[index % len(styles)], color=STATE_COLOURS[state],
                        marker="o", markersize=4, capsize=2, label=f"{label}: {state}")
    ax.set_xlabel("incline angle theta (degrees)")
    ax.set_ylabel(ylabel)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    return fig, ax


def state_fractions(rows: list[dict], path: pathlib.Path) -> None:
    """Fractions of active contacts unglued / glued / frictional against the angle.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (``model``, ``angle``, ``fraction_<state>``).
    path : pathlib.Path
        The image file.
    """
    fig, ax = _state_plot(rows, "fraction", "fraction of active contacts (-)")
    ax.set_ylim(-0.03, 1.03)                  # fractions of 0 and 1 stay off the frame
    _save(fig, path)


def coordination_curve(rows: list[dict], path: pathlib.Path) -> None:
    """Contacts per free grain in each state against the angle.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (``model``, ``angle``, ``coordination_<state>``).
    path : pathlib.Path
        The image file.
    """
    fig, _ = _state_plot(rows, "coordination", "active contacts per grain (-)")
    _save(fig, path)


def regime_map(rows: list[dict], path: pathlib.Path) -> None:
    """The gluey model's contact regime over (angle, viscosity): frictional and glued fractions.

    Two panels of colour maps, the fraction of active contacts at ``gamma_min``
    (frictional) and strictly between ``gamma_min`` and 0 (glued,
    lubricated), seed means, with the angle along x and ``eta`` (log scale)
    along y.

    Parameters
    ----------
    rows : list of dict
        Sweep rows of the ``gluey`` model with several viscosities and one roughness.
    path : pathlib.Path
        The image file.
    """
    means = [m for m in seed_means(rows) if m["model"] == "gluey"]
    angles = sorted({float(m["angle"]) for m in means})
    etas = sorted({float(m["viscosity"]) for m in means})
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, state in zip(axes, ("frictional", "glued")):
        grid = np.full((len(etas), len(angles)), np.nan)
        for m in means:
            grid[etas.index(float(m["viscosity"])), angles.index(float(m["angle"]))] = \
                m[f"fraction_{state}"]
        image = ax.pcolormesh(_cell_edges(np.array(angles)), _cell_edges(np.log10(etas)), grid,
                              vmin=0.0, vmax=1.0, cmap="viridis")
        ax.set_xlabel("incline angle theta (degrees)")
        ax.set_title(f"{state} fraction of active contacts")
        fig.colorbar(image, ax=ax, label="fraction (-)")
    axes[0].set_ylabel("log10 of the viscosity eta / (Pa s)")
    _save(fig, path)


def _cell_edges(centres: np.ndarray) -> np.ndarray:
    """Edges of cells centred on sorted ``centres`` (a lone centre gets width 1)."""
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])


def sweep_figures(rows: list[dict], out_dir: pathlib.Path, preset: str = "dimensionless",
                  groups: list[dict] | None = None) -> None:
    """Q(theta), contact states, coordination, the regime map and the profiles of a sweep.

    Writes ``flow_rate.png``, ``contact_states.png`` and ``coordination.png``
    (seed means) and, with several viscosities, ``regime_map.png`` (one
    ``regime_map_eps_<eps>.png`` per roughness when that varies too) in
    ``out_dir``; ``profiles_<model>.png`` and, for the gluey model,
    ``gamma_gluey.png`` (from the runs' ``measurements.npz``) in each group's
    folder.

    Parameters
    ----------
    rows : list of dict
        Sweep rows (:func:`lubcontact.flow.sweep.sweep`).
    out_dir : pathlib.Path
        The sweep's folder.
    preset : str
        Parameter preset of the runs (units of the axes).
    groups : list of dict, optional
        The sweep's combinations of varied axes (default: none varied).
    """
    out_dir = pathlib.Path(out_dir)
    params = inclined.PRESETS[preset]()
    flow_rate_curve(rows, out_dir / "flow_rate.png")
    state_fractions(rows, out_dir / "contact_states.png")
    coordination_curve(rows, out_dir / "coordination.png")
    gluey = [row for row in rows if row["model"] == "gluey"]
    roughnesses = sorted({row.get("roughness") for row in gluey}, key=str)
    for roughness in roughnesses:          # one map per roughness: its cells are (angle, eta)
        mine = [row for row in gluey if row.get("roughness") == roughness]
        if len({row.get("viscosity") for row in mine}) > 1:
            name = "regime_map.png" if len(roughnesses) == 1 else \
                f"regime_map_{group_folder('.', {'roughness': roughness}).name}.png"
            regime_map(mine, out_dir / name)
    for group in groups or [{}]:
        folder = group_folder(out_dir, group)
        mine = [row for row in rows if all(row.get(k) == v for k, v in group.items())]
        for model in dict.fromkeys(row["model"] for row in mine):
            curves = []
            for row in sorted((r for r in mine if r["model"] == model),
                              key=lambda r: float(r["angle"])):
                path = run_folder(folder, model, row["angle"]) / "measurements.npz"
                if path.exists():
                    with np.load(path) as data:
                        curves.append((f"{float(row['angle']):g} deg", measure.Profile(
                            data["profile.edges"], data["profile.packing"],
                            data["profile.velocity"])))
            if curves:
                profiles(curves, folder / f"profiles_{model}.png", params)
        histograms = [(f"{float(row['angle']):g} deg", run_folder(folder, row["model"], row["angle"])
                       / "measurements.npz") for row in mine if row["model"] == "gluey"]
        histograms = [(label, path) for label, path in histograms if path.exists()]
        if histograms:
            gamma_histograms(histograms, folder / "gamma_gluey.png")


def gamma_histograms(runs: list[tuple[str, pathlib.Path]], path: pathlib.Path) -> None:
    """Distribution of ``gamma / gamma_min`` over the glued contacts of each run.

    Parameters
    ----------
    runs : list of (str, pathlib.Path)
        A label and the ``measurements.npz`` of each run (its ``gamma_histogram``,
        counted over the averaging window).
    path : pathlib.Path
        The image file (not written when no run has a glued contact).
    """
    histograms = []
    for label, file in runs:
        with np.load(file) as data:
            counts = data["gamma_histogram"].astype(float)
        if counts.sum() > 0:
            histograms.append((label, counts))
    if not histograms:
        return
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for (label, counts), colour in zip(histograms, line_colours(len(histograms))):
        edges = np.linspace(0.0, 1.0, counts.size + 1)
        ax.stairs(counts / counts.sum(), edges, label=label, color=colour)
    ax.set_xlabel("gamma / gamma_min (0: just glued, lubricated ... 1: frictional)")
    ax.set_ylabel("fraction of glued contact samples (-)")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, path)


def ramp_curves(stage_rows: list[dict], path: pathlib.Path, flow_speed: float) -> None:
    """Mean downhill velocity at the end of each hold of angle ramps, up and down.

    Parameters
    ----------
    stage_rows : list of dict
        Rows of ``stages.csv`` (:func:`lubcontact.flow.hysteresis.hysteresis`):
        ``model``, ``seed``, ``leg``, ``angle``, ``mean_velocity``.
    path : pathlib.Path
        The image file.
    flow_speed : float
        The threshold of a flowing layer (``sqrt(g' d)``), drawn as a line.
    """
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    colours: dict[str, str] = {}
    labelled: set[tuple[str, str]] = set()
    floor = 1e-7                        # a layer at rest: drawn at the bottom of the log axis
    for (model, seed) in dict.fromkeys((r["model"], r["seed"]) for r in stage_rows):
        colour = colours.setdefault(model, f"C{len(colours)}")
        mine = [r for r in stage_rows if r["model"] == model and r["seed"] == seed]
        up = [r for r in mine if r["leg"] == "up"]
        for leg, rows, style in (("up", up, "-"),       # the down leg starts from the top hold
                                 ("down", up[-1:] + [r for r in mine if r["leg"] == "down"], "--")):
            ax.plot([float(r["angle"]) for r in rows],
                    [max(abs(float(r["mean_velocity"])), floor) for r in rows], style,
                    color=colour, marker="o", markersize=3, alpha=0.8,
                    label=None if (model, leg) in labelled else f"{model}, {leg}")
            labelled.add((model, leg))
    ax.axhline(flow_speed, color="grey", linewidth=1, linestyle=":",
               label=f"flowing above {flow_speed:g}")
    ax.set_yscale("log")
    ax.set_xlabel("incline angle theta (degrees)")
    ax.set_ylabel("mean downhill velocity at the end of a hold / sqrt(g' d)")
    ax.set_title("angle ramps: up (solid) then down (dashed), one line per seed", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    _save(fig, path)
