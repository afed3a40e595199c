"""Readers and writers: external problem files (FCLIB HDF5, Siconos ``.dat``) and atomic writes.

- :func:`read_problem` reads any problem file in local form; :func:`read_global`
  a global one as a :class:`~lubcontact.problem.global_form.GlobalProblem`;
- :func:`write_siconos` and :func:`write_fclib` (or :func:`write_fclib_local`,
  :func:`write_fclib_global`) write them back;
- :func:`local_from_step` and :func:`global_from_step` turn a step problem into
  those forms; :func:`delassus_diagnostics` measures how far a ``W`` is from
  symmetric positive semi-definite.
"""
from ..problem.global_form import (
                                   GlobalProblem,
                                   delassus_diagnostics,
                                   global_from_step,
                                   global_to_local,
                                   local_from_step,
                                   step_forces_to_local,
)
from .fclib import (
                                   read_fclib,
                                   read_fclib_global,
                                   read_fclib_metadata,
                                   read_fclib_solution,
                                   write_fclib,
                                   write_fclib_global,
                                   write_fclib_local,
)
from .files import save_npz
from .readers import read_global, read_problem
from .siconos import read_siconos, read_siconos_global, write_siconos

__all__ = ["GlobalProblem", "delassus_diagnostics", "global_from_step", "global_to_local",
           "local_from_step", "read_fclib", "read_fclib_global", "read_fclib_metadata",
           "read_fclib_solution", "read_global", "read_problem", "read_siconos",
           "read_siconos_global", "save_npz", "step_forces_to_local", "write_fclib",
           "write_fclib_global", "write_fclib_local", "write_siconos"]
