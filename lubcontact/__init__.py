"""lubcontact: rigid grains in a viscous fluid with the gluey contact model.

The public face: scenes and laws (``model``), the step problems
(``problem``), the solver registry and results (``solvers``) and the time
stepper (``sim``). The tooling (``lubcontact.bench``, ``lubcontact.flow``) is
imported on demand by the command line, never by this core.

Names are loaded on first use (``lubcontact.Simulation`` imports the time
stepper then), so that ``lubcontact --help`` and the light commands start
without importing cvxpy and numba.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

_EXPORTS = {
    "lubcontact.model": ("Contacts", "Coulomb", "GlueyCoulomb", "GlueyLubrication", "Grains",
        "Inelastic", "Law", "Planes", "Scene", "Schedule", "find_contacts"),
    "lubcontact.problem": ("ConeKind", "Cones", "ConicProblem", "LocalProblem", "StepProblem"),
    "lubcontact.sim": ("Simulation", "SimulationState", "StepReport", "Trajectory"),
    "lubcontact.solvers": ("CoulombResult", "MethodOutput", "SolveResult", "SolverError",
        "SolverWarning", "SolveSettings", "methods", "register", "solve",
        "solve_coulomb", "solver_info"),
}
_HOME = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = ["scenes", *_HOME]


def __getattr__(name: str) -> object:
    """Load a public name (or the ``scenes`` subpackage) on first use."""
    if name == "scenes":
        return importlib.import_module("lubcontact.scenes")
    if name in _HOME:
        value = getattr(importlib.import_module(_HOME[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'lubcontact' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:                       # the same names, for type checkers and editors
    from . import scenes
    from .model import (
        Contacts,
        Coulomb,
        GlueyCoulomb,
        GlueyLubrication,
        Grains,
        Inelastic,
        Law,
        Planes,
        Scene,
        Schedule,
        find_contacts,
    )
    from .problem import ConeKind, Cones, ConicProblem, LocalProblem, StepProblem
    from .sim import Simulation, SimulationState, StepReport, Trajectory
    from .solvers import (
        CoulombResult,
        MethodOutput,
        SolverError,
        SolveResult,
        SolverWarning,
        SolveSettings,
        methods,
        register,
        solve,
        solve_coulomb,
        solver_info,
    )
