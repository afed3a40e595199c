"""lubcontact: rigid grains in a viscous fluid with the gluey contact model.

The public face: scenes and laws (``model``), the step problems
(``problem``), the solver registry and results (``solvers``) and the time
stepper (``sim``). The tooling (``lubcontact.bench``, ``lubcontact.flow``) is
imported on demand by the command line, never by this core.
"""
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

__version__ = "0.1.0"
__all__ = ["scenes", "Contacts", "Coulomb", "GlueyCoulomb", "GlueyLubrication", "Grains",
           "Inelastic", "Law", "Planes", "Scene", "Schedule", "find_contacts", "ConeKind", "Cones",
           "ConicProblem", "LocalProblem", "StepProblem", "Simulation", "SimulationState",
           "StepReport", "Trajectory", "CoulombResult", "MethodOutput", "SolveResult", "SolverError",
           "SolverWarning", "SolveSettings", "methods", "register", "solve", "solve_coulomb",
           "solver_info"]
