"""Readers and writers: external problem files (FCLIB HDF5, Siconos ``.dat``) and atomic writes."""
from .files import save_npz
from .readers import global_to_local, read_fclib, read_problem, read_siconos

__all__ = ["global_to_local", "read_fclib", "read_problem", "read_siconos", "save_npz"]
