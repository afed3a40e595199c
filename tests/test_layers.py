"""The layer contract: which folder of the package may import which.

The core a teacher reads alone (``problem``, ``model``, ``solvers``, ``sim``,
``io``, ``scenes``, ``checks`` and the public face ``lubcontact/__init__.py``)
never imports the tooling (``bench``, ``flow``, ``demo``, ``cli``), and inside
the core data flows one way::

    problem <- model <- sim <- scenes        solvers see problems only, never grains
    problem <- solvers <- sim

Every ``import`` statement of every module is read (function-level imports and
``importlib.import_module("lubcontact...")`` calls included), so a lazy import
cannot hide a violation.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import lubcontact

PACKAGE = Path(lubcontact.__file__).resolve().parent
TOOLING = {"bench", "flow", "demo", "cli"}
CORE_ALLOWED = {
    "face": {"checks", "problem", "model", "solvers", "sim", "io", "scenes"},
    "checks": set(),
    "problem": {"checks"},
    "model": {"checks", "problem"},
    "solvers": {"checks", "problem"},
    "io": {"checks", "problem", "model"},
    "sim": {"checks", "problem", "model", "solvers", "io"},
    "scenes": {"checks", "problem", "model", "solvers", "sim", "io"},
}
"""For each core layer, the layers it may import (itself always)."""


def layer_of(module: str) -> str:
    """``lubcontact.solvers.registry`` -> ``solvers``; the package itself -> ``face``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "face"


def imported_modules(module: str, is_package: bool, source: str) -> list[str]:
    """Absolute names of the lubcontact modules that ``source`` imports."""
    found = []
    base = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - (node.level - 1)]
                target = ".".join(anchor + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append(target)
            found += [f"{target}.{alias.name}" for alias in node.names]   # submodules by name
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) \
                == "import_module" and node.args and isinstance(node.args[0], ast.Constant):
            found.append(str(node.args[0].value))
    return [name for name in found if name.split(".")[0] == "lubcontact"]


def violations(module: str, is_package: bool, source: str) -> list[str]:
    """The imports of ``module`` that break the layer contract, as readable lines."""
    layer = layer_of(module)
    if layer not in CORE_ALLOWED:
        return []                                        # tooling may import anything
    allowed = CORE_ALLOWED[layer] | {layer}
    out = []
    for target in imported_modules(module, is_package, source):
        if target == "lubcontact":
            continue
        wanted = layer_of(target)
        if wanted in TOOLING or (wanted in CORE_ALLOWED and wanted not in allowed):
            out.append(f"{module} ({layer}) imports {target} ({wanted})")
    return sorted(set(out))


def package_modules() -> list[tuple[str, bool, Path]]:
    modules = []
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(relative.parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        modules.append((".".join(parts), is_package, path))
    return modules


def test_every_core_layer_is_listed():
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert folders == (set(CORE_ALLOWED) - {"face", "checks"}) | (TOOLING - {"demo", "cli"})


def test_the_package_keeps_its_layers():
    found = [line for module, is_package, path in package_modules()
             for line in violations(module, is_package, path.read_text())]
    assert found == []


@pytest.mark.parametrize("module, source", [
    ("lubcontact.solvers.registry", "from ..bench import compare"),          # core -> tooling
    ("lubcontact.sim.simulation", "def f():\n    from lubcontact.flow import run\n"),  # lazy
    ("lubcontact.solvers.gradient", "from ..model.contacts import Contacts"),  # solvers -> model
    ("lubcontact.problem.step", "from ..solvers import solve"),             # problem -> solvers
    ("lubcontact.model.laws", "import importlib\nimportlib.import_module('lubcontact.sim')"),
    ("lubcontact", "from .bench import hard"),                              # the face
])
def test_a_violation_is_caught(module, source):
    assert violations(module, module == "lubcontact", source) != []


@pytest.mark.parametrize("module, source", [
    ("lubcontact.bench.compare", "from ..solvers import solve\nfrom ..flow import run"),
    ("lubcontact.sim.simulation", "from ..solvers import SolveSettings\nfrom ..model import Scene"),
    ("lubcontact.solvers.coulomb", "from ..problem.metrics import coulomb_shift"),
])
def test_allowed_imports_pass(module, source):
    assert violations(module, False, source) == []
