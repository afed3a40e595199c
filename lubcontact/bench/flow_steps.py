"""``lubcontact bench flow``: the solves of a developed inclined flow, per size, model and method.

A pile at rest is the easy case; a flow changes its active set, its push/pull
branches and its stick/slip states every step. For each size and model this
benchmark settles a bed (frictionless, ``apgd-jacobi``), tilts it by the
angle, lets the flow develop (:data:`DEVELOP_SOLVER`, exact Coulomb), and caches that state in
``CACHE/flow-<n>-<model>-<angle>-<settle>-<develop>-<solver>.npz`` (built once: a second call
reads it).
With ``--layer`` (a checkpoint of ``lubcontact run``, e.g. a steady flow of
the poster's preset) each size is that developed layer widened instead
(:func:`~lubcontact.scenes.inclined.widen`: copies side by side, no onset to
wait for), its velocities jittered by
:data:`~lubcontact.scenes.inclined.PARTING_JITTER` of their rms (seed 0) so
that the copies part, and run :data:`MIX_STEPS` steps with the layer run's
solver; cached as ``CACHE/widened-<layer digest>-<copies>x.npz``. Every size
must then be a multiple of the layer's grains.

Then, for each method and friction (``--friction``: ``exact``, Coulomb's law
with ``SolveSettings(exact_coulomb=True)``; ``relaxation``, the convex
relaxation, one solve), it restores the state, solves one untimed step (numba
compilation and imports are never timed) and times ``--steps`` steps, each
warm-started from the previous one as in a simulation. Per method it prints
the contacts, the median time per step, iterations per step, the largest
FCLIB error over the steps (the accuracy measure of a frictional step, whose
velocities are not unique; of the relaxation's steps too, which solve another
law) and the statuses. ``--figure`` draws the time per step against the
number of grains on log-log axes with the fitted exponents
(:func:`~lubcontact.bench.figures.scaling_figure`); ``--json`` keeps the rows.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import resource
import time
from typing import Any

import numpy as np

from ..flow.run import FlowRun
from ..io.files import save_npz, save_text
from ..model.scene import Scene
from ..problem.metrics import scaled_coulomb_error, velocity_error
from ..problem.step import StepProblem
from ..scenes import inclined
from ..sim.simulation import Simulation
from ..sim.state import SimulationState
from ..sim.trajectory import StepReport
from ..solvers import SolveSettings
from ..solvers.coulomb import has_joint_phase
from .harness import reference_distrust, solve_reference, warm_up
from .options import check_methods, counts, names, number
from .statistics import scaling_exponents
from .tables import format_table

COLUMNS = ("n_grains", "model", "friction", "method", "contacts", "s_per_step", "iterations",
           "joint_iterations", "per_product", "warm_cold",
           "max_fclib_error", "v_err", "ref_s", "contacts_pc", "assembly_pc", "setup_pc", "iterations_pc",
           "finish_pc", "update_pc", "peak_mb", "statuses", "ref_statuses")
"""``contacts``: mean per step; ``s_per_step``: median time of the whole step (contacts,
assembly, the exact-Coulomb solve, update); ``iterations``: median per step (Newton iterations
for ``newton-ac``, sweeps for ``nsgs``, inner first-order iterations for the others; the joint
phase's APGD iterations included); ``joint_iterations``: with ``--joint``, the median of those
of the joint phase (``newton-ac``'s Newton iterations are the difference);
``per_product``: the solve's time per iteration (set-up included; median over the steps) over
one scipy product ``W x`` on the last step's normalised ``W``;
``warm_cold``: iterations of the first timed step warm-started from the previous step (pair
keys) over those of the same step started cold (1 where the first-order methods set aside a
warm start worse than zero: :func:`lubcontact.solvers.dual_data.initial_point`; not measured
with ``--no-cold``); ``v_err``: with ``--reference K``, the largest relative velocity error
(:func:`~lubcontact.problem.metrics.velocity_error`) of every K-th timed step against the
reference's solve of the same problem (:func:`reference_settings`), ``ref_s`` the median time of
those reference solves and ``ref_statuses`` their statuses (a reference not trusted,
:func:`~lubcontact.bench.harness.reference_distrust`, is also said on its own line); ``*_pc``:
percentage of the steps' total time in each phase (:func:`step_phases`); ``peak_mb``: the process's peak
resident memory so far (MB; with ``--reference``, the reference's included, and the steps after
a reference solve are slower for its use of the caches: compare times of runs without it). A
column that no row has is not printed (:func:`shown_columns`)."""


def shown_columns(rows: list[dict[str, Any]]) -> list[str]:
    """The columns of :data:`COLUMNS` that some row of ``rows`` has (``joint_iterations``,
    ``warm_cold`` and the reference's are measured only on request)."""
    return [column for column in COLUMNS if any(column in row for row in rows)]


PHASES = ("contacts", "assembly", "setup", "iterations", "finish", "update")
"""The phases of a step (:func:`step_phases`)."""


def step_phases(report: StepReport) -> dict[str, float]:
    """Seconds of each of :data:`PHASES` in a step: ``contacts``, ``assembly`` and ``update`` as
    :attr:`~lubcontact.sim.trajectory.StepReport.timings` has them, and the solve split into
    the method's ``setup`` and ``iterations`` (the result's ``setup_time`` and ``solve_time``,
    summed over a fixed point's inner solves; with its joint phase, which builds the matrices the
    inner solves then share, in ``iterations``) and the rest, ``finish`` (the result's checks,
    the fixed point's own work, and a first solve that a fallback replaced). Not clipped: a
    negative ``finish`` would be time counted twice."""
    timings, result = report.timings, report.result
    return {"contacts": timings["contacts"], "assembly": timings["assembly"],
            "setup": result.setup_time, "iterations": result.solve_time,
            "finish": timings["solve"] - result.setup_time - result.solve_time,
            "update": timings["update"]}


DEVELOP_SOLVER = "newton-ac"
"""Solver of the flow steps before the timed ones (exact Coulomb): on a dense 1000-grain bed,
apgd-jacobi's fixed point spent 20 000 to 370 000 iterations on each of them."""

MIX_STEPS = 50
"""Steps run after widening a layer, before any timed step."""
FRICTIONS = ("exact", "relaxation")
"""``exact``: Coulomb's law (``SolveSettings(exact_coulomb=True)``); ``relaxation``: its convex
relaxation, one solve (not by a method that solves exact Coulomb itself: it has no
relaxation)."""
REFERENCE_TOL = 1e-9
"""Tolerance of the reference solves (``--reference``): the inner solves and the fixed point on s."""


def reference_settings(method: str, friction: str) -> SolveSettings:
    """Settings of a reference solve (``method``, the registry's reference) of a step of
    ``friction``: :data:`REFERENCE_TOL`, and for ``exact`` the fixed point on s."""
    return SolveSettings(method=method, tol=REFERENCE_TOL, tol_fp=REFERENCE_TOL,
                         exact_coulomb=friction == "exact")


def developed_flow(n_grains: int, model: str, angle: float, cache: pathlib.Path, *, seed: int = 1,
                   settle_steps: int = 1500, develop_steps: int = 100) -> Simulation:
    """A simulation of a developed inclined flow (dimensionless preset, ``dt = 0.01 sqrt(d/g')``).

    The grains fall from their release heights for ``settle_steps`` steps
    (the default settles 10^3-3x10^3 grains into a bed with about two contacts
    per grain), then flow down the incline for ``develop_steps``. Built once
    and cached in ``cache`` (the settled bed, one per size for both models, and the
    state after the flow steps).
    """
    params = inclined.dimensionless_parameters()
    dt = inclined.time_step(params)
    law = params.law(model)
    path = pathlib.Path(cache) / (f"flow-{n_grains}-{model}-{angle:g}-{settle_steps}-{develop_steps}"
                                  f"-{DEVELOP_SOLVER}.npz")
    if path.exists():
        with np.load(path) as data:
            state = SimulationState.from_arrays(data)
        sim = Simulation(state.scene, law, dt, solver=DEVELOP_SOLVER, tol=1e-6, on_failure="warn")
        sim.restore(state)
        return sim
    bed_path = pathlib.Path(cache) / f"bed-{n_grains}-{settle_steps}.npz"
    if bed_path.exists():
        with np.load(bed_path) as data:
            bed = SimulationState.from_arrays(data)
    else:
        settling = Simulation(inclined.sedimentation(n_grains, params, seed=seed),
                              params.law("frictionless"), dt, solver="apgd-jacobi", tol=1e-6,
                              fixed_point=False, on_failure="warn")
        settling.run(settle_steps)
        bed = settling.state
        bed_path.parent.mkdir(parents=True, exist_ok=True)
        save_npz(bed_path, **bed.to_arrays())
    sim = Simulation(inclined.inclined_flow(bed.scene, angle), law, dt, solver=DEVELOP_SOLVER,
                     tol=1e-6, on_failure="warn")
    sim.run(develop_steps)
    save_npz(path, **sim.state.to_arrays())
    return sim


def widened_flow(layer: pathlib.Path, n_grains: int, cache: pathlib.Path) -> tuple[str, Simulation]:
    """The developed layer of a ``lubcontact run`` checkpoint, widened to ``n_grains`` grains.

    Returns
    -------
    (str, Simulation)
        The layer run's model, and a simulation of the widened layer after
        :data:`MIX_STEPS` steps (jitter :data:`~lubcontact.scenes.inclined.PARTING_JITTER`,
        seed 0), with the layer run's law, time step, search distance and solver settings;
        cached in ``cache``.

    Raises
    ------
    ValueError
        Naming ``--sizes`` when ``n_grains`` is not a multiple of the layer's grains.
    """
    base = FlowRun.resume(pathlib.Path(layer))
    grains = base.sim.scene.grains.count
    if n_grains % grains:
        raise ValueError(f"--sizes: {n_grains} is not a multiple of the layer's {grains} grains")
    copies = n_grains // grains
    digest = hashlib.sha1(pathlib.Path(layer).read_bytes()).hexdigest()[:10]
    path = pathlib.Path(cache) / f"widened-{digest}-{copies}x.npz"
    model = base.config.model

    def simulation(scene: Scene) -> Simulation:
        return Simulation(scene, base.sim.law, base.sim.dt, solver=base.sim.settings.method,
                          tol=base.sim.settings.tol, fixed_point=base.sim.settings.exact_coulomb,
                          d_max=base.sim.d_max, on_failure="warn", keep_trajectory=False)

    if path.exists():
        with np.load(path) as data:
            state = SimulationState.from_arrays(data)
        sim = simulation(state.scene)
        sim.restore(state)
        return model, sim
    scene = inclined.widen(base.sim.scene, copies, jitter=inclined.PARTING_JITTER, seed=0)
    sim = simulation(scene)
    sim.run(MIX_STEPS)
    save_npz(path, **sim.state.to_arrays())
    return model, sim


def product_time(problem: StepProblem, repeats: int = 20) -> float:
    """Seconds of one scipy product ``W x`` with the problem's normalised ``W`` (the best of
    ``repeats``, after one untimed)."""
    matrix = problem.normalized().delassus
    vector = np.ones(matrix.shape[0])
    matrix @ vector
    best = np.inf
    for _ in range(repeats):
        clock = time.perf_counter()
        matrix @ vector
        best = min(best, time.perf_counter() - clock)
    return best


def time_method(sim: Simulation, method: str, steps: int, tol: float,
                friction: str = "exact", joint: int = 0, cold: bool = True,
                reference: int = 0) -> dict[str, Any]:
    """Solve ``steps`` steps of ``sim`` from its current state with ``method`` (``friction``:
    one of :data:`FRICTIONS`; ``joint`` > 0: exact Coulomb starting with the fixed point's joint
    phase, ``joint`` of :func:`~lubcontact.solvers.coulomb.solve_coulomb`, for the methods it
    applies to (:func:`~lubcontact.solvers.coulomb.has_joint_phase`), labelled
    ``method+jointN``; ``cold``: solve the first timed step from zero forces as well, for
    ``warm_cold``; ``reference`` > 0: every ``reference``-th timed step, the first included, also
    solved untimed by the reference, for ``v_err``); the state is kept. The caller skips the
    relaxation by a method that solves exact Coulomb itself (:func:`has_no_relaxation`).
    """
    start = sim.state.copy()              # the steps below move sim.state in place
    exact = friction == "exact"
    joint = joint if exact and has_joint_phase(method) else 0
    settings = SolveSettings(method=method, tol=tol, exact_coulomb=exact,
                             options={"joint": joint} if joint else {})
    sim.step(settings)                       # untimed: compilation, caches
    ratio = {}
    if cold:
        _, _, problem, guess, shift = sim.next_problem()
        from_zero = settings.solve(problem).iterations
        warm = settings.solve(problem, guess, shift).iterations
        ratio["warm_cold"] = warm / max(from_zero, 1)
    times, iterations, errors, contacts, statuses = [], [], [], [], set()
    per_iteration, checked, joint_iterations = [], [], []
    phases = dict.fromkeys(PHASES, 0.0)
    for k in range(steps):
        clock = time.perf_counter()
        report = sim.step(settings)
        times.append(time.perf_counter() - clock)
        if reference and k % reference == 0:
            checked.append(check_step(report, friction, k))
        iterations.append(report.result.iterations)
        joint_iterations.append(report.result.joint_iterations)
        per_iteration.append(report.timings["solve"] / max(report.result.iterations, 1))
        contacts.append(report.problem.n_contacts)
        statuses.add(report.result.status)
        errors.append(scaled_coulomb_error(report.problem, report.result.forces))
        for phase, seconds in step_phases(report).items():
            phases[phase] += seconds
    sim.restore(start)
    total = sum(times)
    if checked:
        errors_v, seconds, ref_statuses = zip(*checked)
        ratio.update(ref_s=float(np.median(seconds)), ref_statuses=",".join(sorted(set(ref_statuses))))
        trusted = [error for error in errors_v if error is not None]
        if trusted:
            ratio["v_err"] = float(max(trusted))
    return {"friction": friction, "method": f"{method}+joint{joint}" if joint else method,
            "contacts": int(np.mean(contacts)),
            "s_per_step": float(np.median(times)),
            "iterations": float(np.median(iterations)), **ratio,
            **({"joint_iterations": float(np.median(joint_iterations))} if joint else {}),
            "per_product": float(np.median(per_iteration)) / product_time(report.problem),
            "max_fclib_error": float(max(errors)),
            **{f"{phase}_pc": 100.0 * phases[phase] / total for phase in PHASES},
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "statuses": ",".join(sorted(statuses))}


def has_no_relaxation(method: str, problem: StepProblem) -> bool:
    """Whether ``method`` solves ``problem``'s relaxation as exact Coulomb all the same
    (:meth:`~lubcontact.solvers.SolveSettings.solves_exact_coulomb` with ``exact_coulomb``
    off: a native Coulomb method on a frictional problem)."""
    return SolveSettings(method=method, exact_coulomb=False).solves_exact_coulomb(problem)


def check_step(report: StepReport, friction: str, step: int) -> tuple[float | None, float, str]:
    """The velocity error of a solved step against the reference's solve of its problem.

    The reference starts from the step's forces: they choose the first piece of each UNION
    contact for its branch rule (a union of cones has a solution per consistent choice of
    pieces). For ``exact`` its fixed point on s starts from the step's shift and must still
    converge to :data:`REFERENCE_TOL` from there (from a zero shift it ended ``max_iter``, 50
    outer iterations, on dry 12 000-grain flows). Clarabel's relaxation of gluey steps still
    ends ``inaccurate`` from the forces of ``apgd-jacobi`` (docs/records/benchmarks.md).

    Parameters
    ----------
    report : StepReport
        The solved step.
    friction : str
        One of :data:`FRICTIONS`: the law the step was solved with.
    step : int
        The step's index among the timed ones (from 0), for the messages.

    Returns
    -------
    (float or None, float, str)
        :func:`~lubcontact.problem.metrics.velocity_error` against a trusted reference (None
        when the reference raised or is not trusted,
        :func:`~lubcontact.bench.harness.reference_distrust`, which is then said on its own
        line), the reference's seconds, and its status (``raised``, ``not trusted`` or the
        result's status).
    """
    _, timed = solve_reference(report.problem, lambda name: reference_settings(name, friction),
                               warm_start=report.result.forces, shift=report.result.shift)
    if timed.result is None:
        print(f"# reference failed on timed step {step}: {timed.message}", flush=True)
        return None, timed.seconds, "raised"
    distrust = reference_distrust(timed.result)
    if distrust:
        print(f"# reference NOT trusted on timed step {step}: {distrust}", flush=True)
        return None, timed.seconds, "not trusted"
    error = velocity_error(report.problem, report.result.velocities, timed.result.velocities)
    return error, timed.seconds, timed.result.status


def main(argv: list[str] | None = None) -> int:
    """``lubcontact bench flow [--sizes ...] [--models ...] [--methods ...]``."""
    parser = argparse.ArgumentParser(prog="lubcontact bench flow",
                                     description="Exact-Coulomb step solves of developed inclined "
                                                 "flows, per size, model and method.")
    parser.add_argument("--sizes", nargs="+", default=["1000"],
                        help="numbers of grains, space or comma separated (default: 1000)")
    parser.add_argument("--models", type=names, default=["dry", "gluey"],
                        help="comma list of dry, gluey (default: dry,gluey)")
    parser.add_argument("--methods", type=names, default=["apgd-jacobi", "newton-ac"],
                        help="comma list of registered methods (default: apgd-jacobi,newton-ac)")
    parser.add_argument("--angle", type=float, default=25.0, help="incline angle, degrees (default: 25)")
    parser.add_argument("--steps", type=int, default=10, help="timed steps per method (default: 10)")
    parser.add_argument("--tol", type=number(float, 0, above=True), default=1e-6,
                        help="solver tolerance (default: 1e-6)")
    parser.add_argument("--settle-steps", type=int, default=1500,
                        help="steps that settle the bed before it is tilted (default: 1500)")
    parser.add_argument("--cache", type=pathlib.Path, default=pathlib.Path("out/bench-flow"),
                        help="folder of the developed flows (default: out/bench-flow)")
    parser.add_argument("--layer", type=pathlib.Path, action="append", default=[],
                        help="checkpoint.npz of a developed flow (lubcontact run), widened to each "
                             "size instead of settling and developing one; repeat for each model "
                             "(--models, --angle and --settle-steps are then not used)")
    parser.add_argument("--friction", type=names, default=["exact"],
                        help="comma list of exact (Coulomb's law), relaxation (its convex "
                             "relaxation; skipped for methods that solve exact Coulomb "
                             "themselves) (default: exact)")
    parser.add_argument("--joint", type=int, default=0,
                        help="exact friction starting with the fixed point's joint phase (the "
                             "first-order methods and newton-ac, which runs it on steps without "
                             "UNION contacts: first above 700 rows, after stalled "
                             "strategies up to 700), shift updated every JOINT iterations inside "
                             "one APGD run (0: none; default 0)")
    parser.add_argument("--no-cold", dest="cold", action="store_false",
                        help="do not solve a step from zero forces (no warm_cold column): "
                             "newton-ac's solve from zero on a 10^5-grain pile at rest "
                             "took 8 minutes")
    parser.add_argument("--reference", type=int, default=0,
                        help="every REFERENCE-th timed step (the first included) also solved, "
                             f"untimed, by the Clarabel reference at tol {REFERENCE_TOL:g}, for "
                             "the v_err column (0: none; default 0); peak_mb then includes it, "
                             "and the times are not those of a run without it")
    parser.add_argument("--json", type=pathlib.Path, help="write the rows to this JSON file")
    parser.add_argument("--figure", type=pathlib.Path,
                        help="draw s/step against grains (log-log, fitted exponents) to this PNG")
    args = parser.parse_args(argv)
    try:
        check_methods("--methods", args.methods)
        args.sizes = counts("--sizes", args.sizes)
    except ValueError as exc:
        parser.error(f"argument {exc}")
    for flag, value in (("--steps", args.steps), ("--settle-steps", args.settle_steps)):
        if value < 1:
            parser.error(f"argument {flag}: must be >= 1, got {value}")
    for flag, value in (("--joint", args.joint), ("--reference", args.reference)):
        if value < 0:
            parser.error(f"argument {flag}: must be >= 0, got {value}")
    for model in args.models:
        if model not in ("dry", "gluey"):
            parser.error(f"argument --models: unknown model {model!r}; choose from dry, gluey")
    for friction in args.friction:
        if friction not in FRICTIONS:
            parser.error(f"argument --friction: unknown {friction!r}; choose from {', '.join(FRICTIONS)}")
    for layer in args.layer:
        if not layer.is_file():
            parser.error(f"argument --layer: no such file {str(layer)!r}")
    rows = []
    for n_grains in args.sizes:
        for source in args.layer or args.models:
            if args.layer:
                try:
                    model, sim = widened_flow(source, n_grains, args.cache)
                except ValueError as exc:
                    parser.error(f"argument {exc}")
            else:
                model, sim = source, developed_flow(n_grains, source, args.angle, args.cache,
                                                    settle_steps=args.settle_steps)
            probe = sim.next_problem()[2]
            warm_up(probe, args.methods)
            for friction in args.friction:
                for method in args.methods:
                    if friction == "relaxation" and has_no_relaxation(method, probe):
                        print(f"# relaxation skipped: {method} solves exact Coulomb itself, it has "
                              "no relaxation", flush=True)
                        continue
                    row = {"n_grains": n_grains, "model": model,
                           **time_method(sim, method, args.steps, args.tol, friction,
                                         args.joint, args.cold, args.reference)}
                    rows.append(row)
                    print(format_table([row], shown_columns([row])), flush=True)
                    if args.json:             # rewritten after each row: a stopped run keeps them
                        save_text(args.json, json.dumps(rows, indent=1))
    print()
    print(format_table(rows, shown_columns(rows)))
    for (model, friction, method), exponent in scaling_exponents(rows).items():
        print(f"# {model} {friction} {method}: s/step ~ N^{exponent:.2f}")
    if args.figure:
        from .figures import scaling_figure

        scaling_figure(rows, args.figure)
    return 0
