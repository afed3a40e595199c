"""Command-line entry point: ``lubcontact COMMAND [options]``.

Each command lives in its own module exposing ``main(argv) -> int``; this
file only dispatches, so that importing the CLI stays cheap.
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from pathlib import Path

COMMANDS = {
    "demo": ("lubcontact.demo", "main", "run the built-in demo and write its report under out/"),
    "bench": ("lubcontact.bench.commands", "main", "benchmarks (e.g. 'bench solvers'); prints tables"),
    "run": ("lubcontact.flow.cli", "run_main", "run a scene with checkpoints"),
    "sweep": ("lubcontact.flow.cli", "sweep_main", "inclined-flow sweep over angles"),
    "hysteresis": ("lubcontact.flow.cli", "hysteresis_main",
                   "theta_start / theta_stop: angle ramps up and down"),
    "window": ("lubcontact.flow.cli", "window_main",
               "a run's series over a window of steps: mean, block error, trend"),
    "compare": ("lubcontact.bench.compare", "main", "solver-comparison report"),
    "check-hard": ("lubcontact.bench.hard", "main", "run every solver on the hard-case suite"),
    "verify": ("lubcontact.bench.verify", "main",
               "judge a solution file against a problem file (exit 0 pass, 1 fail)"),
}


BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""The environment variables of the BLAS libraries' thread counts. Where none of them is set, a
command sets them all to one thread (:func:`main`, before numpy is imported): a dense product
split over threads sums in another order, and over the demo's 150-step flow that rounding
changed the flow rate by 3 % and the steady/transient verdict. One thread makes a command's
results independent of the machine's core count (another CPU or BLAS build may still round
differently), and its benchmarks time one core, as the records do (the solvers' loops are
compiled or sparse, on one thread either way). Any of them set: the environment decides."""

SOLVER_ENTRY_POINTS = "lubcontact.solvers"
"""Entry-point group of installed packages that register solvers (loaded by every command)."""


def _usage() -> str:
    lines = ["usage: lubcontact [--version] [--solver-module MODULE ...] COMMAND [options]", "",
             "commands:"]
    lines += [f"  {name:<11} {help_}" for name, (_, _, help_) in COMMANDS.items()]
    lines += ["", "--solver-module MODULE  import MODULE (a dotted name or a .py file) before the "
                  "command,", "                        so that the solvers it registers run in "
                  "compare, check-hard, verify, ...",
              "Installed packages can also register solvers through the entry-point group "
              f"{SOLVER_ENTRY_POINTS!r}."]
    return "\n".join(lines)


def load_solver_module(name: str) -> None:
    """Import a module that registers solvers: a dotted module name or a path to a ``.py`` file.

    Raises
    ------
    ValueError
        Naming ``--solver-module`` when the module cannot be found.
    """
    if name.endswith(".py"):
        path = Path(name)
        if not path.is_file():
            raise ValueError(f"--solver-module: no file {name}")
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[path.stem] = module
        spec.loader.exec_module(module)
        return
    try:
        importlib.import_module(name)
    except ModuleNotFoundError as exc:
        raise ValueError(f"--solver-module: cannot import {name!r} ({exc})") from None


def _load_entry_points() -> None:
    """Import every installed package's solver entry point (group :data:`SOLVER_ENTRY_POINTS`)."""
    from importlib.metadata import entry_points

    for entry in entry_points(group=SOLVER_ENTRY_POINTS):
        entry.load()


def _solver_modules(argv: list[str]) -> tuple[list[str], list[str]]:
    """Split ``--solver-module X`` pairs (given before the command) from the other arguments."""
    modules = []
    while argv and (argv[0] == "--solver-module" or argv[0].startswith("--solver-module=")):
        if "=" in argv[0]:
            modules.append(argv[0].split("=", 1)[1])
            argv = argv[1:]
        elif len(argv) < 2:
            raise ValueError("--solver-module: expects a module name or a .py file")
        else:
            modules.append(argv[1])
            argv = argv[2:]
    return modules, argv


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``lubcontact COMMAND ...``; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not any(variable in os.environ for variable in BLAS_THREADS):   # before numpy loads
        os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))
    if argv[:1] == ["--version"]:
        from . import __version__

        print(f"lubcontact {__version__}")
        return 0
    try:
        modules, argv = _solver_modules(argv)
    except ValueError as exc:
        print(f"lubcontact: {exc}", file=sys.stderr)
        return 2
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"lubcontact: unknown command {name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    try:
        _load_entry_points()
        for module in modules:
            load_solver_module(module)
    except ValueError as exc:
        print(f"lubcontact: {exc}", file=sys.stderr)
        return 2
    module_name, function, _ = COMMANDS[name]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name != module_name:
            raise
        print(f"lubcontact: command {name!r} is not available in this version", file=sys.stderr)
        return 2
    return int(getattr(module, function)(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
