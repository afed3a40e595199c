"""The angle sweep: one settled bed, an inclined-flow run per model and angle, ``sweep.csv``.

In the sweep's folder: ``bed.npz`` (the bed every run tilts), one folder per run
``<model>/angle_<angle>/`` (the files of :mod:`lubcontact.flow.run`) and
``sweep.csv`` with one row per run (:data:`SWEEP_COLUMNS`). Each run is
resumable: a finished one (its ``summary.json`` exists) is read back, an
interrupted one continues from its checkpoint. A folder holding a run that
another scene or physics made (:data:`~lubcontact.flow.config.DEFINING_FIELDS`)
is an error, not a silent mix of two sweeps.

Flow rates are in units of ``d sqrt(g' d)`` (:data:`~lubcontact.flow.config.Q_UNIT`),
in the console, in ``sweep.csv`` (named in its header) and in the figures.
"""
from __future__ import annotations

import csv
import json
import multiprocessing
import pathlib
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np

from .. import checks
from ..io.files import atomic_path
from . import interrupt
from .bed import initial_scene
from .config import DEFINING_FIELDS, Q_UNIT, RunConfig, flow_rate_unit
from .run import FlowRun

SWEEP_COLUMNS = ("model", "angle", "flow_rate", "flow_rate_std", "state", "energy_ratio",
                 "relative_change", "fraction_unglued", "fraction_glued", "fraction_frictional",
                 "kinetic_energy", "steps", "time", "unconverged_steps", "max_cross_check",
                 "wall_time", "steps_per_second", "cpu_time", "steps_per_cpu_second",
                 "warm_up_time", "solver", "tol")
"""Columns of ``sweep.csv``: keys of :meth:`lubcontact.flow.run.FlowRun.summary`."""
COLUMN_UNITS = {"angle": "deg", "flow_rate": Q_UNIT, "flow_rate_std": Q_UNIT, "wall_time": "s",
                "cpu_time": "s", "warm_up_time": "s"}
"""Units written in the header of ``sweep.csv``: ``flow_rate [d sqrt(g' d)]``."""


def csv_header(column: str) -> str:
    """The header of a column of ``sweep.csv``: its key, with its unit in brackets if it has one."""
    unit = COLUMN_UNITS.get(column)
    return column if unit is None else f"{column} [{unit}]"


def run_folder(out_dir: pathlib.Path, model: str, angle: float) -> pathlib.Path:
    """The folder of one run of a sweep: ``out_dir/<model>/angle_<angle, 05.2f>``."""
    return pathlib.Path(out_dir) / model / f"angle_{float(angle):05.2f}"


def stored_config(checkpoint: pathlib.Path) -> RunConfig:
    """The :class:`RunConfig` stored in a checkpoint."""
    with np.load(checkpoint) as data:
        return RunConfig.from_json(str(data["config"]))


def stored_steps(checkpoint: pathlib.Path) -> int:
    """Steps done by the run of a checkpoint (0 when there is none)."""
    if not pathlib.Path(checkpoint).exists():
        return 0
    with np.load(checkpoint) as data:
        return int(data["steps_done"])


def folder_conflicts(run_dir: pathlib.Path, config: RunConfig) -> dict[str, tuple]:
    """The fields of the run in ``run_dir`` that differ from ``config`` and must not.

    Those are the :data:`~lubcontact.flow.config.DEFINING_FIELDS` and the
    friction coefficient (the runs of one sweep share it); ``bed``, a path
    that may be spelled differently, is not compared.

    Returns
    -------
    dict of str to (stored, requested)
        Empty when the folder holds no checkpoint or the same run.
    """
    checkpoint = pathlib.Path(run_dir) / "checkpoint.npz"
    if not checkpoint.exists():
        return {}
    stored = stored_config(checkpoint)
    names = tuple(name for name in DEFINING_FIELDS if name != "bed")
    changed = stored.differences(config, names)
    if "preset" not in changed and stored.params.friction != config.params.friction:
        changed["friction"] = (stored.friction, config.friction)
    return changed


def check_folder(run_dir: pathlib.Path, config: RunConfig) -> None:
    """Refuse a run folder whose checkpoint was made with other defining fields.

    Raises
    ------
    ValueError
        Naming the folder and the fields that differ (:func:`folder_conflicts`).
    """
    changed = folder_conflicts(run_dir, config)
    if changed:
        raise ValueError(f"{run_dir} holds a run with other settings ("
                         + ", ".join(f"{name} {old!r}, here {new!r}"
                                     for name, (old, new) in changed.items())
                         + "): use another output folder")


def sweep(config: RunConfig, angles: np.ndarray, models: list[str], out_dir: pathlib.Path,
          progress: bool = False, workers: int = 1, scheduler: str | None = None) -> list[dict[str, Any]]:
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
        Show progress bars (sequential sweeps only).
    workers : int
        Runs at once, each in its own process (1: one after the other, here).
        The bed is settled first, here; the runs are independent and
        deterministic, so the results do not depend on ``workers``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``): the
        runs become tasks of that cluster instead (``workers`` is then
        ignored). Its workers must read and write ``out_dir`` (one file
        system for all) and have lubcontact installed. A worker lost mid-run
        loses at most one checkpoint interval: Dask gives its task to another
        worker, which continues the run from its checkpoint. Needs the
        optional dependency ``distributed`` (``pip install lubcontact[dask]``).

    Returns
    -------
    list of dict
        The runs' summaries, models outer, angles inner.

    Raises
    ------
    ValueError
        When a run folder holds a run made with other settings (:func:`check_folder`),
        or ``workers`` is not a positive integer.
    Interrupted
        When a stop is requested (:mod:`lubcontact.flow.interrupt`): the runs
        under way are checkpointed; running the sweep again continues them.
    """
    workers = int(checks.positive("workers", workers, shape=()))
    out_dir = pathlib.Path(out_dir)
    print(f"Q: time-averaged flow rate per unit depth, in units of {Q_UNIT} "
          "(d: mean grain diameter, g': reduced gravity)", flush=True)
    runs = []
    for model in models:
        for angle in angles:
            run_config = replace(config, model=model, angle=float(angle),
                                 bed=str(out_dir / "bed.npz"))
            run_dir = run_folder(out_dir, model, angle)
            check_folder(run_dir, run_config)
            runs.append((run_config, run_dir))
    if any(not (run_dir / "summary.json").exists() for _, run_dir in runs):
        initial_scene(runs[0][0], out_dir, progress)      # the common bed: settled once, saved
    if scheduler is not None:
        rows = _on_dask(runs, out_dir, scheduler)
    elif workers == 1 or len(runs) == 1:
        rows = [_report(run_sweep_point(run_config, run_dir, out_dir, progress))
                for run_config, run_dir in runs]
    else:
        rows = _in_processes(runs, out_dir, workers)
    write_csv(out_dir / "sweep.csv", rows)
    return rows


def run_sweep_point(config: RunConfig, run_dir: pathlib.Path, out_dir: pathlib.Path,
                    progress: bool = False) -> tuple[dict[str, Any], bool]:
    """One run of a sweep: read back when finished, continued from its checkpoint, or started.

    ``out_dir`` is the sweep's folder (its ``bed.npz`` is the bed, settled when absent).

    Returns
    -------
    (dict, bool)
        The run's summary, and whether it was computed now (False: read back).
    """
    done = run_dir / "summary.json"
    if done.exists():
        return _read_summary(done, config), False
    checkpoint = run_dir / "checkpoint.npz"
    if checkpoint.exists():      # with this sweep's settings (solver, periods, ...)
        changes = {name: getattr(config, name) for name in RunConfig.field_names() - set(DEFINING_FIELDS)}
        run = FlowRun.resume(checkpoint, run_dir, **changes)
    else:
        run = FlowRun(config, initial_scene(config, out_dir, progress), run_dir)
    return run.finish(progress), True


def _worker_point(config: RunConfig, run_dir: pathlib.Path,
                  out_dir: pathlib.Path) -> tuple[dict[str, Any], bool]:
    """:func:`run_sweep_point` in a worker process: a signal checkpoints the run under way."""
    with interrupt.stop_on_signals():
        return run_sweep_point(config, run_dir, out_dir)


def _in_processes(runs: list[tuple[RunConfig, pathlib.Path]], out_dir: pathlib.Path,
                  workers: int) -> list[dict[str, Any]]:
    """The runs in ``workers`` processes (spawned: they start from a fresh interpreter), in order."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        return _gather(pool.submit, as_completed, runs, out_dir)


def _on_dask(runs: list[tuple[RunConfig, pathlib.Path]], out_dir: pathlib.Path,
             scheduler: str) -> list[dict[str, Any]]:
    """The runs as tasks of the Dask cluster at ``scheduler``, in order."""
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError as exc:
        raise ValueError("scheduler: a Dask cluster needs the optional dependency 'distributed' "
                         "(pip install lubcontact[dask])") from exc
    with Client(scheduler) as client:
        return _gather(partial(client.submit, pure=False), dask_completed, runs, out_dir)


def _gather(submit: Callable, completed: Callable, runs: list[tuple[RunConfig, pathlib.Path]],
            out_dir: pathlib.Path) -> list[dict[str, Any]]:
    """Submit every run (``submit(function, *args)`` returns a future), report each as
    ``completed(futures)`` yields it, return the summaries in the order of ``runs``."""
    rows: list[dict[str, Any] | None] = [None] * len(runs)
    futures = {submit(_worker_point, run_config, run_dir, out_dir): index
               for index, (run_config, run_dir) in enumerate(runs)}
    for future in completed(list(futures)):
        rows[futures[future]] = _report(future.result())
    return rows


def _report(outcome: tuple[dict[str, Any], bool]) -> dict[str, Any]:
    """Print the line of a run computed now; return its summary."""
    summary, computed = outcome
    if computed:
        print(f"{summary['model']:6s} {summary['angle']:5.1f} deg  Q = {summary['flow_rate']:.4g} "
              f"{Q_UNIT}  {summary['state']}  {summary['steps_per_second']:.1f} steps/s", flush=True)
    return summary


def _read_summary(path: pathlib.Path, config: RunConfig) -> dict[str, Any]:
    """A finished run's ``summary.json``; flow rates of older files (length^2 / time) converted."""
    row = json.loads(path.read_text())
    if "units" not in row:
        scale = flow_rate_unit(config.params)
        for key in ("flow_rate", "flow_rate_std"):
            if row.get(key) is not None:
                row[key] = row[key] / scale
    return row


def write_csv(path: pathlib.Path, rows: list[dict[str, Any]]) -> None:
    """Write sweep rows as CSV (atomically), the :data:`SWEEP_COLUMNS` only.

    The header names each column with its unit (:func:`csv_header`); a
    quantity without a value (None, NaN) is an empty cell.

    Parameters
    ----------
    path : pathlib.Path
        The ``.csv`` file.
    rows : list of dict
        Run summaries (other keys are left out).
    """
    with atomic_path(path) as temporary, open(temporary, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow([csv_header(column) for column in SWEEP_COLUMNS])
        for row in rows:
            writer.writerow([_cell(row.get(column)) for column in SWEEP_COLUMNS])


def _cell(value: Any) -> Any:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    return value
