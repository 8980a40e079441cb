"""The one numpy-to-JSON converter (svgs_sim.base.jsonable) and its three writers' options."""

import json
from pathlib import Path

import numpy as np
import pytest


def test_numpy_values_become_plain_ones():
    from svgs_sim.base.jsonable import to_jsonable

    out = to_jsonable({1: np.float32(0.5), "a": (np.int64(2), np.bool_(True)), "m": np.array([[1, 2], [3, 4]])})
    assert out == {"1": 0.5, "a": [2, True], "m": [[1, 2], [3, 4]]}
    assert type(out["a"][0]) is int and type(out["a"][1]) is bool and type(out["1"]) is float


def test_nonfinite_kept_or_null():
    from svgs_sim.base.jsonable import to_jsonable

    x = {"v": np.array([np.nan, 1.5, np.inf]), "s": float("-inf")}
    assert to_jsonable(x, nonfinite="null") == {"v": [None, 1.5, None], "s": None}
    kept = to_jsonable(x)
    assert np.isnan(kept["v"][0]) and kept["v"][2] == np.inf and kept["s"] == -np.inf
    assert json.dumps(kept) == '{"v": [NaN, 1.5, Infinity], "s": -Infinity}'
    with pytest.raises(ValueError, match="nonfinite"):
        to_jsonable(x, nonfinite="drop")


def test_other_types_as_text_or_left_for_json_to_refuse():
    from svgs_sim.base.jsonable import json_default, to_jsonable

    assert to_jsonable({"p": Path("a") / "b"}) == {"p": "a/b"}
    obj = object()
    assert to_jsonable([obj], other=None)[0] is obj
    with pytest.raises(TypeError):
        json.dumps(to_jsonable({"o": obj}, other=None))
    assert json.dumps({"x": np.int16(3), "a": np.array([0.25, np.nan])}, default=json_default) == \
        '{"x": 3, "a": [0.25, NaN]}'


def test_the_writers_share_it():
    """svgs_sim.cli.json_out.clean (strict --json), svgs_sim.cli.solve.json_default (solution files) and the results
    store's manifests are the one converter with their options."""
    from svgs_sim.cli.json_out import clean
    from svgs_sim.cli.solve import json_default
    from svgs_sim.studies.store import _jsonable
    from svgs_sim.base import jsonable

    assert json_default is jsonable.json_default
    x = {"a": np.float64("nan"), "b": (np.int64(2), Path("p"))}
    assert clean(x) == {"a": None, "b": [2, "p"]}
    got = _jsonable(x)
    assert np.isnan(got["a"]) and got["b"][0] == 2 and isinstance(got["b"][1], Path)
