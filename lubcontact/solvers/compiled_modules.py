"""The compiled (numba) modules of the solvers, imported on first use.

Importing numba and loading the compiled kernels costs start-up time that a solve needing no
compiled loop (Clarabel, a numpy lane) should not pay, so :mod:`.newton` and
:mod:`.factorisations` call these instead of importing them at the top.
"""
from __future__ import annotations

from functools import cache
from types import ModuleType


@cache
def kernels() -> ModuleType:
    """:mod:`.kernels` (numba), imported on first use; an import statement in a function costs
    0.8 us each time, which a small solve paid at each phase and each error."""
    from . import kernels as compiled

    return compiled


@cache
def ordering() -> ModuleType:
    """:mod:`.ordering` (numba), imported on first use."""
    from . import ordering as compiled

    return compiled
