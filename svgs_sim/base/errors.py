"""Exceptions for bad input and for simulated physical failures.

Bad input (a missing file, a profile with a NaN, a degenerate point set) raises
:class:`InputError`, a :class:`ValueError` whose message names the input and what was
wrong. The CLI maps it to exit code 2. Failures of *estimation* (no consistent set of
blobs, a diverged solve) are not exceptions: they are falsy result objects, see
:mod:`svgs_sim.svgs.result`. A *simulated* sensor that measures nothing at all (every pixel
saturated by the light it was given) raises :class:`SimulationFailure`: the input was
valid, the physics failed; the CLI maps it to exit code 1 (no solution) with its reason.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: the message names the input and what was wrong with it."""


class ProfileError(InputError):
    """A camera profile or target pattern that cannot be used."""


class SimulationFailure(RuntimeError):
    """A simulated physical failure: valid input, but the simulated sensor measured nothing usable.

    Not bad input (that is :class:`InputError`, exit 2): the scene and the sensor were what the
    user asked for, and the physics left nothing to measure (e.g. the ambient light saturated
    every pixel). The CLI prints the message and exits 1, as for an unsolved pose.

    Parameters
    ----------
    message : str
        What failed and why, for people (the numbers that made it fail).
    reason : str
        A short machine-readable code (``"saturated"``, ``"no_signal"``).
    """

    def __init__(self, message: str, reason: str):
        super().__init__(message)
        self.reason = str(reason)


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


def interrupt_in(exc: BaseException) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` (Ctrl-C, or SIGTERM's subclass) among ``exc``'s causes, if any:
    an interrupt raised inside a callback from compiled code (a Numba kernel) comes back as a
    ``SystemError`` caused by it, one raised in the Python frame of a Dr.Jit custom operation
    (``mi.render``) as a ``RuntimeError``.

    Parameters
    ----------
    exc : BaseException
        An exception raised by native code that wraps what it caught (``__cause__`` or
        ``__context__``).

    Returns
    -------
    KeyboardInterrupt or None
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def number_items(text, flag: str, *, count: int | None = None) -> list[float]:
    """The numbers of a comma-separated option value, each item checked as written.

    ``"5,10,20"`` -> ``[5.0, 10.0, 20.0]``. Refused with :class:`InputError` naming ``flag`` and the
    item: an empty item (``"5,,10"``, a trailing comma), an item with an underscore (Python's
    ``float`` reads ``"5_0"`` as 50, which a user did not mean), any other item that is not a
    number, and, with ``count``, a list of another length. Finiteness and bounds are the caller's.

    Parameters
    ----------
    text : str
    flag : str
        The option, as the user typed it (``--ranges``), for the message.
    count : int, optional
        The number of items required.

    Returns
    -------
    list of float
    """
    vals = []
    for s in (s.strip() for s in str(text).split(",")):
        if not s:
            raise InputError(f"{flag}: an empty item in {text!r} (write the numbers separated by single commas)")
        if "_" in s:
            raise InputError(f"{flag}: {s!r} is not a number as written (no underscores), in {text!r}")
        try:
            vals.append(float(s))
        except ValueError:
            raise InputError(f"{flag}: {s!r} is not a number, in {text!r}") from None
    if count is not None and len(vals) != count:
        raise InputError(f"{flag}: expected {count} comma-separated numbers, got {len(vals)} in {text!r}")
    return vals

