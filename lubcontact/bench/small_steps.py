"""``lubcontact bench small``: the fixed cost of a solve on small systems (a teaching run).

A teaching run steps a few tens of grains 10^4 times; each step's problem has
1-100 contacts, so what a solve costs is set-up (normalising, scaling, building
``W``, checking, finishing), not iterations. For each size (grains of
:func:`~lubcontact.scenes.small.settling_pile`, seed 1, ``dt`` = 0.02) and law
this benchmark settles the pile with ``apgd-jacobi`` (``--settle`` steps, from
the same start), then, for each method, steps it once untimed (compilation
and imports are never timed) and times ``--steps`` steps as a simulation takes
them (a new problem each step, warm-started from the previous step by pair).

Laws (``--laws``): ``frictionless`` (gluey lubrication, gamma_min = -1: a QP),
``relaxation`` (Coulomb mu = 0.3, the convex relaxation, one solve per step),
``exact`` (Coulomb mu = 0.3, exact friction by the fixed point on s).

Per row: contacts (mean per step), the median microseconds of the solve
(``settings.solve``: normalising, set-up, iterations, finish, the result's
checks), of the method's own solve within it (``method_us``: the result's
``solve_time``; for a method that times its iterations apart from its set-up,
those alone, else the whole call of the method; on a step without contacts the
registry's empty answer) and of the whole step (contacts, assembly, solve,
update), the steps per second of the run, the median iterations per solve and
the statuses.

The field's reference library is one of the methods where it is installed: the
Siconos peer's methods (``siconos-nsgs``, ...; docs/guide/siconos-peer.md) are
registered, and their ``method_us`` is Siconos' own solve, timed in its worker
(``solve_us`` then holds the worker's process and the problem's transfer).

A method that cannot solve a law's problems (the peer's take no gluey contacts),
or that solves exact Coulomb itself on the relaxation (``newton-ac``, the peer's:
they have none), is skipped there, with a line on standard error saying why.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time
from typing import Any

import numpy as np

from ..io.files import save_text
from ..model.laws import Coulomb, GlueyLubrication, Law
from ..problem.step import StepProblem
from ..scenes.small import settling_pile
from ..sim.simulation import Simulation
from ..solvers import SolveSettings, methods, solver_info
from ..solvers.siconos_peer import is_peer_method, register_siconos, siconos_status
from .flow_steps import has_no_relaxation
from .options import check_methods, counts, names, number
from .tables import format_table

LAWS = ("frictionless", "relaxation", "exact")
"""Laws of ``--laws`` (module docstring)."""
DT = 0.02
"""Time step of the settling piles (radius 0.5, g = 1)."""
FRICTION = 0.3
"""Coulomb coefficient of the frictional laws."""
COLUMNS = ("n_grains", "law", "method", "contacts", "solve_us", "method_us", "step_us",
           "steps_per_s", "iterations", "statuses")


def _law(name: str) -> Law:
    return GlueyLubrication(gamma_min=-1.0) if name == "frictionless" else Coulomb(FRICTION)


def settled(n_grains: int, law: str, steps: int, tol: float) -> Simulation:
    """A settling pile of ``n_grains`` after ``steps`` steps of ``apgd-jacobi`` under ``law``."""
    sim = Simulation(settling_pile(n_grains, seed=1), _law(law), DT, solver="apgd-jacobi",
                     tol=tol, fixed_point=law == "exact", tol_fp=1e-6, keep_trajectory=False,
                     on_failure="ignore")
    sim.run(steps)
    return sim


def step_settings(method: str, tol: float, exact: bool) -> SolveSettings:
    """The settings a pile's timed steps are solved with: ``method`` at ``tol``, exact Coulomb
    (fixed point to 1e-6) where ``exact``."""
    return SolveSettings(method=method, tol=tol, exact_coulomb=exact, tol_fp=1e-6)


def time_steps(sim: Simulation, method: str, steps: int, tol: float, exact: bool) -> dict[str, Any]:
    """Time ``steps`` steps of ``sim`` with ``method`` after one untimed step; the state is kept.

    Returns
    -------
    dict
        The row's measured columns (:data:`COLUMNS` but ``n_grains`` and ``law``).
    """
    start = sim.state.copy()              # the steps below move sim.state in place
    settings = step_settings(method, tol, exact)
    sim.step(settings)                      # untimed: compilation, imports, caches
    solves, own, totals, iterations, contacts, statuses = [], [], [], [], [], set()
    for _ in range(steps):
        clock = time.perf_counter()
        report = sim.step(settings)
        totals.append(time.perf_counter() - clock)
        solves.append(report.timings["solve"])
        own.append(report.result.solve_time)
        iterations.append(report.result.iterations)
        contacts.append(report.problem.n_contacts)
        statuses.add(report.result.status)
    sim.restore(start)
    return {"method": method, "contacts": float(np.mean(contacts)),
            "solve_us": 1e6 * float(np.median(solves)), "method_us": 1e6 * float(np.median(own)),
            "step_us": 1e6 * float(np.median(totals)),
            "steps_per_s": steps / sum(totals), "iterations": float(np.median(iterations)),
            "statuses": ",".join(sorted(statuses))}


def skipped(method: str, law: str, problem: StepProblem) -> str | None:
    """Why ``method`` is not timed on ``law`` (``problem``: one of the law's steps), or None: it
    cannot solve the law's problems (the Siconos peer on gluey contacts), or, on the relaxation,
    it solves exact Coulomb itself (:func:`~lubcontact.bench.flow_steps.has_no_relaxation`; its
    row would repeat the exact law's)."""
    if reason := solver_info(method).rejection(problem):
        return reason
    if law == "relaxation" and has_no_relaxation(method, problem):
        return "it solves exact Coulomb itself, it has no relaxation"
    return None


def main(argv: list[str] | None = None) -> int:
    """``lubcontact bench small [--sizes ...] [--laws ...] [--methods ...]``."""
    parser = argparse.ArgumentParser(prog="lubcontact bench small", description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", nargs="+", default=["4", "10", "20", "40"],
                        help="grains per pile, space or comma separated (default: 4 10 20 40)")
    parser.add_argument("--laws", type=names, default=list(LAWS),
                        help=f"comma-separated, of {', '.join(LAWS)} (default: all)")
    parser.add_argument("--methods", type=names, default=["apgd-jacobi", "apgd-as", "nsgs"],
                        help="comma-separated registered methods, the Siconos peer's where installed "
                             "(default: apgd-jacobi,apgd-as,nsgs)")
    parser.add_argument("--steps", type=number(int, 1), default=300,
                        help="timed steps per method (default: 300)")
    parser.add_argument("--settle", type=number(int, 0), default=100,
                        help="steps before the timed ones (default: 100)")
    parser.add_argument("--tol", type=number(float, 0, above=True), default=1e-8,
                        help="solver tolerance (default: 1e-8)")
    parser.add_argument("--json", type=pathlib.Path, help="write the rows to this JSON file")
    args = parser.parse_args(argv)
    if unknown := sorted(set(args.laws) - set(LAWS)):
        parser.error(f"argument --laws: unknown {', '.join(map(repr, unknown))}; known: {', '.join(LAWS)}")
    try:
        args.sizes = counts("--sizes", args.sizes)
    except ValueError as exc:
        parser.error(f"argument {exc}")
    register_siconos()                   # the field's reference library, when installed
    if absent := [name for name in args.methods if is_peer_method(name) and name not in methods()]:
        parser.error(f"argument --methods: {', '.join(map(repr, absent))} need Siconos, which is "
                     f"absent here ({siconos_status().reason})")
    try:
        check_methods("--methods", args.methods)
    except ValueError as exc:
        parser.error(f"argument {exc}")
    rows = []
    for n_grains in args.sizes:
        for law in args.laws:
            sim = settled(n_grains, law, args.settle, args.tol)
            problem = sim.next_problem()[2]
            for method in args.methods:
                if reason := skipped(method, law, problem):
                    print(f"lubcontact bench small: {method} skipped on the {law} law: {reason}",
                          file=sys.stderr)
                    continue
                row = {"n_grains": n_grains, "law": law,
                       **time_steps(sim, method, args.steps, args.tol, law == "exact")}
                rows.append(row)
                print(format_table([row], COLUMNS, floats=".4g"), flush=True)
                if args.json:              # rewritten after each row: a stopped run keeps them
                    save_text(args.json, json.dumps(rows, indent=1))
    print()
    print(format_table(rows, COLUMNS, floats=".4g"))
    return 0
