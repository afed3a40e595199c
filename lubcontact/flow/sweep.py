"""The angle sweep: settled beds, an inclined-flow run per model and angle, ``sweep.csv``.

In the sweep's folder: ``bed.npz`` (the bed every run tilts), one folder per run
``<model>/angle_<angle>/`` (the files of :mod:`lubcontact.flow.run`) and
``sweep.csv`` with one row per run (:data:`SWEEP_COLUMNS`). A sweep over seeds
or physical parameters (:data:`AXES`) repeats that layout in one folder per
combination, ``seed_<k>/eta_<eta>/eps_<eps>/`` (only the axes it varies), each
with its own bed, and adds ``sweep_means.csv``: the means over seeds and their
spread (:func:`seed_means`). With ``start_from`` no bed is settled: each run
starts from its model's and seed's developed flow (:func:`start_path`). Each run is
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
from ..io.files import atomic_path, save_text
from . import interrupt
from .bed import initial_scene
from .config import DEFINING_FIELDS, Q_UNIT, RunConfig, flow_rate_unit
from .run import FlowRun

SWEEP_COLUMNS = ("model", "angle", "seed", "viscosity", "roughness", "flow_rate", "flow_rate_std",
                 "state", "energy_ratio", "relative_change", "fraction_unglued", "fraction_glued",
                 "fraction_frictional", "mean_velocity", "coordination_unglued",
                 "coordination_glued", "coordination_frictional",
                 "kinetic_energy", "steps", "time", "unconverged_steps", "rescued_steps",
                 "max_cross_check",
                 "wall_time", "steps_per_second", "cpu_time", "steps_per_cpu_second",
                 "warm_up_time", "solver", "tol")
"""Columns of ``sweep.csv``: keys of :meth:`lubcontact.flow.run.FlowRun.summary`."""
COLUMN_UNITS = {"angle": "deg", "flow_rate": Q_UNIT, "flow_rate_std": Q_UNIT, "wall_time": "s",
                "cpu_time": "s", "warm_up_time": "s", "viscosity": "Pa s", "roughness": "m",
                "mean_velocity": "sqrt(g' d)"}
"""Units written in the header of ``sweep.csv``: ``flow_rate [d sqrt(g' d)]``."""


def csv_header(column: str) -> str:
    """The header of a column of ``sweep.csv``: its key, with its unit in brackets if it has one."""
    unit = COLUMN_UNITS.get(column)
    return column if unit is None else f"{column} [{unit}]"


AXES = {"seed": "seed", "viscosity": "eta", "roughness": "eps"}
"""The :class:`RunConfig` fields a sweep can vary besides model and angle, and the prefix of
their folder names."""
MEAN_KEYS = ("model", "angle", "viscosity", "roughness")
"""What a row of ``sweep_means.csv`` is for: the runs that differ only by their seed."""
MEAN_COLUMNS = ("flow_rate", "mean_velocity", "fraction_unglued", "fraction_glued",
                "fraction_frictional", "coordination_unglued", "coordination_glued",
                "coordination_frictional")
"""The quantities averaged over seeds in ``sweep_means.csv`` (each with ``_sd``, its sample
standard deviation over seeds, and ``_se``, the standard error of the mean)."""


def run_folder(out_dir: pathlib.Path, model: str, angle: float) -> pathlib.Path:
    """The folder of one run of a sweep: ``out_dir/<model>/angle_<angle, 05.2f>``."""
    return pathlib.Path(out_dir) / model / f"angle_{float(angle):05.2f}"


def group_folder(out_dir: pathlib.Path, group: dict[str, Any]) -> pathlib.Path:
    """The folder of one combination of the varied :data:`AXES`: ``out_dir/seed_1/eta_0.01``.

    Parameters
    ----------
    out_dir : pathlib.Path
        The sweep's folder.
    group : dict of str to value
        The values of the varied axes (an empty dict: ``out_dir`` itself).
    """
    folder = pathlib.Path(out_dir)
    for name, prefix in AXES.items():
        if name in group:
            value = group[name]
            folder = folder / (f"{prefix}_{int(value)}" if name == "seed" else
                               f"{prefix}_{float(value):.12g}")
    return folder


def axis_groups(**axes: list | None) -> list[dict[str, Any]]:
    """Every combination of the given axes' values, the first axis of :data:`AXES` outermost.

    Parameters
    ----------
    **axes : list or None
        Values of the fields of :data:`AXES`; None or absent: not varied.

    Returns
    -------
    list of dict
        ``[{}]`` when nothing varies.

    Raises
    ------
    ValueError
        Naming an axis that is not in :data:`AXES`, or an axis with no value or values
        that share a folder name (:func:`group_folder`: 12 significant digits).
    """
    groups: list[dict[str, Any]] = [{}]
    for name in axes:
        checks.require(name in AXES, name, f"not a sweep axis (axes: {', '.join(AXES)})", None)
    for name in AXES:
        values = axes.get(name)
        if values is None:
            continue
        names = {group_folder(".", {name: value}).name for value in values}
        checks.require(len(values) > 0 and len(names) == len(values), name,
                       "needs distinct values (to 12 significant digits)", values)
        groups = [{**group, name: value} for group in groups for value in values]
    return groups


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

    Those are the :data:`~lubcontact.flow.config.DEFINING_FIELDS`, the
    friction coefficient (the runs of one sweep share it) and ``average_from``
    (a finished run is read back with its own averaging window); ``bed`` and
    ``start_from``, paths that may be spelled differently, are not compared.

    Returns
    -------
    dict of str to (stored, requested)
        Empty when the folder holds no checkpoint or the same run.
    """
    checkpoint = pathlib.Path(run_dir) / "checkpoint.npz"
    if not checkpoint.exists():
        return {}
    stored = stored_config(checkpoint)
    names = tuple(name for name in DEFINING_FIELDS if name not in ("bed", "start_from")) \
        + ("average_from",)
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
          progress: bool = False, workers: int = 1, scheduler: str | None = None,
          groups: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """Every (group, model, angle) run; finished runs are read back, not redone.

    Prints one line per run it finishes, then writes ``out_dir/sweep.csv``
    and, when ``groups`` vary the seed, ``out_dir/sweep_means.csv``.

    Parameters
    ----------
    config : RunConfig
        Settings of every run (``model``, ``angle``, ``bed``, ``start_from``
        and the fields of ``groups`` are set per run: :func:`sweep_runs`).
    angles : ndarray, shape (n,)
        Incline angles (degrees).
    models : list of str
        Models of :data:`lubcontact.scenes.inclined.MODELS`.
    out_dir : pathlib.Path
        The sweep's folder.
    progress, workers, scheduler
        As :func:`run_all`.
    groups : list of dict, optional
        Combinations of the :data:`AXES` to run (:func:`axis_groups`), each
        in its :func:`group_folder` with its own bed (default: ``[{}]``, the
        config's values, in ``out_dir``).

    Returns
    -------
    list of dict
        The runs' summaries: groups outer, then models, then angles.

    Raises
    ------
    ValueError
        As :func:`run_all`.
    Interrupted
        As :func:`run_all`.
    """
    out_dir = pathlib.Path(out_dir)
    print(f"Q: time-averaged flow rate per unit depth, in units of {Q_UNIT} "
          "(d: mean grain diameter, g': reduced gravity)", flush=True)
    rows = run_all(sweep_runs(config, angles, models, out_dir, groups), progress, workers,
                   scheduler)
    write_csv(out_dir / "sweep.csv", rows, SWEEP_COLUMNS)
    if any("seed" in group for group in groups or [{}]):
        write_csv(out_dir / "sweep_means.csv", seed_means(rows), _mean_columns())
    return rows


def sweep_runs(config: RunConfig, angles: np.ndarray, models: list[str], out_dir: pathlib.Path,
               groups: list[dict[str, Any]] | None = None) -> list[tuple[RunConfig, pathlib.Path]]:
    """The runs of :func:`sweep` (same parameters): each config and folder, in sweep order.

    Each run tilts its group's ``bed.npz``, or, with ``config.start_from``, the state of that
    path with ``{model}`` and ``{seed}`` replaced by the run's (:func:`start_path`).
    """
    runs = []
    for group in groups or [{}]:
        folder = group_folder(out_dir, group)
        for model in models:
            for angle in angles:
                run = replace(config, **group, model=model, angle=float(angle))
                start = start_path(run)
                runs.append((replace(run, start_from=start,
                                     bed="" if start else str(folder / "bed.npz")),
                             run_folder(folder, model, angle)))
    return runs


def start_path(config: RunConfig) -> str:
    """``config.start_from`` with ``{model}`` and ``{seed}`` replaced by the config's values.

    Raises
    ------
    ValueError
        Naming ``start_from`` when it holds another placeholder or a stray brace.
    """
    try:
        return config.start_from.format(model=config.model, seed=config.seed)
    except (KeyError, IndexError, ValueError, AttributeError, TypeError) as exc:
        raise ValueError(f"start_from: the placeholders are {{model}} and {{seed}}, a literal "
                         f"brace is written twice ({exc}), got {config.start_from!r}") from None


def run_all(runs: list[tuple[RunConfig, pathlib.Path]], progress: bool = False, workers: int = 1,
            scheduler: str | None = None) -> list[dict[str, Any]]:
    """Independent runs, each in its folder, from the beds or the states their configs name.

    The beds that unfinished runs need are settled first, here, one after
    the other (:func:`~lubcontact.flow.bed.initial_scene`); then the runs go
    out. Runs are deterministic, so the results do not depend on
    ``workers`` or ``scheduler``.

    Parameters
    ----------
    runs : list of (RunConfig, pathlib.Path)
        Each run's config (its ``bed`` a path, settled there when absent, or its
        ``start_from`` a run's checkpoint)
        and folder.
    progress : bool
        Show progress bars (sequential runs only).
    workers : int
        Runs at once, each in its own process (1: one after the other, here).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``): the
        runs become tasks of that cluster instead (``workers`` is then
        ignored). Its workers must read and write the run folders (one file
        system for all) and have lubcontact installed. A worker lost mid-run
        loses at most one checkpoint interval: Dask gives its task to another
        worker, which continues the run from its checkpoint. Needs the
        optional dependency ``distributed`` (``pip install lubcontact[dask]``).

    Returns
    -------
    list of dict
        The runs' summaries, in the order of ``runs``.

    Raises
    ------
    ValueError
        When a run folder holds a run made with other settings (:func:`check_folder`),
        or ``workers`` is not a positive integer.
    Interrupted
        When a stop is requested (:mod:`lubcontact.flow.interrupt`): the runs
        under way are checkpointed; running again continues them.
    """
    workers = int(checks.positive("workers", workers, shape=()))
    for run_config, run_dir in runs:
        check_folder(run_dir, run_config)
    beds = {}
    for run_config, run_dir in runs:
        if not (run_dir / "summary.json").exists() and not run_config.start_from:
            beds.setdefault(run_config.bed, run_config)
    for run_config in beds.values():      # each bed settled once, saved, before the runs
        initial_scene(run_config, None, progress)
    if scheduler is not None:
        return _on_dask(runs, scheduler)
    if workers == 1 or len(runs) == 1:
        return [_report(run_sweep_point(run_config, run_dir, progress))
                for run_config, run_dir in runs]
    return _in_processes(runs, workers)


def run_sweep_point(config: RunConfig, run_dir: pathlib.Path,
                    progress: bool = False) -> tuple[dict[str, Any], bool]:
    """One run of a sweep: read back when finished, continued from its checkpoint, or started.

    A new run starts from the bed at ``config.bed`` (settled there when absent) or from
    ``config.start_from``. A run finished here, started or continued from its checkpoint, also
    draws its last state, contacts coloured by their glue level, in ``run_dir/snapshot.png``.

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
        run = FlowRun(config, initial_scene(config, None, progress), run_dir)
    summary = run.finish(progress)
    from . import plots

    plots.snapshot(run.sim, run.last_report, run_dir / "snapshot.png")
    return summary, True


def _worker_point(config: RunConfig, run_dir: pathlib.Path) -> tuple[dict[str, Any], bool]:
    """:func:`run_sweep_point` in a worker process: a signal checkpoints the run under way."""
    with interrupt.stop_on_signals():
        return run_sweep_point(config, run_dir)


def _in_processes(runs: list[tuple[RunConfig, pathlib.Path]], workers: int) -> list[dict[str, Any]]:
    """The runs in ``workers`` processes (spawned: they start from a fresh interpreter), in order."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        return _gather(pool.submit, as_completed, runs)


def _on_dask(runs: list[tuple[RunConfig, pathlib.Path]], scheduler: str) -> list[dict[str, Any]]:
    """The runs as tasks of the Dask cluster at ``scheduler``, in order."""
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError as exc:
        raise ValueError("scheduler: a Dask cluster needs the optional dependency 'distributed' "
                         "(pip install lubcontact[dask])") from exc
    with Client(scheduler) as client:
        return _gather(partial(client.submit, pure=False), dask_completed, runs)


def _gather(submit: Callable, completed: Callable, runs: list[tuple[RunConfig, pathlib.Path]]
            ) -> list[dict[str, Any]]:
    """Submit every run (``submit(function, *args)`` returns a future), report each as
    ``completed(futures)`` yields it, return the summaries in the order of ``runs``."""
    rows: list[dict[str, Any] | None] = [None] * len(runs)
    futures = {submit(_worker_point, run_config, run_dir): index
               for index, (run_config, run_dir) in enumerate(runs)}
    for future in completed(list(futures)):
        rows[futures[future]] = _report(future.result())
    return rows


def _report(outcome: tuple[dict[str, Any], bool]) -> dict[str, Any]:
    """Print the line of a run computed now; return its summary."""
    summary, computed = outcome
    if computed:
        where = "".join(f"{prefix} {summary[name]:g}  " for name, prefix in AXES.items()
                        if summary.get(name) is not None)
        if summary.get("ramp_stages"):
            top = summary["angle"] + summary["ramp_stages"] * summary["ramp_step"]
            print(f"{summary['model']:6s} ramp {summary['angle']:g} -> {top:g} -> "
                  f"{summary['angle']:g} deg  {where}{summary['steps_per_second']:.1f} steps/s",
                  flush=True)
        else:
            print(f"{summary['model']:6s} {summary['angle']:5.1f} deg  {where}"
                  f"Q = {summary['flow_rate']:.4g} {Q_UNIT}  {summary['state']}  "
                  f"{summary['steps_per_second']:.1f} steps/s", flush=True)
        if summary.get("failure"):
            print(f"       stopped at {summary['failure']}", flush=True)
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


def write_csv(path: pathlib.Path, rows: list[dict[str, Any]],
              columns: tuple[str, ...] = SWEEP_COLUMNS) -> None:
    """Write rows as CSV (atomically), the ``columns`` only.

    The header names each column with its unit (:func:`csv_header`); a
    quantity without a value (None, NaN) is an empty cell.

    Parameters
    ----------
    path : pathlib.Path
        The ``.csv`` file.
    rows : list of dict
        Run summaries (other keys are left out).
    columns : tuple of str
        The keys written, in order (default :data:`SWEEP_COLUMNS`).
    """
    with atomic_path(path) as temporary, open(temporary, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow([csv_header(column) for column in columns])
        for row in rows:
            writer.writerow([_cell(row.get(column)) for column in columns])


def _mean_columns() -> tuple[str, ...]:
    """Columns of ``sweep_means.csv``."""
    return (*MEAN_KEYS, "seeds", "failed", *(f"{name}{suffix}" for name in MEAN_COLUMNS
                                   for suffix in ("", "_sd", "_se")))


def mean_spread(values: list) -> tuple[float, float, int]:
    """Mean and sample standard deviation of the finite values among ``values``.

    Returns
    -------
    (float, float, int)
        The mean (NaN without a value), the standard deviation (``ddof = 1``;
        NaN with fewer than two values) and how many values entered (None and
        NaN are left out).
    """
    kept = np.array([v for v in values if v is not None], dtype=float)
    kept = kept[np.isfinite(kept)]
    return (float(np.mean(kept)) if kept.size else float("nan"),
            float(np.std(kept, ddof=1)) if kept.size > 1 else float("nan"), int(kept.size))


def seed_means(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Means over seeds of the runs that differ only by their seed (:data:`MEAN_KEYS`).

    Parameters
    ----------
    rows : list of dict
        Run summaries.

    Returns
    -------
    list of dict
        One per (model, angle, viscosity, roughness), in order of first
        appearance: those keys, ``seeds`` (how many runs enter the means),
        ``failed`` (runs left out: they stopped on a failed step,
        ``state == "failed"``), ``states`` (every run's state, failed ones
        included), ``flow_rate_std`` (the runs' fluctuation of Q over their
        averaging windows, averaged), and for each of :data:`MEAN_COLUMNS`
        its mean, ``_sd`` (sample standard deviation over the seeds, NaN for
        one seed) and ``_se`` (``sd / sqrt(seeds)``). Missing values (None,
        NaN) are left out of a mean (:func:`mean_spread`).
    """
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row.get(key) for key in MEAN_KEYS), []).append(row)
    means = []
    for key, every in groups.items():
        members = [row for row in every if row.get("state") != "failed"]
        mean = dict(zip(MEAN_KEYS, key), seeds=len(members), failed=len(every) - len(members),
                    states=[row.get("state") for row in every],
                    flow_rate_std=mean_spread([m.get("flow_rate_std") for m in members])[0])
        for name in MEAN_COLUMNS:
            average, sd, count = mean_spread([m.get(name) for m in members])
            mean.update({name: average, f"{name}_sd": sd,
                         f"{name}_se": sd / np.sqrt(count) if count > 1 else float("nan")})
        means.append(mean)
    return means


def write_report(out_dir: pathlib.Path, rows: list[dict[str, Any]], command: str) -> None:
    """Write ``out_dir/report.md``: the command, the seed means and the files of a sweep.

    Parameters
    ----------
    out_dir : pathlib.Path
        The sweep's folder (its figures already written).
    rows : list of dict
        The runs' summaries.
    command : str
        The command line that reproduces the sweep.
    """
    out_dir = pathlib.Path(out_dir)
    lines = ["# Sweep report", "", "Reproduce (finished runs are read back):", "", "```",
             command, "```", "",
             f"Flow rate Q in units of {Q_UNIT}, mean downhill velocity in sqrt(g' d); means "
             "over seeds +/- their standard deviation over seeds; fractions of the active "
             "contacts; z: active contacts per grain. Runs that stopped on a failed step "
             "(column 'failed') are left out of the means.", "",
             "| model | theta (deg) | eta (Pa s) | eps (m) | seeds | failed | Q | mean velocity | "
             "frictional | glued | unglued | z frictional | z glued | verdicts |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for mean in seed_means(rows):
        lines.append("| " + " | ".join([
            mean["model"], f"{float(mean['angle']):g}", _shown(mean["viscosity"]),
            _shown(mean["roughness"]), str(mean["seeds"]), str(mean["failed"]),
            _plus_minus(mean, "flow_rate"), _plus_minus(mean, "mean_velocity"),
            *(_shown(mean[f"fraction_{state}"], ".3f") for state in ("frictional", "glued",
                                                                      "unglued")),
            _shown(mean["coordination_frictional"], ".2f"),
            _shown(mean["coordination_glued"], ".2f"), ", ".join(mean["states"])]) + " |")
    figures = sorted(path.relative_to(out_dir).as_posix() for path in out_dir.rglob("*.png")
                     if path.name != "snapshot.png")
    lines += ["", "Files: `sweep.csv` (one row per run), `sweep_means.csv` (the table above, "
              "with standard errors), each run's folder (`summary.json`, `measurements.npz` with "
              "the time series, profiles and gamma histogram, `checkpoint.npz`, "
              "`snapshot.png`: the last state, contacts coloured by their glue level gamma / "
              "gamma_min).", "",
              "Figures:", ""] + [f"- `{name}`" for name in figures]
    save_text(out_dir / "report.md", "\n".join(lines) + "\n")


def _shown(value: Any, fmt: str = ".4g") -> str:
    """A table cell: the value formatted, ``-`` when it has none."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return format(value, fmt) if isinstance(value, (int, float)) else str(value)


def _plus_minus(mean: dict[str, Any], name: str) -> str:
    """``mean +/- sd`` of a seed mean (``mean`` alone with one seed)."""
    sd = mean[f"{name}_sd"]
    return _shown(mean[name]) + ("" if not np.isfinite(sd) else f" +/- {sd:.2g}")


def _cell(value: Any) -> Any:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    return value
