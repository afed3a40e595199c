"""Benchmarks: ``lubcontact bench NAME [options]``; each prints a table.

Sub-benchmarks are dispatched through :data:`BENCHMARKS` with lazy imports:

- ``solvers``: every registered method on 2D piles at rest (:func:`solvers_main`);
- ``friction``: the friction benchmarks (``lubcontact.bench_friction:main``).

``bench solvers`` builds, for each size N, a polydisperse pile at rest: by
default settled by the dynamics (:func:`lubcontact.packing.settle_pile`,
cached under ``out/cache``; ``--tiles k`` starts it from k settled piles of
N/k grains side by side, cheaper to settle for large N), with ``--pile deposited`` as deposited
(:func:`lubcontact.packing.deposit_pile`: zero velocities, closed contacts,
not in equilibrium),
its step problem with inelastic frictionless contacts (``dry``) and the same
with a fraction of the closed contacts glued (``glued``: FREE cones), and
solves each with every method. Errors are measured against the reference
(``clarabel`` through cvxpy, ``tol = 1e-10``, polished on its active set):

- relative velocity error ``|v - v_ref|_M / |U|_M`` (mass-weighted norms,
  relative to the free velocity, i.e. in units of ``g dt`` for a pile at rest);
- most negative gap after the step, ``min(D + dt u_n)``, in units of the
  mean radius.

It then advances the pile one step with the reference velocities and solves
the next step's problem cold and warm-started from each method's forces
(matched by pair key), to compare iteration counts.

``--condition`` also prints the condition number of the Delassus matrix on
the reference's loaded rows (:func:`active_condition`), which sets how many
iterations the gradient methods need on the pile.
"""
from __future__ import annotations

import argparse
import importlib
import time
from dataclasses import dataclass

import numpy as np
from ..model.assemble import assemble
from ..problem.metrics import active_condition, velocity_error

BENCHMARKS = {
    "solvers": ("lubcontact.bench.piles", "solvers_main", "every solver on 2D piles at rest"),
    "friction": ("lubcontact.bench.friction", "main", "friction benchmarks"),
}

FAST_METHODS = ("pgd", "apgd", "bb", "apgd-jacobi", "apgd-as")
REFERENCE_METHODS = ("clarabel-direct", "osqp", "scs")


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``bench NAME ...`` to the sub-benchmark's ``main(argv)``."""
    argv = list(argv or [])
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: lubcontact bench NAME [options]\n\nbenchmarks:")
        for name, (_, _, help_) in BENCHMARKS.items():
            print(f"  {name:<10} {help_}")
        return 0
    if argv[0] not in BENCHMARKS:
        print(f"lubcontact bench: unknown benchmark {argv[0]!r}; known: {', '.join(BENCHMARKS)}")
        return 2
    module_name, function, _ = BENCHMARKS[argv[0]]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name != module_name:
            raise
        print(f"lubcontact bench: benchmark {argv[0]!r} is not available in this version")
        return 2
    return int(getattr(module, function)(argv[1:]) or 0)


# -- problems ----------------------------------------------------------------------------------
@dataclass
class PileCase:
    """One benchmark problem and what is needed to build the next step."""

    label: str
    n_grains: int
    scene: object
    simulation: object
    problem: object
    glued_keys: np.ndarray


PILES = ("settled", "deposited")


def pile_cases(n_grains: int, glued_fraction: float, dt: float, seed: int,
               pile: str = "settled", tiles: int = 1) -> list[PileCase]:
    """The dry and glued step problems of a pile of ``n_grains`` disks.

    ``pile``: ``"settled"`` (:func:`lubcontact.packing.settle_pile` with
    ``tiles``, cached under ``out/cache``) or ``"deposited"``
    (:func:`lubcontact.packing.deposit_pile`).
    """
    from ..model.contacts import find_contacts
    from ..sim.simulation import Simulation
    from ..model.laws import Inelastic
    from ..scenes.packing import deposit_pile, settle_pile

    if pile not in PILES:
        raise ValueError(f"pile: must be one of {PILES}, got {pile!r}")
    if pile == "settled":
        scene, info = settle_pile(n_grains, seed=seed, tiles=tiles)
        print(f"# settled pile N={n_grains} (tiles {tiles}): {info['steps']} steps, last max speed "
              f"{info['max_speed']:.1e}, at rest: {info['at_rest']}")
    else:
        scene = deposit_pile(n_grains, seed=seed)
    simulation = Simulation(scene, Inelastic(), dt)
    contacts = find_contacts(simulation.scene, simulation.d_max)
    closed = np.flatnonzero(np.abs(contacts.gaps) <= 1e-9 * contacts.smaller_radius)
    rng = np.random.default_rng(seed)
    glued = np.sort(rng.choice(closed, size=int(round(glued_fraction * closed.size)), replace=False))
    cases = []
    for label, keys in (("dry", np.zeros(0, dtype=np.int64)), ("glued", contacts.keys[glued])):
        if label == "glued" and glued_fraction <= 0:
            continue
        problem = assemble(simulation.scene, contacts, _cones(contacts, keys), simulation.dt,
                           rotations=simulation.law.needs_rotation)
        cases.append(PileCase(label, n_grains, scene, simulation, problem, keys))
    return cases


def _cones(contacts, glued_keys: np.ndarray):
    from ..problem.cones import ConeKind, Cones

    kinds = np.where(np.isin(contacts.keys, glued_keys), ConeKind.FREE, ConeKind.NONNEG)
    return Cones.frictionless(kinds, contacts.dim - 1)


def next_step_problem(case: PileCase, velocities: np.ndarray):
    """The step problem after advancing the pile one step with ``velocities``."""
    from ..model.contacts import find_contacts

    scene = case.simulation.scene.copy()
    n, dim = scene.grains.count, scene.grains.dim
    scene.grains.velocities[:] = velocities[: n * dim].reshape(n, dim)
    scene.grains.positions += case.simulation.dt * scene.grains.velocities
    scene.time += case.simulation.dt
    contacts = find_contacts(scene, case.simulation.d_max)
    return assemble(scene, contacts, _cones(contacts, case.glued_keys), case.simulation.dt,
                    rotations=case.simulation.law.needs_rotation)


def matched_forces(previous_keys, previous_forces, problem) -> np.ndarray:
    """Previous normal forces matched to ``problem``'s contacts by pair key (0 if new)."""
    guess = np.zeros(problem.n_rows)
    pos = np.clip(np.searchsorted(previous_keys, problem.keys), 0, previous_keys.size - 1)
    guess[: problem.n_contacts] = np.where(previous_keys[pos] == problem.keys,
                                           previous_forces[pos], 0.0)
    return guess


# -- measurements --------------------------------------------------------------------------------
def timed_solve(problem, method: str, tol: float, max_iter: int | None, warm_start=None):
    from ..solvers import solve

    start = time.perf_counter()
    result = solve(problem, method, tol=tol, max_iter=max_iter, warm_start=warm_start)
    return result, time.perf_counter() - start


def _row(case, method, result, wall, error, gap, radius, note=""):
    return (f"{case.n_grains:>6d} {case.problem.n_contacts:>6d} {case.label:<5} {method:<16} "
            f"{result.setup_time:>8.3f} {result.solve_time:>8.3f} {wall:>8.3f} "
            f"{result.iterations:>6d} {result.status:<9} {error:>9.1e} {gap / radius:>9.1e} {note}")


HEADER = (f"{'N':>6} {'nc':>6} {'pile':<5} {'method':<16} {'setup s':>8} {'solve s':>8} "
          f"{'total s':>8} {'iter':>6} {'status':<9} {'rel v err':>9} {'min gap/r':>9}")


def run_case(case: PileCase, methods, tol: float, reference_tol: float, max_iter, warm: bool,
             out=print, condition: bool = False) -> dict:
    """Solve one case with every method; print rows; return timings for the summary.

    ``condition``: also print :func:`active_condition` of the reference solution.
    """
    problem = case.problem
    radius = float(np.mean(case.scene.grains.radii))
    reference, reference_wall = timed_solve(problem, "clarabel", reference_tol, None)
    reference_gaps = problem.gaps_after(reference.velocities)
    out(_row(case, "clarabel (ref)", reference, reference_wall, 0.0, reference_gaps.min(), radius))
    closed = np.abs(problem.gaps) <= 1e-9 * radius
    opening = closed & (reference_gaps > 1e-9 * radius)
    out(f"# {case.label} N={case.n_grains}: {np.count_nonzero(opening)} of "
        f"{np.count_nonzero(closed)} closed contacts open in the step")
    if condition:
        value, count = active_condition(problem, reference.x)
        out(f"# {case.label} N={case.n_grains}: cond(W_AA) = {value:.2e} on {count} loaded rows")
    totals = {}
    results = {}
    for method in methods:
        method_tol = reference_tol if method in REFERENCE_METHODS else tol
        result, wall = timed_solve(problem, method, method_tol, max_iter)
        error = velocity_error(problem, result.velocities, reference.velocities)
        out(_row(case, method, result, wall, error, problem.gaps_after(result.velocities).min(),
                 radius))
        totals[method] = (wall, error, result.status)
        results[method] = result
    iterations = {}
    if warm:
        following = next_step_problem(case, reference.velocities)
        next_reference, _ = timed_solve(following, "clarabel", reference_tol, None)
        for method in methods:
            if method not in FAST_METHODS:
                continue
            guess = matched_forces(problem.keys, results[method].forces[: problem.n_contacts],
                                   following)
            pair = []
            for label, start in (("cold", None), ("warm", guess)):
                result, wall = timed_solve(following, method, tol, max_iter, warm_start=start)
                error = velocity_error(following, result.velocities, next_reference.velocities)
                out(_row(case, f"{method} {label}", result, wall, error,
                         following.gaps_after(result.velocities).min(), radius, "(next step)"))
                pair.append(result.iterations)
            iterations[method] = tuple(pair)
    return {"totals": totals, "iterations": iterations}


def summarise(case: PileCase, measured: dict, accuracy: float, out=print) -> None:
    """Best fast method against clarabel-direct; warm against cold iterations."""
    totals = measured["totals"]
    if "clarabel-direct" in totals:
        fast = {m: t for m, t in totals.items()
                if m in FAST_METHODS and t[2] == "converged" and t[1] <= accuracy}
        if fast:
            best = min(fast, key=lambda m: fast[m][0])
            ratio = fast[best][0] / totals["clarabel-direct"][0]
            out(f"   N={case.n_grains} {case.label}: best fast method {best} "
                f"{fast[best][0]:.3f} s = {ratio:.3f} x clarabel-direct ({totals['clarabel-direct'][0]:.3f} s)")
        else:
            out(f"   N={case.n_grains} {case.label}: no fast method reached {accuracy:g}")
    for method, (cold, warm) in measured["iterations"].items():
        out(f"   N={case.n_grains} {case.label}: {method} next step warm/cold iterations "
            f"{warm}/{cold} = {warm / max(cold, 1):.2f}")


def solvers_main(argv: list[str] | None = None) -> int:
    """``lubcontact bench solvers``: see the module docstring."""
    from ..solvers import methods as registered

    parser = argparse.ArgumentParser(prog="lubcontact bench solvers", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="100,1000,10000", help="grain counts, comma separated")
    parser.add_argument("--methods", default=",".join(REFERENCE_METHODS + FAST_METHODS),
                        help="methods to compare, comma separated")
    parser.add_argument("--glued-fraction", type=float, default=0.3,
                        help="fraction of closed contacts glued in the 'glued' pile (0: skip it)")
    parser.add_argument("--tol", type=float, default=1e-8, help="tolerance of the fast methods")
    parser.add_argument("--reference-tol", type=float, default=1e-10,
                        help="tolerance of clarabel, clarabel-direct, osqp and scs")
    parser.add_argument("--max-iter", type=int, default=None, help="iteration cap (method default)")
    parser.add_argument("--accuracy", type=float, default=1e-6,
                        help="relative velocity error a fast method must reach in the summary")
    parser.add_argument("--dt", type=float, default=0.01, help="time step (units of sqrt(r/g))")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pile", choices=PILES, default="settled",
                        help="settled by the dynamics (cached in out/cache) or deposited")
    parser.add_argument("--tiles", type=int, default=1,
                        help="settled piles built from this many settled copies side by side "
                             "(packing.settle_pile(tiles=...)); every size must be a multiple")
    parser.add_argument("--no-warm", action="store_true", help="skip the next-step re-solves")
    parser.add_argument("--condition", action="store_true",
                        help="print cond(W_AA) on the reference's loaded rows (active_condition)")
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s]
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(registered()))
    if unknown:
        parser.error(f"--methods: unknown {', '.join(unknown)}; registered: {', '.join(registered())}")
    if any(n < 1 for n in sizes):
        parser.error(f"--sizes: must be positive, got {args.sizes}")
    if args.tiles < 1 or any(n % args.tiles for n in sizes):
        parser.error(f"--tiles: must be >= 1 and divide every size, got {args.tiles}")
    print(HEADER)
    summaries = []
    for n in sizes:
        cases = pile_cases(n, args.glued_fraction, args.dt, args.seed, args.pile, args.tiles)
        if n == sizes[0]:            # untimed: load the compiled kernels before any timing
            timed_solve(cases[0].problem, "apgd-jacobi", 1e-3, None)
        for case in cases:
            measured = run_case(case, methods, args.tol, args.reference_tol, args.max_iter,
                                not args.no_warm, condition=args.condition)
            summaries.append((case, measured))
    print("\nsummary")
    for case, measured in summaries:
        summarise(case, measured, args.accuracy)
    return 0
