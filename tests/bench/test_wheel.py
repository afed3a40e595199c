"""The wheel stands alone: built from the checkout, installed in a fresh venv, its CLI runs.

The wheel is built (``python -m build --wheel --no-isolation``) from a copy of the
checkout's files (no ``build/``, ``*.egg-info`` or venv: a stale ``build/lib``
would leak deleted modules into the wheel), installed with ``pip install
--no-deps`` into a fresh venv, and run from an empty working directory. The
dependencies come from this venv's site-packages through ``PYTHONPATH``, which
does not process ``.pth`` files: the editable install of the checkout is not
seen, and ``lubcontact`` must be imported from the fresh venv. The packaged hard
cases (``check-hard``), reference cases (``compare --set tiny``) and external
benchmark problems (``problem_sets.data_dir``) are then used from the wheel.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
#: not copied for the build: version control, environments, build outputs (top level), caches
TOP_LEFT_OUT = {".git", ".venv", "venv", "build", "dist", "out", ".pytest_cache", ".hypothesis"}
CACHES = shutil.ignore_patterns("__pycache__", "*.egg-info", "*.pyc")
REFERENCE, FAST = "clarabel", "apgd"     # the methods the wheel's commands run


def _left_out(folder: str, names: list[str]) -> set[str]:
    top = TOP_LEFT_OUT if Path(folder) == REPO else set()
    return top & set(names) | CACHES(folder, names)


def _run(command: list, cwd: Path, env: dict | None = None, timeout: float = 300):
    result = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True,
                            text=True, timeout=timeout)
    return result, result.stdout + result.stderr


def build_wheel(tmp: Path) -> Path:
    source = tmp / "source"
    shutil.copytree(REPO, source, ignore=_left_out)
    result, output = _run([sys.executable, "-m", "build", "--wheel", "--no-isolation",
                           "--outdir", tmp / "dist"], cwd=source)
    assert result.returncode == 0, output
    wheel, = (tmp / "dist").glob("lubcontact-*.whl")
    return wheel


def test_wheel_installs_and_runs_from_a_fresh_venv(tmp_path):
    wheel = build_wheel(tmp_path)
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    cases = {n for n in names if n.startswith("lubcontact/bench/cases/data/") and n.endswith(".npz")}
    assert {"lubcontact/bench/cases/data/pile200_inelastic.npz",
            "lubcontact/bench/cases/data/push_pull_impact.npz"} <= cases
    for name in ("README.md", "siconos-testdata/README.md",
                 "siconos-testdata/FrictionContact3D_1c.dat",
                 "siconos-testdata/Spheres-i099-356-679.hdf5",
                 "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat",
                 "fclib-local/LMGC_100_PR_PerioBox-i00361-60-03000.hdf5"):
        assert f"lubcontact/bench/data/{name}" in names, name
    shipped = [p for p in (REPO / "lubcontact/bench/data").rglob("*") if p.is_file()]
    assert {f"lubcontact/{p.relative_to(REPO / 'lubcontact').as_posix()}" for p in shipped} <= names

    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True, symlinks=os.name != "nt")
    python = env_dir / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
    result, output = _run([python, "-m", "pip", "install", "--no-deps", "--no-index",
                           "--disable-pip-version-check", "--quiet", wheel], cwd=tmp_path)
    assert result.returncode == 0, output

    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "LUBCONTACT_DATA_DIR")}
    env.update(PYTHONPATH=sysconfig.get_paths()["purelib"], PYTHONNOUSERSITE="1",
               MPLBACKEND="Agg", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1")

    probe = ("import lubcontact; from lubcontact.bench import problem_sets as p; "
             "print(lubcontact.__file__); print(p.data_dir()); "
             "print(p.benchmark_file('siconos-testdata', 'FrictionContact3D_1c.dat')); "
             "print(len(p.SETS['fclib'].instances()))")
    result, output = _run([python, "-c", probe], cwd=work, env=env)
    assert result.returncode == 0, output
    module, data, one_file, n_fclib = result.stdout.split()
    site = env_dir.resolve()
    for path in (module, data, one_file):
        assert Path(path).resolve().is_relative_to(site), (path, site)    # not the checkout
    assert n_fclib == "4"

    # two methods (the reference and a fast one): what is checked here is the packaged data; every
    # method on every case is the hard-case suite's own test, and compiling each method's kernels
    # afresh in the new venv would take minutes
    result, output = _run([python, "-m", "lubcontact.cli", "check-hard", "--solvers",
                           f"{REFERENCE},{FAST}"], cwd=work, env=env)
    assert result.returncode == 0, output              # 1 would mean a wrong or crashed cell
    assert "crash: 0" in result.stdout and "ok: " in result.stdout, output
    assert "mass_ratio_1e6_collision" in result.stdout

    out = tmp_path / "compare"
    result, output = _run([python, "-m", "lubcontact.cli", "compare", "--set", "tiny", "--quiet",
                           "--solvers", REFERENCE, FAST, "--repeats", "1", "--out", out],
                          cwd=work, env=env)
    assert result.returncode == 0, output
    assert f"set tiny: report written to {out / 'tiny' / 'report.md'}" in result.stdout, output
    assert (out / "tiny" / "report.md").is_file()
