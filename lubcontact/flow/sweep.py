"""The angle sweep: one settled bed, an inclined-flow run per model and angle, ``sweep.csv``.

In the sweep's folder: ``bed.npz`` (the bed every run tilts), one folder per run
``<model>/angle_<angle>/`` (the files of :mod:`lubcontact.flow.run`) and
``sweep.csv`` with one row per run (:data:`SWEEP_COLUMNS`). Each run is
resumable: a finished one (its ``summary.json`` exists) is read back, an
interrupted one continues from its checkpoint.
"""
from __future__ import annotations

import csv
import json
import pathlib
from dataclasses import replace
from typing import Any

import numpy as np

from ..io.files import atomic_path
from .bed import initial_scene
from .config import RunConfig
from .run import FlowRun

SWEEP_COLUMNS = ("model", "angle", "flow_rate", "flow_rate_std", "state", "energy_ratio",
                 "relative_change", "fraction_unglued", "fraction_glued", "fraction_frictional",
                 "kinetic_energy", "steps", "time", "unconverged_steps", "max_cross_check",
                 "wall_time", "steps_per_second", "cpu_time", "steps_per_cpu_second", "solver",
                 "tol")
"""Columns of ``sweep.csv``: keys of :meth:`lubcontact.flow.run.FlowRun.summary`."""


def run_folder(out_dir: pathlib.Path, model: str, angle: float) -> pathlib.Path:
    """The folder of one run of a sweep: ``out_dir/<model>/angle_<angle, 05.2f>``."""
    return pathlib.Path(out_dir) / model / f"angle_{float(angle):05.2f}"


def sweep(config: RunConfig, angles: np.ndarray, models: list[str], out_dir: pathlib.Path,
          progress: bool = False) -> list[dict[str, Any]]:
    """Every (model, angle) run from one settled bed; finished runs are read back, not redone.

    Prints one line per run it finishes, then writes ``out_dir/sweep.csv``.

    Parameters
    ----------
    config : RunConfig
        Settings of every run (``model``, ``angle`` and ``bed`` are set per run).
    angles : ndarray, shape (n,)
        Incline angles (degrees).
    models : list of str
        Models of :data:`lubcontact.scenes.inclined.MODELS`.
    out_dir : pathlib.Path
        The sweep's folder.
    progress : bool
        Show progress bars.

    Returns
    -------
    list of dict
        The runs' summaries, models outer, angles inner.
    """
    out_dir = pathlib.Path(out_dir)
    rows = []
    for model in models:
        for angle in angles:
            run_dir = run_folder(out_dir, model, angle)
            done = run_dir / "summary.json"
            if done.exists():
                rows.append(json.loads(done.read_text()))
                continue
            run_config = replace(config, model=model, angle=float(angle),
                                 bed=str(out_dir / "bed.npz"))
            checkpoint = run_dir / "checkpoint.npz"
            if checkpoint.exists():
                run = FlowRun.resume(checkpoint, run_dir, steps=run_config.steps)
            else:
                run = FlowRun(run_config, initial_scene(run_config, out_dir, progress), run_dir)
            summary = run.finish(progress)
            rows.append(summary)
            print(f"{model:6s} {angle:5.1f} deg  Q = {summary['flow_rate']:.4g}  "
                  f"{summary['state']}  {summary['steps_per_second']:.1f} steps/s", flush=True)
    write_csv(out_dir / "sweep.csv", rows)
    return rows


def write_csv(path: pathlib.Path, rows: list[dict[str, Any]]) -> None:
    """Write sweep rows as CSV (atomically), the :data:`SWEEP_COLUMNS` only.

    Parameters
    ----------
    path : pathlib.Path
        The ``.csv`` file.
    rows : list of dict
        Run summaries (other keys are left out).
    """
    with atomic_path(path) as temporary, open(temporary, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=SWEEP_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
