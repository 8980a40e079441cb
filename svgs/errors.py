"""Exceptions for bad input.

Bad input (a missing file, a profile with a NaN, a degenerate point set) raises
:class:`InputError`, a :class:`ValueError` whose message names the input and what was
wrong. The CLI maps it to exit code 2. Failures of *estimation* (no consistent set of
blobs, a diverged solve) are not exceptions: they are falsy result objects, see
:mod:`svgs.result`.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: the message names the input and what was wrong with it."""


class ProfileError(InputError):
    """A camera profile or target pattern that cannot be used."""


def check_finite_positive(value, name: str, *, allow_zero: bool = False) -> float:
    """Return ``float(value)`` if it is a finite positive number, else raise.

    Parameters
    ----------
    value : object
        The value to check.
    name : str
        Name of the input, used in the error message (e.g. ``"intrinsics.fx"``).
    allow_zero : bool
        Accept exactly zero as well.

    Returns
    -------
    float
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    if v < 0 or (v == 0 and not allow_zero):
        word = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name}: expected a {word} number, got {value!r}")
    return v


def check_finite(value, name: str) -> float:
    """Return ``float(value)`` if it is a finite number, else raise :class:`InputError`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    return v
