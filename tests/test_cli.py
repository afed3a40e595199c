"""The command line: a light --help, --version, outside solver modules; the lazy public face."""
import os
import subprocess
import sys

import pytest

import lubcontact
from lubcontact.cli import BLAS_THREADS, main


@pytest.fixture(autouse=True)
def _blas_environment_restored():
    """``main`` sets the BLAS thread variables where none is set: put them back after each test."""
    saved = {name: os.environ.get(name) for name in BLAS_THREADS}
    yield
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


def test_help_imports_neither_cvxpy_nor_numba():
    """Nor numpy: the BLAS thread default (``BLAS_THREADS``) must be set before it loads."""
    script = ("import sys; from lubcontact.cli import main; print('numpy' in sys.modules); "
              "main(['--help']); print('cvxpy' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()
    assert out[0] == "False" and out[-1] == "False False"


def test_the_solvers_import_numba_only_when_a_kernel_runs():
    """The registry (``lubcontact.solvers``) loads the compiled kernels on first use: a script
    that only solves with Clarabel never pays numba's import."""
    script = ("import sys; import lubcontact.solvers; from lubcontact.solvers import newton; "
              "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip().splitlines()[-1] == "False"


def test_every_public_name_resolves():
    for name in lubcontact.__all__:
        assert getattr(lubcontact, name) is not None, name
    assert set(lubcontact.__all__) <= set(dir(lubcontact))
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        lubcontact.Nope  # noqa: B018


def test_version_and_bad_solver_module(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"lubcontact {lubcontact.__version__}"
    assert main(["--solver-module", "no_such_module_here", "verify", "a", "b"]) == 2
    assert "--solver-module: cannot import 'no_such_module_here'" in capsys.readouterr().err
    assert main(["--solver-module"]) == 2
    assert main(["nope"]) == 2


@pytest.mark.parametrize("command", [["check-hard"], ["compare"], ["verify"], ["bench", "solvers"],
                                     ["bench", "friction"], ["demo"], ["run"], ["sweep"]])
def test_help_has_no_markup(command, capsys):
    """--help shows plain text (docstrings' reStructuredText roles and literals removed)."""
    with pytest.raises(SystemExit) as stop:
        main([*command, "--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert out and "``" not in out and ":func:" not in out and ":class:" not in out


def test_blas_runs_on_one_thread_unless_the_environment_says_otherwise():
    """A command's results do not depend on the core count: BLAS on one thread where none of the
    variables is set (set before numpy loads); any of them set, the environment decides. In a
    fresh interpreter, where numpy is not yet imported, as for the ``lubcontact`` script."""
    script = ("import os; from lubcontact.cli import BLAS_THREADS, main; main(['--help']); "
              "print(','.join(os.environ.get(name, 'unset') for name in BLAS_THREADS))")
    clean = {k: v for k, v in os.environ.items() if k not in BLAS_THREADS}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, env=clean).stdout
    assert out.strip().splitlines()[-1] == "1,1,1"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, env={**clean, "OPENBLAS_NUM_THREADS": "4"}).stdout
    assert out.strip().splitlines()[-1] == "4,unset,unset"


@pytest.mark.parametrize("argv, flag", [
    (["bench", "solvers", "--sizes", "abc"], "--sizes"),
    (["bench", "small", "--sizes", "4,x"], "--sizes"),
    (["bench", "flow", "--sizes", "0"], "--sizes"),
    (["check-hard", "--tol", "-1"], "--tol"),
    (["check-hard", "--tol", "inf"], "--tol"),
    (["check-hard", "--solvers", ","], "--solvers"),
    (["bench", "small", "--tol", "0"], "--tol"),
    (["verify", "p.npz", "s.npz", "--tol", "nan"], "--tol"),
])
def test_bad_numbers_are_one_line_errors_naming_the_flag(argv, flag, capsys):
    """A bad size or tolerance stops the command with argparse's one line naming the flag (they
    were tracebacks from deep inside: ``int('abc')``, ``tol: must be > 0``)."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert flag in last and "Traceback" not in last


def test_counts_take_spaces_commas_or_both():
    """``--sizes 4 10 20``, ``--sizes 4,10,20`` and ``--sizes 4,10 20`` are the same sizes."""
    from lubcontact.bench.options import counts

    assert counts("--sizes", ["4", "10", "20"]) == counts("--sizes", ["4,10,20"]) \
        == counts("--sizes", ["4,10", "20"]) == [4, 10, 20]
    with pytest.raises(ValueError, match="--sizes: must be >= 1, got 0"):
        counts("--sizes", ["4,0"])
