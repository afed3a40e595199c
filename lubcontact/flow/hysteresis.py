"""Hysteresis of the flow angle: an angle ramp up from rest and back down, theta_start and theta_stop.

A ramp run (:class:`~lubcontact.flow.config.RunConfig` with ``ramp_stages``)
tilts a settled bed to ``angle``, holds every angle ``hold_steps`` steps and
turns the incline by ``ramp_step`` degrees between holds, up for
``ramp_stages`` stages, then back down; the grains keep their velocities and
the contacts their gluey state across a change. At the end of each hold the
layer is *flowing* when its mean downhill velocity (mass-weighted, averaged
over the last :data:`END_FRACTION` of the hold) exceeds ``flow_speed``
(:data:`FLOW_SPEED` ``sqrt(g' d)`` by default):

- ``theta_start``: the first angle of the way up from which the layer flows
  at the end of every hold up to the top;
- ``theta_stop``: the first angle of the way down from which it is still at
  the end of every later hold (only when it flowed at the top);

so a stage's angle is an upper bound of the transition it shows: the layer
started (stopped) somewhere within one ``ramp_step`` below (above) it.

In the output folder: the runs ``seed_<k>/<model>/ramp/`` (the files of
:mod:`lubcontact.flow.run`), ``stages.csv`` (every hold of every run),
``hysteresis.csv`` (one row per model and seed) and ``ramp.png``.

Each leg alone, for layers too large for a whole ramp: :func:`ascent` measures
``theta_start``, the way up from the settled bed ended once the layer flows;
:func:`descent` measures ``theta_stop`` from a flowing layer's checkpoint (a
developed flow) turned down hold by hold, without the way up, whose creeping
bed is the costliest kind of step at a few thousand grains
(docs/records/poster-experiment.md).
"""
from __future__ import annotations

import pathlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .. import checks
from .bed import initial_scene
from .config import FLOW_SPEED, RunConfig
from .run import FlowRun
from .sweep import group_folder, mean_spread, run_all, write_csv

END_FRACTION = 0.25
"""The part of a hold (its last quarter) whose samples give the hold's end velocity."""
REST_FACTOR = 0.5
"""A descent ends within a hold, at least half way through it, once the mean downhill velocity
over its last ``END_FRACTION x hold`` steps is below this fraction of ``flow_speed``: the
layer is at rest, and a layer at rest does not start again on the way down, while each step of
a bed at rest costs tens of seconds at a few thousand grains (docs/records/poster-experiment.md,
"theta_stop at 2000 grains"; the hold is then recorded shortened, :attr:`Stage.steps`)."""
STAGE_COLUMNS = ("model", "seed", "stage", "leg", "angle", "steps", "mean_velocity",
                 "acceleration", "flowing")
"""Columns of ``stages.csv``: one row per hold of each run (``flowing``: 1 or 0;
``mean_velocity`` in ``sqrt(g' d)``, ``acceleration`` in ``g'``: :class:`Stage`)."""
RESULT_COLUMNS = ("model", "seed", "theta_start", "theta_stop", "width", "ramp_step",
                  "hold_steps", "flow_speed")
"""Columns of ``hysteresis.csv``: one row per model and seed (``width = theta_start -
theta_stop``, degrees; empty where undefined)."""


@dataclass
class Stage:
    """One hold of a ramp.

    Attributes
    ----------
    stage : int
        Its index (0-based).
    leg : str
        ``"up"`` or ``"down"``: the way the ramp turns (the first hold and the
        turning hold belong to the first leg, ``"up"`` unless ``ramp_step < 0``).
    angle : float
        Incline angle (degrees).
    mean_velocity : float
        Mean downhill velocity over the end of the hold (``sqrt(g' d)``).
    acceleration : float
        Change of the mean downhill velocity from the first to the last
        :data:`END_FRACTION` of the hold over the time between their middles,
        in units of ``g'``: about 0 where the layer, as it is, flows steadily
        at that angle; > 0 accelerating, < 0 slowing down.
    steps : int
        Steps run in the hold: ``hold_steps``, fewer for the last hold of a
        descent that ended it once the layer was at rest (:data:`REST_FACTOR`;
        its windows are then the first and last :data:`END_FRACTION` of a full
        hold's steps within the steps run).
    """

    stage: int
    leg: str
    angle: float
    mean_velocity: float
    acceleration: float
    steps: int


def ramp_config(config: RunConfig, start: float, stop: float, step: float, hold: int) -> RunConfig:
    """``config`` made a ramp up from ``start`` to ``stop`` degrees and back, ``step`` per hold.

    Parameters
    ----------
    config : RunConfig
        The other settings (model, seed, solver, ...).
    start, stop : float
        First and turning angle (degrees); ``stop`` is reached only if it is
        a whole number of ``step`` above ``start``, else the ramp turns below it.
    step : float
        Degrees per stage (> 0).
    hold : int
        Steps per angle; the run must sample at least twice in the last
        :data:`END_FRACTION` of a hold (``sample_every``).

    Raises
    ------
    ValueError
        Naming ``stop`` when it is not at least one ``step`` above ``start``,
        ``sample_every`` when a hold's end would have fewer than 2 samples, or
        a field :class:`RunConfig` refuses.
    """
    step = checks.positive_scalar("step", step)
    stages = _stage_count(stop - start, step, start, stop, "above")
    _check_sampling(config, hold)
    return replace(config, scene="inclined_flow", angle=float(start), ramp_step=float(step),
                   ramp_stages=stages, hold_steps=int(hold), steps=(2 * stages + 1) * int(hold))


def _stage_count(rise: float, step: float, start: float, stop: float, side: str) -> int:
    """Whole ``step``s in ``rise`` (degrees from ``start`` to ``stop``, counted in the ramp's
    direction), at least one; a ``ValueError`` naming ``stop`` (``side``: "above" or "below")."""
    stages = int(np.floor(rise / step + 1e-9))
    checks.require(stages >= 1, "stop", f"must be at least one step ({step:g}) {side} the first "
                   f"angle ({start:g})", stop)
    return stages


def _check_sampling(config: RunConfig, hold: int) -> None:
    """``config`` samples at least twice in the last :data:`END_FRACTION` of a ``hold``."""
    checks.require(2 * config.sample_every <= END_FRACTION * hold, "sample_every",
                   f"must be at most {END_FRACTION:g} x hold / 2 = {END_FRACTION * hold / 2:g} "
                   "(2 samples at the end of each hold)", config.sample_every)


def ramp_runs(config: RunConfig, models: list[str], seeds: list[int], out_dir: pathlib.Path
              ) -> list[tuple[RunConfig, pathlib.Path]]:
    """The runs of :func:`hysteresis`: ``config`` per model and seed, and each run's folder
    ``out_dir/seed_<k>/<model>/ramp`` (its bed ``out_dir/seed_<k>/bed.npz``), models outer."""
    runs = []
    for model in models:
        for seed in seeds:
            folder = group_folder(out_dir, {"seed": seed})
            runs.append((replace(config, model=model, seed=int(seed),
                                 bed=str(folder / "bed.npz")), folder / model / "ramp"))
    return runs


def stages(series: dict[str, np.ndarray], config: RunConfig) -> list[Stage]:
    """The holds of a ramp run and the velocity at the end of each.

    Parameters
    ----------
    series : dict of str to ndarray
        The run's time series (``step``, ``mean_velocity``; :data:`lubcontact.flow.run.SERIES`).
    config : RunConfig
        The ramp's config.

    Returns
    -------
    list of Stage
        The holds the run has reached (every hold of a finished run), in order.

    Raises
    ------
    ValueError
        Naming ``series`` when a hold the run has passed has no sample in its
        last :data:`END_FRACTION` (samples too sparse for the hold).
    """
    steps = np.asarray(series["step"], dtype=float)
    hold = int(config.hold_steps)
    out = []
    for stage in range(2 * int(config.ramp_stages) + 1):
        if steps.size == 0 or steps.max() < (stage + 1) * hold:
            break                                          # not reached (yet)
        out.append(_stage(series, config, stage, hold))
    return out


def _stage(series: dict[str, np.ndarray], config: RunConfig, stage: int, length: int) -> Stage:
    """Hold ``stage`` of a ramp read over its first ``length`` steps (:func:`stages`; ``length``
    below ``hold_steps``: a hold ended early, :data:`REST_FACTOR`)."""
    steps = np.asarray(series["step"], dtype=float)
    velocity = np.asarray(series["mean_velocity"], dtype=float)
    window = END_FRACTION * config.hold_steps
    first = stage * config.hold_steps
    end = (steps > first + length - window) & (steps <= first + length)
    start = (steps > first) & (steps <= first + window)
    checks.require(bool(end.any() and start.any()), "series",
                   f"no sample in the first or the last {END_FRACTION:g} of hold {stage} "
                   f"(steps {first + 1}-{first + length})", steps.size)
    legs = ("up", "down") if config.ramp_step > 0 else ("down", "up")
    elapsed = (length - window) * config.dt_fraction                   # in sqrt(d / g')
    return Stage(stage=stage, leg=legs[stage > config.ramp_stages],
                 angle=config.ramp_stage(first)[1], mean_velocity=float(np.mean(velocity[end])),
                 acceleration=float(np.mean(velocity[end]) - np.mean(velocity[start])) / elapsed,
                 steps=length)


def onset_angles(holds: list[Stage], flow_speed: float = FLOW_SPEED) -> tuple[float, float]:
    """``theta_start`` and ``theta_stop`` of a ramp (see the module).

    ``theta_start`` is the first angle of the way up from which the layer
    flows at the end of every hold up to the top (a transient that dies out,
    such as the bed's rearrangement just after the tilt, does not count);
    ``theta_stop`` the first angle of the way down from which it is still at
    the end of every later hold.

    Parameters
    ----------
    holds : list of Stage
        The ramp's holds (:func:`stages`).
    flow_speed : float
        Threshold of a flowing layer (``sqrt(g' d)``).

    Returns
    -------
    (float, float)
        The angles (degrees); NaN when the layer does not flow at the top
        (both), or does not stop by the end of the way down (``theta_stop``).
    """
    up = [h for h in holds if h.leg == "up"]
    down = [h for h in holds if h.leg == "down"]
    start = _last_run([abs(h.mean_velocity) > flow_speed for h in up])
    if start is None:
        return float("nan"), float("nan")
    return up[start].angle, _stop_angle(down, flow_speed)


def _stop_angle(down: list[Stage], flow_speed: float) -> float:
    """The first angle of the way down ``down`` from which the layer is still at the end of
    every later hold; NaN when it flows at the end of the last one."""
    stop = _last_run([abs(h.mean_velocity) <= flow_speed for h in down])
    return float("nan") if stop is None else down[stop].angle


def _last_run(flags: list[bool]) -> int | None:
    """Index where the final run of True values begins; None when the last flag is False."""
    if not flags or not flags[-1]:
        return None
    index = len(flags) - 1
    while index > 0 and flags[index - 1]:
        index -= 1
    return index


def hysteresis(config: RunConfig, models: list[str], seeds: list[int], out_dir: pathlib.Path, *,
               flow_speed: float = FLOW_SPEED, progress: bool = False, workers: int = 1,
               scheduler: str | None = None) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The ramp of ``config`` for every model and seed; ``stages.csv``, ``hysteresis.csv``.

    Each seed's runs start from its own settled bed (``seed_<k>/bed.npz``).
    Finished runs are read back, interrupted ones continue from their
    checkpoints (:func:`~lubcontact.flow.sweep.run_all`).

    Parameters
    ----------
    config : RunConfig
        A ramp (:func:`ramp_config`); ``model``, ``seed`` and ``bed`` are set per run.
    models : list of str
        Contact models.
    seeds : list of int
        Seeds (the grain sizes and the bed).
    out_dir : pathlib.Path
        The output folder.
    flow_speed : float
        Threshold of a flowing layer (``sqrt(g' d)``).
    progress, workers, scheduler
        As :func:`~lubcontact.flow.sweep.run_all`.

    Returns
    -------
    (list of dict, list of dict)
        One row per (model, seed), models outer: the :data:`RESULT_COLUMNS`;
        and one per hold of each run: the :data:`STAGE_COLUMNS`.
    """
    checks.require(config.ramp_stages > 0, "config", "must be a ramp (ramp_stages > 0)",
                   config.ramp_stages)
    flow_speed = checks.positive_scalar("flow_speed", flow_speed)
    out_dir = pathlib.Path(out_dir)
    runs = ramp_runs(config, models, seeds, out_dir)
    run_all(runs, progress, workers, scheduler)
    stage_rows, results = [], []
    for run_config, run_dir in runs:
        with np.load(run_dir / "measurements.npz") as data:
            series = _series(data)
        holds = stages(series, run_config)
        start, stop = onset_angles(holds, flow_speed)
        where = {"model": run_config.model, "seed": run_config.seed}
        stage_rows += _stage_rows(holds, where, flow_speed)
        results.append({**where, "theta_start": start, "theta_stop": stop,
                        "width": start - stop, "ramp_step": abs(run_config.ramp_step),
                        "hold_steps": run_config.hold_steps, "flow_speed": flow_speed})
    write_csv(out_dir / "stages.csv", stage_rows, STAGE_COLUMNS)
    write_csv(out_dir / "hysteresis.csv", results, RESULT_COLUMNS)
    return results, stage_rows


def _stage_rows(holds: list[Stage], where: dict[str, Any], flow_speed: float
                ) -> list[dict[str, Any]]:
    """Rows of ``stages.csv`` (:data:`STAGE_COLUMNS`) of one run's holds; ``where``: its model
    and seed."""
    return [{**where, "stage": h.stage, "leg": h.leg, "angle": h.angle, "steps": h.steps,
             "mean_velocity": h.mean_velocity, "acceleration": h.acceleration,
             "flowing": int(abs(h.mean_velocity) > flow_speed)} for h in holds]


@dataclass
class Leg:
    """The holds of one leg of a ramp run on its own (:func:`ascent`, :func:`descent`).

    Attributes
    ----------
    holds : list of Stage
        The holds run, all on the leg's way (up or down).
    failure : str or None
        Why the run stopped early (:attr:`lubcontact.flow.run.FlowRun.failure`).
    step_statuses : dict of str to int, or None
        Steps per solver status over the whole run (:attr:`~lubcontact.flow.run.FlowRun.statuses`).
    rescued_steps : int or None
        Steps solved again by Clarabel (:attr:`~lubcontact.flow.run.FlowRun.rescued`).
    """

    holds: list[Stage]
    failure: str | None
    step_statuses: dict[str, int] | None
    rescued_steps: int | None


@dataclass
class Descent(Leg):
    """What :func:`descent` measured: its holds and failure (:class:`Leg`), and ``theta_stop``.

    Attributes
    ----------
    theta_stop : float
        The angle (degrees) of the first hold that ended still: the layer
        stopped within one step above it. NaN when it still flowed at the
        last angle, was still at the first, or the run failed.
    """

    theta_stop: float


def descent(checkpoint: pathlib.Path, out_dir: pathlib.Path, start: float, stop: float,
            step: float, hold: int, *, flow_speed: float = FLOW_SPEED,
            progress: bool = False) -> Descent:
    """``theta_stop`` of a flowing layer: its run turned down by ``step`` degrees every ``hold`` steps.

    The state of ``checkpoint`` continues at ``start`` degrees: the grains keep
    their velocities, the contacts their glue states and the solver its warm
    start; only the incline turns, a ramp with ``ramp_step = -step`` (the
    holds and the threshold as in the module's ramps). The descent ends after
    the first hold that ends still (a lower angle does not set a layer at rest
    moving, and a bed at rest is the costliest kind of step), within that hold
    once the layer is at rest (:data:`REST_FACTOR`), or at ``stop``. A
    checkpoint is written after each hold and at such an end; called again with
    the same arguments, it continues from ``out_dir``'s checkpoint or reads the
    finished descent back. ``stages.csv`` lists the holds.

    Parameters
    ----------
    checkpoint : pathlib.Path
        A flowing layer's ``checkpoint.npz`` (an ``inclined_flow`` run).
    out_dir : pathlib.Path
        The descent's folder (its run's files and ``stages.csv``).
    start, stop : float
        First and lowest angle (degrees); ``stop`` is reached only if it is a
        whole number of ``step`` below ``start``.
    step : float
        Degrees per hold (> 0).
    hold : int
        Steps per angle (the run must sample twice in the last
        :data:`END_FRACTION` of a hold).
    flow_speed : float
        Threshold of a flowing layer (``sqrt(g' d)``).
    progress : bool
        Show a progress bar per hold.

    Returns
    -------
    Descent

    Raises
    ------
    ValueError
        Naming ``stop`` when it is not at least one ``step`` below ``start``;
        ``step``, ``hold`` or ``flow_speed`` out of range; ``sample_every``
        (the checkpoint's) when a hold is too short for it; ``out_dir`` when
        it holds a run of another descent; or a field :class:`RunConfig` refuses.
    """
    step = checks.positive_scalar("step", step)
    hold = checks.integer("hold", hold, minimum=1)
    flow_speed = checks.positive_scalar("flow_speed", flow_speed)
    stages_down = _stage_count(start - stop, step, start, stop, "below")
    out_dir = pathlib.Path(out_dir)
    base = FlowRun.resume(pathlib.Path(checkpoint), out_dir=out_dir)
    _check_sampling(base.config, hold)
    config = replace(base.config, angle=float(start), ramp_step=-step, ramp_stages=stages_down,
                     hold_steps=hold, steps=(2 * stages_down + 1) * hold, start_from="")
    run = _open_run(out_dir, config, "a descent", lambda: _continued(base, config, out_dir))
    holds = _hold_by_hold(run, hold, stages_down + 1, lambda holds: bool(holds) and abs(
        holds[-1].mean_velocity) <= flow_speed, progress, rest_speed=REST_FACTOR * flow_speed)
    _write_stages(out_dir, run, holds, flow_speed)
    theta_stop = _transition(holds, [abs(h.mean_velocity) <= flow_speed for h in holds],
                             run.failure)
    return Descent(theta_stop=theta_stop, holds=holds, failure=run.failure,
                   step_statuses=run.statuses, rescued_steps=run.rescued)


def _continued(base: FlowRun, config: RunConfig, out_dir: pathlib.Path) -> FlowRun:
    """A new run of ``config`` in ``out_dir`` that continues ``base``'s state: the grains'
    velocities, the contacts' glue states, the solver's warm start."""
    run = FlowRun(config, base.sim.scene, out_dir)
    run.sim.restore(replace(base.sim.state, steps_done=0, start_time=base.sim.scene.time))
    return run


@dataclass
class Ascent(Leg):
    """What :func:`ascent` measured: its holds and failure (:class:`Leg`), and ``theta_start``.

    Attributes
    ----------
    theta_start : float
        The angle (degrees) from which the layer flowed at the end of every
        later hold: it started within one step below it. NaN when it flowed
        from the first hold (the start was not below the transition), never
        flowed up to the last angle, or the run failed.
    """

    theta_start: float


def ascent(config: RunConfig, out_dir: pathlib.Path, start: float, stop: float, step: float,
           hold: int, *, confirm: int = 2, flow_speed: float = FLOW_SPEED,
           progress: bool = False) -> Ascent:
    """``theta_start`` of a settled bed: tilted to ``start`` degrees, turned up by ``step`` every
    ``hold`` steps until it flows.

    The way up of :func:`ramp_config`'s ramp (same holds, same threshold), ended
    once the last ``confirm`` holds have ended flowing (a layer that has started
    at a few thousand grains accelerates, and the way back down is
    :func:`descent`'s), or at ``stop``. The bed is ``config.bed``, else
    ``out_dir/bed.npz``, else one settled and saved there
    (:func:`~lubcontact.flow.bed.initial_scene`). A checkpoint is written after
    each hold; called again with the same arguments, it continues from
    ``out_dir``'s checkpoint or reads the finished ascent back. ``stages.csv``
    lists the holds.

    Parameters
    ----------
    config : RunConfig
        The other settings (model, seed, solver, size, ...).
    out_dir : pathlib.Path
        The ascent's folder (its run's files, ``stages.csv``, the bed if settled here).
    start, stop : float
        First and highest angle (degrees); ``stop`` is reached only if it is a
        whole number of ``step`` above ``start``.
    step : float
        Degrees per hold (> 0).
    hold : int
        Steps per angle (``config`` must sample twice in the last
        :data:`END_FRACTION` of a hold).
    confirm : int
        Consecutive flowing holds that end the ascent (>= 1).
    flow_speed : float
        Threshold of a flowing layer (``sqrt(g' d)``).
    progress : bool
        Show a progress bar per hold.

    Returns
    -------
    Ascent

    Raises
    ------
    ValueError
        Naming ``stop`` when it is not at least one ``step`` above ``start``;
        ``step``, ``hold``, ``confirm`` or ``flow_speed`` out of range;
        ``sample_every`` when a hold is too short for it; ``out_dir`` when it
        holds a run of another ascent; or a field :class:`RunConfig` refuses.
    """
    hold = checks.integer("hold", hold, minimum=1)
    confirm = checks.integer("confirm", confirm, minimum=1)
    flow_speed = checks.positive_scalar("flow_speed", flow_speed)
    config = ramp_config(config, start, stop, step, hold)
    out_dir = pathlib.Path(out_dir)
    run = _open_run(out_dir, config, "an ascent",
                    lambda: FlowRun(config, initial_scene(config, out_dir, progress), out_dir))

    def started(holds: list[Stage]) -> bool:
        return len(holds) >= confirm and all(abs(h.mean_velocity) > flow_speed
                                             for h in holds[-confirm:])

    holds = _hold_by_hold(run, hold, config.ramp_stages + 1, started, progress)
    _write_stages(out_dir, run, holds, flow_speed)
    theta_start = _transition(holds, [abs(h.mean_velocity) > flow_speed for h in holds],
                              run.failure)
    return Ascent(theta_start=theta_start, holds=holds, failure=run.failure,
                  step_statuses=run.statuses, rescued_steps=run.rescued)


def _transition(holds: list[Stage], flags: list[bool], failure: str | None) -> float:
    """The angle of the first hold of the final run of True ``flags`` (one per hold of a leg);
    NaN when the last flag is False, the run begins at the leg's first hold (the transition is
    not bracketed) or the run failed (``failure``)."""
    first = _last_run(flags)
    bracketed = first is not None and first > 0 and failure is None
    return holds[first].angle if bracketed else float("nan")


def _open_run(out_dir: pathlib.Path, config: RunConfig, what: str,
              new_run: Callable[[], FlowRun]) -> FlowRun:
    """``out_dir``'s run resumed from its checkpoint, else ``new_run()``; a ``ValueError``
    naming ``out_dir`` when the checkpoint's run is not ``config``'s (``what``: "a descent")."""
    if not (out_dir / "checkpoint.npz").exists():
        return new_run()
    run = FlowRun.resume(out_dir / "checkpoint.npz")
    changed = run.config.differences(config)
    checks.require(not changed, "out_dir", f"{out_dir} holds {what} with other settings: "
                   + ", ".join(f"{name} {_shown(old)} (asked {_shown(new)})"
                               for name, (old, new) in changed.items()))
    return run


def _shown(value: Any) -> str:
    """A setting as an error message shows it (numbers in ``g`` format)."""
    return f"{value:g}" if isinstance(value, (int, float, np.number)) else str(value)


def _hold_by_hold(run: FlowRun, hold: int, last: int, ended: Callable[[list[Stage]], bool],
                  progress: bool, rest_speed: float | None = None) -> list[Stage]:
    """Advance a ramp ``run`` one ``hold`` at a time, a checkpoint after each, until it has run
    ``last`` holds, failed or ``ended(holds)``; its holds (:func:`stages`). With ``rest_speed``
    a hold goes in parts of a third of its end window, and the run also ends in a hold's second
    half once the mean velocity over the window is below ``rest_speed``: the holds then end with
    that one, shortened (:data:`REST_FACTOR`)."""
    part = hold if rest_speed is None else max(1, int(END_FRACTION * hold) // 3)
    while True:
        series = _series(run.measurements())
        holds = stages(series, run.config)
        if run.failure is not None or len(holds) == last or ended(holds):
            return holds
        done = run.steps_done % hold
        if rest_speed is not None and done >= 2 * END_FRACTION * hold:
            shortened = _stage(series, run.config, len(holds), done)
            if abs(shortened.mean_velocity) <= rest_speed:
                return [*holds, shortened]
        run.advance(min(part, hold - done), progress)
        if run.steps_done % hold == 0 or rest_speed is not None:
            run.save_checkpoint()


def _write_stages(out_dir: pathlib.Path, run: FlowRun, holds: list[Stage], flow_speed: float
                  ) -> None:
    """``out_dir/stages.csv``: the holds of ``run``."""
    write_csv(out_dir / "stages.csv", _stage_rows(
        holds, {"model": run.config.model, "seed": run.config.seed}, flow_speed), STAGE_COLUMNS)


def _series(measurements: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The time series of a run's :meth:`~lubcontact.flow.run.FlowRun.measurements` (or of its
    ``measurements.npz``, read series by series)."""
    return {name[len("series."):]: value for name, value in measurements.items()
            if name.startswith("series.")}


def model_means(results: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Mean and standard deviation over seeds of ``theta_start``, ``theta_stop`` and ``width``.

    Parameters
    ----------
    results : list of dict
        Rows of :func:`hysteresis`.

    Returns
    -------
    dict of str to dict
        Per model: ``<name>`` and ``<name>_sd`` (sample standard deviation,
        NaN for one seed) for each quantity, over the seeds where it is
        defined, and ``seeds`` (rows) and ``<name>_n`` (defined values).
    """
    out: dict[str, dict[str, float]] = {}
    for model in dict.fromkeys(row["model"] for row in results):
        rows = [row for row in results if row["model"] == model]
        entry: dict[str, float] = {"seeds": len(rows)}
        for name in ("theta_start", "theta_stop", "width"):
            entry[name], entry[f"{name}_sd"], entry[f"{name}_n"] = \
                mean_spread([row[name] for row in rows])
        out[model] = entry
    return out
