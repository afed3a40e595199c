"""The scene a run starts from: a sedimenting layer, or a settled bed tilted for the flow.

A settled bed is sedimented once (:func:`settle`) and kept as ``bed.npz``
(:func:`~lubcontact.io.scene_arrays.scene_arrays`), so that the runs of a
sweep, and a run started again, all tilt the same bed.
"""
from __future__ import annotations

import pathlib
from dataclasses import replace

import numpy as np

from ..io.files import save_npz
from ..io.scene_arrays import scene_arrays, scene_from_arrays
from ..model.scene import Scene
from ..scenes import inclined
from .config import RunConfig
from .run import FlowRun


def initial_scene(config: RunConfig, out_dir: pathlib.Path | None = None,
                  progress: bool = False) -> Scene:
    """The scene a config starts from.

    ``sedimentation`` starts from grains released above the rough bed;
    ``inclined_flow`` tilts a settled bed by ``config.angle``: the one at
    ``config.bed``, else ``out_dir/bed.npz`` when it exists, else one settled
    here by :func:`settle` (and saved to that path when there is one).

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
        Periodic along x, at rest for ``inclined_flow``.
    """
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
