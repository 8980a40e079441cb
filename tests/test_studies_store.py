"""Results store: exact round trip, resume, torn writes, manifest checks, locking."""

import json
import math

import numpy as np
import pytest

from studies.seeding import design_rng, trial_seed
from studies.store import ResultStore, read_rows, read_table
from svgs.errors import InputError

COLS = ["trial_id", "seed", "camera", "value", "ok", "reason"]


def _rows(ids):
    return [{"trial_id": i, "seed": 10 + i, "camera": "galaxy-nexus", "value": 0.1 * i + 1e-17 * i,
             "ok": i % 3 != 0, "reason": None if i % 3 else "diverged"} for i in ids]


def test_rows_round_trip_exactly_and_resume_skips_done(tmp_path):
    vals = [1 / 3, np.pi * 1e-9, -2.5e30, 0.1 + 0.2]
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.append(_rows([3, 1])) == 2
        st.append([{"trial_id": 10 + k, "value": v} for k, v in enumerate(vals)])
        st.append([{"trial_id": 20, "value": float("nan")}])
        assert st.append(_rows([1, 2])) == 1  # 1 is already stored: skipped
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {1, 2, 3, 10, 11, 12, 13, 20}
        rows = st.read_rows()
    assert [r["trial_id"] for r in rows] == [1, 2, 3, 10, 11, 12, 13, 20]  # sorted by id
    assert [r["value"] for r in rows if 10 <= r["trial_id"] < 20] == [vals[0], vals[1], vals[2], vals[3]]  # bit-exact
    by = {r["trial_id"]: r for r in rows}
    assert by[3]["ok"] == 0 and by[3]["reason"] == "diverged" and by[1]["reason"] is None
    t = read_table(tmp_path / "results.csv", COLS)
    assert t["value"].dtype == float and math.isnan(t["value"][list(t["trial_id"]).index(20)])
    assert t["reason"].dtype == object and t["reason"][list(t["trial_id"]).index(3)] == "diverged"


def test_torn_last_line_is_cut_and_rerun(tmp_path):
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        st.append(_rows([0, 1, 2]))
    with open(tmp_path / "results.csv", "ab") as fh:  # a write cut short by SIGKILL
        fh.write(b"3,13,galaxy-nexus,0.30000")
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {0, 1, 2}
        st.append(_rows([3]))
    text = (tmp_path / "results.csv").read_text()
    assert text.endswith("\n") and "0.30000\n" not in text
    ids = [r["trial_id"] for r in read_rows(tmp_path / "results.csv")]
    assert ids == [0, 1, 2, 3]


def test_other_parameters_are_refused_with_the_differences(tmp_path):
    ResultStore(tmp_path, {"camera": "galaxy-nexus", "trials": 10}, COLS)
    with pytest.raises(InputError, match=r"trials: 10 -> 20"):
        ResultStore(tmp_path, {"camera": "galaxy-nexus", "trials": 20}, COLS)
    with pytest.raises(InputError, match="different parameters"):
        ResultStore(tmp_path, {"camera": "galaxy-nexus", "trials": 10}, COLS + ["extra"])
    m = json.loads((tmp_path / "manifest.json").read_text())
    assert m["parameters"] == {"camera": "galaxy-nexus", "trials": 10}


def test_two_runs_cannot_write_one_directory(tmp_path):
    a = ResultStore(tmp_path, {"a": 1}, COLS).open()
    try:
        with pytest.raises(InputError, match="another run"):
            ResultStore(tmp_path, {"a": 1}, COLS).open()
    finally:
        a.close()
    ResultStore(tmp_path, {"a": 1}, COLS).open().close()  # released


def test_trial_seeds_are_the_spawned_children_and_independent_of_order():
    import numpy as np

    kids = np.random.SeedSequence(42).spawn(5)
    for i, k in enumerate(kids):
        want = int(k.spawn(2)[0].generate_state(1, np.uint64)[0] >> np.uint64(1))
        assert trial_seed(42, i) == want
    seeds = [trial_seed(42, i) for i in range(1000)]
    assert len(set(seeds)) == 1000
    assert [trial_seed(42, i) for i in reversed(range(1000))] == seeds[::-1]
    assert design_rng(42, 7).uniform() == design_rng(42, 7).uniform()
    assert design_rng(42, 7).uniform() != design_rng(42, 8).uniform()
    with pytest.raises(InputError):
        trial_seed(-1, 0)


def test_a_torn_header_is_rewritten(tmp_path):
    ResultStore(tmp_path, {"a": 1}, COLS)
    (tmp_path / "results.csv").write_bytes(b"trial_id,se")
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == set()
        st.append(_rows([5]))
    assert (tmp_path / "results.csv").read_text().startswith(",".join(COLS) + "\n5,15,")
