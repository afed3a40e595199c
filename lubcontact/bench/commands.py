"""``lubcontact bench NAME [options]``: dispatch to a benchmark, each printing a table.

Benchmarks are listed in :data:`BENCHMARKS` and imported lazily:

- ``solvers``: every method on 2D piles at rest (:mod:`lubcontact.bench.piles`);
- ``friction``: exact Coulomb friction on external problems and a pile step
  (:mod:`lubcontact.bench.friction`);
- ``flow``: exact-Coulomb steps of developed inclined flows (:mod:`lubcontact.bench.flow_steps`).
- ``small``: the fixed cost of a solve on small systems (:mod:`lubcontact.bench.small_steps`).
- ``switch``: one change of a solver's setting, timed step by step in one process
  (:mod:`lubcontact.bench.switch`).
"""
from __future__ import annotations

import importlib

BENCHMARKS = {
    "solvers": ("lubcontact.bench.piles", "solvers_main", "every solver on 2D piles at rest"),
    "friction": ("lubcontact.bench.friction", "main", "friction benchmarks"),
    "flow": ("lubcontact.bench.flow_steps", "main", "exact-Coulomb steps of developed inclined flows"),
    "small": ("lubcontact.bench.small_steps", "main", "the fixed cost of a solve on small systems"),
    "switch": ("lubcontact.bench.switch", "main", "one setting changed, timed step by step in one process"),
}
"""Name -> (module, function, one line of help); ``function(argv) -> int``."""


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``bench NAME ...`` to the benchmark's ``main(argv)``; 2 for an unknown name."""
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
    module = importlib.import_module(module_name)
    return int(getattr(module, function)(argv[1:]) or 0)
