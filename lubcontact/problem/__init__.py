"""The solver-facing layer: step problems without geometry.

A problem is a plain record: force sets (:class:`Cones`), the Delassus
operator ``W`` and the offset ``b``. :class:`StepProblem` comes from a time
step of a scene, :class:`LocalProblem` from an external file (FCLIB,
Siconos); both satisfy the :class:`ConicProblem` protocol that every solver
accepts.
"""
from .cones import ConeKind, Cones
from .conic import ConicProblem, Scaling
from .local import LocalProblem
from .step import StepProblem

__all__ = ["ConeKind", "Cones", "ConicProblem", "LocalProblem", "Scaling", "StepProblem"]
