"""Plain JSON values from numpy ones: the project's one converter.

Every JSON file and ``--json`` object the project writes goes through :func:`to_jsonable`
(directly, or through :func:`json_default` as ``json.dumps``' ``default`` hook): numpy
arrays become lists, numpy scalars Python numbers, tuples lists and dict keys strings.
What differs between writers is stated by its two options, not by another copy:

- ``nonfinite="null"`` writes NaN and infinity as ``null`` (strict JSON, the ``--json``
  objects of the study commands); ``"keep"`` leaves them as floats (``json.dumps`` then
  writes ``NaN``/``Infinity``, as the solution files and the results store's manifests do).
- ``other``: what becomes of a value of any other type (a ``Path``, an enum, ...):
  ``str`` (the default) writes its text; ``None`` leaves it as it is, so that ``json.dumps``
  refuses it (the results store's manifests: a parameter must be a plain value).

Imports only the standard library and numpy (generic: no other module of the project).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

NONFINITE = ("keep", "null")


def to_jsonable(obj, *, nonfinite: str = "keep", other: Callable | None = str):
    """``obj`` in plain JSON types.

    Parameters
    ----------
    obj : object
        Nested dicts, lists and tuples of numbers, strings, None, numpy arrays and scalars.
    nonfinite : {"keep", "null"}
        NaN and infinite floats kept as floats, or written as None.
    other : callable or None
        Applied to values of any other type (default ``str``); None leaves them unchanged.

    Returns
    -------
    object
        Dicts (keys ``str(key)``), lists, bool, int, float, str and None; numpy arrays as
        nested lists of their elements (converted alike).
    """
    if nonfinite not in NONFINITE:
        raise ValueError(f"to_jsonable: nonfinite must be one of {NONFINITE}, not {nonfinite!r}")

    def conv(o):
        if isinstance(o, dict):
            return {str(k): conv(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [conv(v) for v in o]
        if isinstance(o, np.ndarray):
            return conv(o.tolist())
        if isinstance(o, (bool, np.bool_)):
            return bool(o)
        if isinstance(o, (int, np.integer)):
            return int(o)
        if isinstance(o, (float, np.floating)):
            v = float(o)
            return None if nonfinite == "null" and not math.isfinite(v) else v
        if o is None or isinstance(o, str):
            return o
        return o if other is None else other(o)

    return conv(obj)


def json_default(o):
    """``json.dumps``' ``default`` hook: :func:`to_jsonable` of a value ``json`` does not know
    (numpy arrays and scalars; anything else as its text). NaN stays NaN."""
    return to_jsonable(o)
