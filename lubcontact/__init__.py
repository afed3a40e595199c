"""lubcontact: rigid grains in a viscous fluid with the gluey contact model."""
from .problem.cones import ConeKind, Cones
from .model.contacts import Contacts, find_contacts
from .sim.simulation import Simulation, Trajectory
from .model.laws import GlueyLubrication, Inelastic, Law
from .problem.step import StepProblem
from .model.scene import Grains, Planes, Scene, Schedule
from .solvers import SolveResult, SolverError, methods, solve

__version__ = "0.1.0"
__all__ = ["ConeKind", "Cones", "Contacts", "find_contacts", "Simulation", "Trajectory",
           "GlueyLubrication", "Inelastic", "Law", "StepProblem", "Grains", "Planes", "Scene",
           "Schedule", "SolveResult", "SolverError", "methods", "solve"]
