"""The scene a run starts from: a sedimenting layer, or a settled bed tilted for the flow.

A settled bed is sedimented once (:func:`settle`) and kept as ``bed.npz``
(:func:`~lubcontact.io.scene_arrays.scene_arrays`), so that the runs of a
sweep, and a run started again, all tilt the same bed.
"""
from __future__ import annotations

import pathlib
from dataclasses import replace

import numpy as np

from .. import checks
from ..io.files import save_npz
from ..io.scene_arrays import scene_arrays, scene_from_arrays
from ..model.scene import Scene
from ..scenes import inclined
from ..sim.state import SimulationState
from .config import RunConfig
from .run import FlowRun, read_checkpoint


def initial_scene(config: RunConfig, out_dir: pathlib.Path | None = None,
                  progress: bool = False) -> Scene:
    """The scene a config starts from.

    ``sedimentation`` starts from grains released above the rough bed;
    ``inclined_flow`` tilts a settled bed by ``config.angle``: the one at
    ``config.bed``, else ``out_dir/bed.npz`` when it exists, else one settled
    here by :func:`settle` (and saved to that path when there is one); with
    ``config.start_from``, the grains of that run's checkpoint instead,
    velocities kept, widened ``config.widen`` times (:func:`started_scene`).

    Parameters
    ----------
    config : RunConfig
    out_dir : pathlib.Path, optional
        Folder holding the runs' common ``bed.npz`` (used when ``config.bed`` is empty).
    progress : bool
        Show a progress bar while settling.

    Returns
    -------
    Scene
        Periodic along x, at rest for ``inclined_flow`` from a bed.
    """
    if config.start_from:
        return started_scene(config)
    params = config.params
    bed_scene = inclined.sedimentation(config.n_grains, params,
                                       width=config.width * params.radius, seed=config.seed)
    if config.scene == "sedimentation":
        return bed_scene
    bed_path = pathlib.Path(config.bed) if config.bed else None
    if bed_path is None and out_dir is not None:
        bed_path = pathlib.Path(out_dir) / "bed.npz"
    if bed_path is not None and bed_path.exists():
        with np.load(bed_path) as data:
            settled = scene_from_arrays(dict(data))
    else:
        settled = settle(config, bed_scene, progress)
        if bed_path is not None:
            save_npz(bed_path, **scene_arrays(settled))
    return inclined.inclined_flow(settled, config.angle)


def started_scene(config: RunConfig) -> Scene:
    """The grains of the run at ``config.start_from``, widened ``config.widen`` times (the
    copies parted by a jitter seeded by ``config.seed``), tilted to ``config.angle``, still
    moving.

    Parameters
    ----------
    config : RunConfig
        An ``inclined_flow`` with ``start_from`` the path of a run's ``checkpoint.npz``.

    Returns
    -------
    Scene
        The checkpoint's scene (positions, velocities, spins, rough bed, time), widened, its
        gravity turned to ``config.angle``.

    Raises
    ------
    ValueError
        Naming ``start_from`` when the file is missing, is not a run's checkpoint, or holds
        another number of grains or another period than ``config`` (once widened).
    """
    path = pathlib.Path(config.start_from)
    data = read_checkpoint(path, "start_from", "(a settled bed goes to bed)")
    scene = SimulationState.from_arrays(data).scene
    period = config.width * config.params.radius
    copies = int(config.widen)
    times = f" times {copies} copies" if copies > 1 else ""
    checks.require(scene.grains.count * copies == config.n_grains and scene.period is not None
                   and np.isclose(scene.period * copies, period), "start_from",
                   f"{path} holds {scene.grains.count} grains over a period {scene.period}{times}, "
                   f"the run {config.n_grains} grains over {period:g} (n_grains, width, widen)")
    if copies > 1:
        scene = inclined.widen(scene, copies, jitter=inclined.PARTING_JITTER, seed=config.seed)
    return inclined.inclined_flow(scene, config.angle, keep_velocities=True)


def settle(config: RunConfig, scene: Scene, progress: bool = False) -> Scene:
    """Sediment ``scene`` for ``config.settle_steps`` steps with ``config.settle_model``.

    Parameters
    ----------
    config : RunConfig
        The run the bed is for (its other settings: solver, time step, ...).
    scene : Scene
        The sedimentation scene.
    progress : bool
        Show a progress bar.

    Returns
    -------
    Scene
        The settled scene, its time reset to 0.
    """
    settling = replace(config, scene="sedimentation", model=config.settle_model,
                       steps=config.settle_steps, cross_check_every=0, frame_every=0,
                       ramp_step=0.0, ramp_stages=0, hold_steps=0)
    run = FlowRun(settling, scene)
    run.advance(settling.steps, progress)
    settled = run.sim.scene.copy()
    settled.time = 0.0
    return settled
