"""Command-line values common to the benchmark commands: name lists, methods, the data folder."""
from __future__ import annotations

import re
from pathlib import Path

from ..solvers import methods
from .problem_sets import data_dir


def names(text: str | None) -> list[str] | None:
    """The items of a comma-separated option, stripped (None when the option is absent)."""
    if text is None:
        return None
    return [item.strip() for item in text.split(",") if item.strip()]


def check_methods(option: str, given: list[str]) -> None:
    """Raise ``ValueError`` naming ``option`` when a method of ``given`` is not registered."""
    unknown = sorted(set(given) - set(methods()))
    if unknown:
        raise ValueError(f"{option}: unknown {', '.join(map(repr, unknown))}; "
                         f"registered: {', '.join(methods())}")


def data_folder(override: str | Path | None) -> Path:
    """The benchmark-data folder (:func:`~lubcontact.bench.problem_sets.data_dir`) of ``--data-dir``.

    Raises
    ------
    ValueError
        ``override`` is not a directory (the message names ``--data-dir``), or
        the environment variable ``LUBCONTACT_DATA_DIR`` is not one.
    """
    try:
        return data_dir(override)
    except ValueError:
        if override is None:
            raise
        raise ValueError(f"--data-dir: not a directory: {override}") from None


def plain(text: str) -> str:
    """Docstring text for ``--help``: reStructuredText roles and literals made plain.

    ``:func:`~a.b.name``` -> ``name``, ``:mod:`a.b``` -> ``a.b``, double backquotes -> none.
    """
    text = re.sub(r":[a-z]+:`~?(?:[\w.]+\.)?([^`<]+?)`", lambda m: m.group(1), text)
    return text.replace("``", "")
