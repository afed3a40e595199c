"""Command-line values common to the commands: name lists, counts, bounded numbers, methods, the
data folder. Light to import (``lubcontact run --help`` imports it): the registry and the problem
sets are imported where they are used."""
from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from pathlib import Path


def names(text: str | None) -> list[str] | None:
    """The items of a comma-separated option, stripped (None when the option is absent)."""
    if text is None:
        return None
    return [item.strip() for item in text.split(",") if item.strip()]


def number(kind: type, low: float | None = None, *, above: bool = False,
            high: float | None = None) -> Callable[[str], float]:
    """An argparse type: ``kind`` (int or float) >= ``low`` (> with ``above``), < ``high``; a bad
    value is argparse's one-line error naming the flag (``--tol: must be > 0, got -1``)."""
    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        if low is not None and (value <= low if above else value < low):
            raise argparse.ArgumentTypeError(f"must be {'>' if above else '>='} {low:g}, "
                                             f"got {text}")
        if high is not None and not value < high:
            raise argparse.ArgumentTypeError(f"must be < {high:g}, got {text}")
        return value
    return parse


def items(tokens: list[str]) -> list[str]:
    """The items of an option given with ``nargs="+"`` whose values may also be comma separated
    (``--solvers a b``, ``--solvers a,b`` or both mixed), in order."""
    return [item for token in tokens for item in names(token)]


def counts(option: str, tokens: list[str]) -> list[int]:
    """Positive integers given after ``option`` (``--sizes 4 10 20`` or ``--sizes 4,10,20``, or both
    mixed), in order.

    Raises
    ------
    ValueError
        Naming ``option`` and the token that is not a positive integer.
    """
    values = []
    for item in items(tokens):
        try:
            value = int(item)
        except ValueError:
            raise ValueError(f"{option}: expected positive integers (spaces or commas between "
                             f"them), got {item!r}") from None
        if value < 1:
            raise ValueError(f"{option}: must be >= 1, got {value}")
        values.append(value)
    if not values:
        raise ValueError(f"{option}: expected at least one positive integer")
    return values


def given_methods(option: str, tokens: list[str]) -> list[str]:
    """The registered methods given after ``option`` (``nargs="+"``, space or comma separated).

    Raises
    ------
    ValueError
        Naming ``option``, where none is given or one is not registered.
    """
    given = items(tokens)
    if not given:
        raise ValueError(f"{option}: expected at least one method")
    check_methods(option, given)
    return given


def check_methods(option: str, given: list[str]) -> None:
    """Raise ``ValueError`` naming ``option`` when a method of ``given`` is not registered."""
    from ..solvers import methods  # the registry, on use: this module stays light (number)
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
    from .problem_sets import data_dir  # on use, as the registry above

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
