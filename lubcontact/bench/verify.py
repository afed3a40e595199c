"""``lubcontact verify PROBLEM SOLUTION``: judge a solution computed anywhere, exit 0 (pass) or 1 (fail).

PROBLEM is a Siconos ``.dat`` or FCLIB ``.hdf5``/``.h5`` file (a local problem
``u = W r + q``), or a step problem written by lubcontact as ``.npz``
(``StepProblem.to_arrays``). SOLUTION holds forces and/or velocities:

- ``.npz``: arrays named ``r``/``forces`` and ``u``/``v``/``velocities``;
- ``.h5``/``.hdf5``: the same names at the top level or in a ``solutions`` group (FCLIB);
- text (anything else): whitespace-separated columns, the first the forces, an
  optional second the velocities (as many rows as the problem has rows).

Vectors of a local problem are read in the FCLIB/Siconos contact-major layout
(normal component first for each contact) unless ``--layout ours``; vectors
of a step problem in lubcontact's own layout. The verdict and its measures
are those of :func:`lubcontact.solvers.verify.verify`.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..io import read_problem
from ..problem import LocalProblem, StepProblem
from ..problem.conic import ConicProblem
from ..solvers import methods
from ..solvers.verify import VerificationReport, verify
from .options import number

FORCE_NAMES = ("r", "forces", "x")
VELOCITY_NAMES = ("u", "v", "velocities")


def load_problem(path: Path) -> ConicProblem:
    """A problem file: ``.npz`` step problem, else a Siconos/FCLIB local problem."""
    if path.suffix == ".npz":
        with np.load(path) as data:
            return StepProblem.from_arrays(dict(data))
    return read_problem(path)


def load_solution(path: Path) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(forces, velocities)`` from a solution file (either may be None)."""
    if not path.is_file():
        raise ValueError(f"SOLUTION: no file {path}")
    if path.suffix == ".npz":
        with np.load(path) as data:
            arrays = dict(data)
    elif path.suffix in (".h5", ".hdf5"):
        import h5py

        with h5py.File(path, "r") as stream:
            group = stream["solutions"] if "solutions" in stream else stream
            arrays = {name: np.asarray(group[name]) for name in group
                      if isinstance(group[name], h5py.Dataset)}
    else:
        try:
            columns = np.loadtxt(path, ndmin=2)
        except ValueError as exc:
            raise ValueError(f"SOLUTION: {path}: not numeric columns ({exc})") from None
        arrays = {"forces": columns[:, 0]}
        if columns.shape[1] > 1:
            arrays["velocities"] = columns[:, 1]
    forces = next((np.ravel(arrays[n]) for n in FORCE_NAMES if n in arrays), None)
    velocities = next((np.ravel(arrays[n]) for n in VELOCITY_NAMES if n in arrays), None)
    if forces is None and velocities is None:
        raise ValueError(f"SOLUTION: {path} holds none of {FORCE_NAMES + VELOCITY_NAMES}")
    return forces, velocities


def verify_files(problem_path: Path, solution_path: Path, *, tol: float, reference: str | None,
                 layout: str, worst: int) -> VerificationReport:
    """Read both files and verify (see the module docstring)."""
    problem = load_problem(problem_path)
    forces, velocities = load_solution(solution_path)
    if isinstance(problem, LocalProblem) and layout == "contact-major":
        forces = None if forces is None else _ours(problem, forces, "forces")
        velocities = None if velocities is None else _ours(problem, velocities, "velocities")
    return verify(problem, forces, velocities, tol=tol, reference=reference, worst=worst)


def _ours(problem: LocalProblem, vector: np.ndarray, field: str) -> np.ndarray:
    if vector.shape != (problem.n_rows,):
        raise ValueError(f"{field}: expected {problem.n_rows} values ({problem.n_contacts} "
                         f"contacts x {problem.dim}), got {vector.size}")
    return problem.from_contact_major_vector(vector)


def parser() -> argparse.ArgumentParser:
    cli = argparse.ArgumentParser(
        prog="lubcontact verify", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        description="Judge a solution of a contact problem against the problem and the "
                    "Clarabel reference; exit status 0 on pass, 1 on fail, 2 on bad input.")
    cli.add_argument("problem", type=Path, help="problem file (.dat, .hdf5/.h5, or .npz step problem)")
    cli.add_argument("solution", type=Path, help="solution file (.npz, .h5/.hdf5, or text columns)")
    cli.add_argument("--tol", type=number(float, 0, above=True), default=1e-8,
                     help="tolerance of the verdict "
                     "(normalised units)")
    cli.add_argument("--reference", default="auto",
                     help="registered method computing the reference ('auto': Clarabel on the "
                          "primal form for a step problem, on the dual form otherwise; 'none' "
                          "to skip)")
    cli.add_argument("--layout", choices=("contact-major", "ours"), default="contact-major",
                     help="row layout of a local problem's solution vectors")
    cli.add_argument("--worst", type=int, default=5, help="how many contacts to list")
    cli.add_argument("--json", action="store_true", help="print the report as JSON")
    return cli


def main(argv: list[str] | None = None) -> int:
    cli = parser()
    args = cli.parse_args(argv)
    reference = None if args.reference == "none" else args.reference
    if reference not in (None, "auto") and reference not in methods():
        cli.error(f"--reference: unknown method {reference!r}; registered: {', '.join(methods())}")
    if args.worst < 0:
        cli.error(f"--worst: must be >= 0, got {args.worst}")
    try:
        report = verify_files(args.problem, args.solution, tol=args.tol, reference=reference,
                              layout=args.layout, worst=args.worst)
    except (ValueError, FileNotFoundError) as exc:
        print(f"lubcontact verify: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    print(report.to_json() if args.json else report.text())
    return 0 if report.passed else 1
