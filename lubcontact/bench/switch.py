"""``lubcontact bench switch``: one change of a solver's setting, timed step by step in one process.

A change of a few per cent in a solve is below what two runs of a benchmark can tell apart on a
shared machine, whose speed moves by more than that from one minute to the next. This benchmark
captures steps as a simulation takes them (the problem, its warm start and shift, as
:meth:`~lubcontact.solvers.SolveSettings.solve` receives them), then solves each step with the
module's settings as they are (``A``) and with ``--switch`` applied (``B``), one after the other,
the order swapped from step to step and round to round, and keeps the least time of each over
the rounds. The ratio of each step's two times, and of their sums, is what it reports: a pair
shares the machine's minute.

``--switch MODULE.NAME=VALUE`` (repeatable; all applied together for ``B``): a module constant
of the package, set to a Python literal (``lubcontact.solvers.newton.CHAINED_SUBPROBLEMS=False``,
``lubcontact.solvers.newton.INNER_CAP=6``). Constants read when a solve runs take effect;
constants read once, when their module is imported, do not.

Steps come from ``bench small``'s settling piles (``--small``: grains per pile, the pile settled
by :func:`~lubcontact.bench.small_steps.settled`, then stepped with ``--method``) or from a
developed flow widened as ``bench flow --layer`` widens it (``--layer`` and ``--sizes``, stepped
with ``--method`` at the flow's own tolerance, unless ``--tol``, and friction law). Per set: the
steps, mean contacts, Newton (or first-order) iterations summed over the steps for ``A`` and
``B``, the median microseconds of a solve for each, the median of the per-step ratios ``B / A``,
the ratio of the sums, and the largest difference of the forces (relative to the largest force),
0 where ``B`` takes the same steps to the bit.
"""
from __future__ import annotations

import argparse
import ast
import importlib
import json
import pathlib
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..io.files import save_text
from ..problem.step import StepProblem
from ..sim.simulation import Simulation
from ..solvers import SolveSettings
from ..solvers.result import CoulombResult
from .options import check_methods, counts, names, number
from .tables import format_table

SETTLE_STEPS = 100
"""Steps that settle a pile before its steps are captured (``bench small``'s default)."""
COLUMNS = ("set", "steps", "contacts", "iterations_a", "iterations_b", "us_a", "us_b",
           "median_ratio", "sum_ratio", "force_difference")


@dataclass
class Switch:
    """A module constant and the value ``B`` gives it (:func:`parse_switch`)."""

    module: Any
    name: str
    value: Any

    def swapped(self) -> Any:
        """Set the value, returning the one it replaced."""
        before = getattr(self.module, self.name)
        setattr(self.module, self.name, self.value)
        return before


def parse_switch(text: str) -> Switch:
    """``MODULE.NAME=VALUE`` as a :class:`Switch`.

    Raises
    ------
    ValueError
        Naming ``--switch``: no ``=``, a module that does not import, a name it does not have,
        or a value that is not a Python literal.
    """
    target, sep, literal = text.partition("=")
    module_name, dot, name = target.strip().rpartition(".")
    if not sep or not dot or not name:
        raise ValueError(f"--switch: expected MODULE.NAME=VALUE, got {text!r}")
    try:
        module = importlib.import_module(module_name)
    except ImportError:
        raise ValueError(f"--switch: no module {module_name!r}") from None
    if not hasattr(module, name):
        raise ValueError(f"--switch: module {module_name!r} has no {name!r}")
    try:
        value = ast.literal_eval(literal.strip())
    except (ValueError, SyntaxError):
        raise ValueError(f"--switch: {literal.strip()!r} is not a Python literal") from None
    return Switch(module, name, value)


Step = tuple[StepProblem, np.ndarray | None, np.ndarray | None]
"""A captured step: the problem, its warm start and shift (None without a previous step)."""


def captured_steps(sim: Simulation, settings: SolveSettings, count: int) -> list[Step]:
    """``count`` steps of ``sim`` as it takes them with ``settings``, after one untimed step."""
    sim.step(settings)
    steps = []
    for _ in range(count):
        _, _, problem, forces, shift = sim.next_problem()
        steps.append((problem, forces, shift))
        sim.step(settings)
    return steps


def paired_times(steps: list[Step], settings: SolveSettings, switches: list[Switch],
                 rounds: int) -> dict[str, Any]:
    """Each step solved with the settings as they are (``A``) and with ``switches`` (``B``) in
    turn, the order swapped every step and round; the least time of each over ``rounds``.

    Returns
    -------
    dict
        The columns of :data:`COLUMNS` but ``set``.
    """
    seconds = np.full((2, len(steps)), np.inf)
    iterations = np.zeros((2, len(steps)), dtype=int)
    answers: list[list[np.ndarray | None]] = [[None] * len(steps), [None] * len(steps)]
    for step in steps:                        # untimed: both sides compiled and warm
        for side in (0, 1):
            _solve(step, settings, switches if side else [])
    for round_ in range(rounds):
        for k, step in enumerate(steps):
            for side in ((0, 1) if (k + round_) % 2 == 0 else (1, 0)):
                clock = time.perf_counter()
                result = _solve(step, settings, switches if side else [])
                seconds[side, k] = min(seconds[side, k], time.perf_counter() - clock)
                iterations[side, k], answers[side][k] = result.iterations, result.forces
    largest = max((float(np.abs(forces).max(initial=0.0)) for forces in answers[0]), default=0.0)
    difference = max((float(np.abs(a - b).max(initial=0.0)) for a, b in zip(*answers)), default=0.0)
    return {"steps": len(steps), "contacts": float(np.mean([p.n_contacts for p, _, _ in steps])),
            "iterations_a": int(iterations[0].sum()), "iterations_b": int(iterations[1].sum()),
            "us_a": 1e6 * float(np.median(seconds[0])), "us_b": 1e6 * float(np.median(seconds[1])),
            "median_ratio": float(np.median(seconds[1] / seconds[0])),
            "sum_ratio": float(seconds[1].sum() / seconds[0].sum()),
            "force_difference": difference / largest if largest > 0 else difference}


def _solve(step: Step, settings: SolveSettings, switches: list[Switch]) -> CoulombResult:
    """One solve of ``step`` with ``switches`` set for its duration."""
    problem, forces, shift = step
    before = [switch.swapped() for switch in switches]
    try:
        return settings.solve(problem, forces, shift)
    finally:
        for switch, value in zip(switches, before):
            setattr(switch.module, switch.name, value)


def main(argv: list[str] | None = None) -> int:
    """``lubcontact bench switch --switch MODULE.NAME=VALUE [--small ...] [--layer ... --sizes ...]``."""
    parser = argparse.ArgumentParser(prog="lubcontact bench switch",
                                     description=__doc__.split("\n")[0].split(": ", 1)[1])
    parser.add_argument("--switch", action="append", required=True, metavar="MODULE.NAME=VALUE",
                        help="a module constant and the value B gives it (repeatable)")
    parser.add_argument("--small", type=int, nargs="+", default=[],
                        help="grains of bench small's settling piles to take steps from")
    parser.add_argument("--law", default="exact",
                        help="the piles' law: frictionless, relaxation or exact (default: exact)")
    parser.add_argument("--layer", type=pathlib.Path, action="append", default=[],
                        help="checkpoint.npz of a developed flow, widened to each of --sizes "
                             "(as bench flow --layer; repeatable)")
    parser.add_argument("--sizes", nargs="+", default=[],
                        help="grains of each widened --layer, space or comma separated")
    parser.add_argument("--cache", type=pathlib.Path, default=pathlib.Path("out/bench-flow"),
                        help="folder of the widened flows (default: out/bench-flow)")
    parser.add_argument("--method", default="newton-ac", help="solver (default: newton-ac)")
    parser.add_argument("--tol", type=number(float, 0, above=True), default=None,
                        help="solver tolerance (default: 1e-8 on piles, the flow's own on layers)")
    parser.add_argument("--steps", type=int, default=100,
                        help="steps per set, all kept in memory (default: 100; a 10^4-grain "
                             "flow's step keeps its matrices: take 10-20 there)")
    parser.add_argument("--rounds", type=int, default=6, help="rounds of pairs (default: 6)")
    parser.add_argument("--json", type=pathlib.Path, help="write the rows to this JSON file")
    args = parser.parse_args(argv)
    try:
        switches = [parse_switch(text) for text in args.switch]
        check_methods("--method", names(args.method))
        args.sizes = counts("--sizes", args.sizes) if args.sizes else []
    except ValueError as exc:
        parser.error(f"argument {exc}")
    from .flow_steps import widened_flow
    from .small_steps import LAWS, settled, step_settings

    if args.law not in LAWS:
        parser.error(f"argument --law: unknown {args.law!r}; known: {', '.join(LAWS)}")
    for flag, values in (("--small", args.small), ("--sizes", args.sizes),
                         ("--steps", [args.steps]), ("--rounds", [args.rounds])):
        if values and min(values) < 1:
            parser.error(f"argument {flag}: must be >= 1, got {min(values)}")
    if bool(args.layer) != bool(args.sizes):
        parser.error("argument --sizes: give --layer and --sizes together")
    if not args.small and not args.layer:
        parser.error("argument --small: give --small or --layer (a source of steps)")
    sources = [(f"pile {n} {args.law}", n, None) for n in args.small] \
        + [(f"{layer.parent.name} {n}", n, layer) for layer in args.layer for n in args.sizes]
    rows = []
    for label, n_grains, layer in sources:
        if layer is None:           # a settling pile, stepped as bench small steps it
            tol = 1e-8 if args.tol is None else args.tol
            sim = settled(n_grains, args.law, SETTLE_STEPS, tol)
            settings = step_settings(args.method, tol, args.law == "exact")
        else:                       # a widened flow, with its own settings but --method and --tol
            try:
                sim = widened_flow(layer, n_grains, args.cache)[1]
            except ValueError as exc:
                parser.error(f"argument {exc}")
            own = sim.settings
            settings = SolveSettings(method=args.method, tol=own.tol if args.tol is None else args.tol,
                                     exact_coulomb=own.exact_coulomb, tol_fp=own.tol_fp)
        steps = captured_steps(sim, settings, args.steps)
        rows.append({"set": label, **paired_times(steps, settings, switches, args.rounds)})
        print(format_table(rows[-1:], COLUMNS, floats=".4g"), flush=True)
        if args.json:                  # rewritten after each set: a stopped run keeps them
            save_text(args.json, json.dumps(rows, indent=1))
    print()
    print(format_table(rows, COLUMNS, floats=".4g"))
    return 0

