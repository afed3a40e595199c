"""Command-line entry point: ``lubcontact COMMAND [options]``.

Each command lives in its own module exposing ``main(argv) -> int``; this
file only dispatches, so that importing the CLI stays cheap.
"""
from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "demo": ("lubcontact.demo", "main", "run the built-in demo and write its report under out/"),
    "bench": ("lubcontact.bench.commands", "main", "benchmarks (e.g. 'bench solvers'); prints tables"),
    "run": ("lubcontact.flow.cli", "run_main", "run a scene with checkpoints"),
    "sweep": ("lubcontact.flow.cli", "sweep_main", "inclined-flow sweep over angles"),
    "compare": ("lubcontact.bench.compare", "main", "solver-comparison report"),
    "check-hard": ("lubcontact.bench.hard", "main", "run every solver on the hard-case suite"),
    "verify": ("lubcontact.bench.verify", "main",
               "judge a solution file against a problem file (exit 0 pass, 1 fail)"),
}


def _usage() -> str:
    lines = ["usage: lubcontact COMMAND [options]", "", "commands:"]
    lines += [f"  {name:<11} {help_}" for name, (_, _, help_) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"lubcontact: unknown command {name!r}\n\n{_usage()}", file=sys.stderr)
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
