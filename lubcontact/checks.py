"""Input validation used by every public constructor.

Every failure raises ``ValueError`` with a message that names the field and
shows the offending value, so that a user can find the mistake in their input.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike


def _show(value: ArrayLike) -> str:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iubfc":               # a string, None, an object: as it is
        return repr(value)
    if arr.size <= 6:
        if not arr.ndim:
            return repr(int(arr)) if arr.dtype.kind in "iub" else repr(float(arr))
        return np.array2string(arr, precision=6)
    return f"array of shape {arr.shape}"


def as_array(field: str, value: ArrayLike, shape: tuple[int | None, ...] | None = None,
             dtype: type = float) -> np.ndarray:
    """Convert ``value`` to an array, checking its shape and finiteness.

    Parameters
    ----------
    field : str
        Name reported in the error message.
    value : array_like
        The input.
    shape : tuple of int or None, optional
        Expected shape; ``None`` entries match any length.
    dtype : numpy dtype, optional
        Target dtype (default float).
    """
    try:
        arr = np.array(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{field}: cannot convert {value!r} to an array of {dtype.__name__}") from exc
    if shape is not None and arr.shape != shape:        # (equal: no entry to compare)
        ok = arr.ndim == len(shape) and all(
            want is None or want == got for want, got in zip(shape, arr.shape))
        if not ok:
            want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{field}: expected shape {want}, got {arr.shape}")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr.ravel()))
        raise ValueError(f"{field}: non-finite value {arr.ravel()[bad[0]]} at flat index {bad[0]}")
    return arr


def positive(field: str, value: ArrayLike, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Like :func:`as_array` and require every entry to be strictly positive."""
    arr = as_array(field, value, shape)
    if (arr <= 0).any():
        bad = np.flatnonzero(arr.ravel() <= 0)
        raise ValueError(f"{field}: must be > 0, got {arr.ravel()[bad[0]]} at index {bad[0]}")
    return arr


def per_item(field: str, value: ArrayLike, count: int) -> np.ndarray:
    """One value for each of ``count`` items: a scalar is repeated, an array must have shape (count,).

    Returns a new float array of shape (count,); finiteness is checked as in :func:`as_array`.
    """
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(count, float(arr))
    require(arr.shape == (count,), field, f"expected one value or shape ({count},), "
                                          f"got shape {arr.shape}")
    return as_array(field, arr, shape=(count,)).copy()


def integer(field: str, value: float, minimum: int = 0) -> int:
    """An integer (an integral float such as 3.0 is accepted) >= ``minimum``."""
    if type(value) is int and value >= minimum:          # the common case, without an array
        return value
    number = np.asarray(value)
    ok = number.ndim == 0 and number.dtype.kind in "iubf" and np.isfinite(number) \
        and float(number) == int(number)
    require(bool(ok) and int(value) >= minimum, field, f"must be an integer >= {minimum}", value)
    return int(value)


def positive_scalar(field: str, value: float) -> float:
    """A finite, strictly positive float."""
    if type(value) is float and 0.0 < value < math.inf:     # the common case, without an array
        return value
    return float(positive(field, value, shape=()))


def nonnegative(field: str, value: ArrayLike, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Like :func:`as_array` and require every entry to be >= 0."""
    arr = as_array(field, value, shape)
    if (arr < 0).any():
        bad = np.flatnonzero(arr.ravel() < 0)
        raise ValueError(f"{field}: must be >= 0, got {arr.ravel()[bad[0]]} at index {bad[0]}")
    return arr


def require(condition: bool, field: str, message: str, value: ArrayLike | None = None) -> None:
    """Raise ``ValueError`` naming ``field`` unless ``condition`` holds."""
    if not condition:
        shown = "" if value is None else f", got {_show(value)}"
        raise ValueError(f"{field}: {message}{shown}")
