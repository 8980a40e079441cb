"""Results store: exact round trip, resume, torn writes, manifest checks, locking."""

import json
import math

import numpy as np
import pytest

from svgs_sim.studies.seeding import design_rng, trial_seed
from svgs_sim.studies.store import ResultStore, read_rows, read_table
from svgs_sim.base.errors import InputError

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


# --------------------------------------------------------------------------- malformed rows
def _with_line(tmp_path, line: bytes, **kw) -> bytes:
    """A store of trials 0, 1, 2 with ``line`` inserted as file line 4 (between trials 1 and 2)."""
    with ResultStore(tmp_path, {"a": 1}, COLS, **kw) as st:
        st.append(_rows([0, 1, 2]))
    clean = (tmp_path / "results.csv").read_bytes()
    lines = clean.split(b"\n")
    lines.insert(3, line)
    (tmp_path / "results.csv").write_bytes(b"\n".join(lines))
    return clean


def _rejected(tmp_path):
    import csv

    with open(tmp_path / "results.rejected.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("line, problem", [
    (b"\xff\xfe garbage \x00 @@@", "not UTF-8 text"),
    (b'7,17,"galaxy-nexus,0.5,1,', "not a CSV row (unexpected end of data)"),
    (b"999,this,is,not,a,row,@@@", "7 fields where the header has 6"),
    (b"7,17,galaxy-nexus,0.5", "4 fields where the header has 6"),
    (b"x7,17,galaxy-nexus,0.5,1,", "trial_id 'x7' is not a non-negative integer"),
    (b"7.0,17,galaxy-nexus,0.5,1,", "trial_id '7.0' is not a non-negative integer"),
    (b"-7,17,galaxy-nexus,0.5,1,", "trial_id '-7' is not a non-negative integer"),
    (b"7,1.5,galaxy-nexus,0.5,1,", "seed '1.5' is not an integer"),
    (b"7,17,galaxy-nexus,@@@,1,", "value '@@@' is not a number"),
    (b"7,17,galaxy-nexus,0.5,yes,", "ok 'yes' is not a number"),
], ids=["binary-garbage", "unterminated-quote", "too-many-fields", "too-few-fields", "non-integer-id", "float-id",
        "negative-id", "non-integer-seed", "text-in-numeric-column", "text-in-flag-column"])
def test_a_malformed_row_is_set_aside_not_counted(tmp_path, capsys, line, problem):
    clean = _with_line(tmp_path, line)
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {0, 1, 2}  # 7 and 999 are not done
        assert st.set_aside == [(4, problem)]
        assert st.append(_rows([7])) == 1
    err = capsys.readouterr().err
    assert f"{tmp_path / 'results.csv'} line 4: {problem}" in err and "results.rejected.csv" in err
    rej = _rejected(tmp_path)
    assert [(r["line"], r["problem"]) for r in rej] == [("4", problem)]
    assert rej[0]["row"] == line.decode(errors="backslashreplace")
    assert (tmp_path / "results.csv").read_bytes().startswith(clean)  # the good rows, untouched
    assert [r["trial_id"] for r in read_rows(tmp_path / "results.csv")] == [0, 1, 2, 7]
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:  # clean now: nothing more is set aside
        assert st.done_ids == {0, 1, 2, 7} and st.set_aside == []
    assert capsys.readouterr().err == ""


def test_an_id_outside_the_study_is_set_aside(tmp_path, capsys):
    _with_line(tmp_path, b"999,1009,galaxy-nexus,0.5,1,")
    with ResultStore(tmp_path, {"a": 1}, COLS, trial_ids=range(5)) as st:
        assert st.done_ids == {0, 1, 2}
        assert st.set_aside == [(4, "trial_id 999 is not a trial of this study (this study's ids are 0..4)")]
        with pytest.raises(ValueError, match="not a trial of this study"):
            st.append(_rows([5]))
    assert "results.csv line 4: trial_id 999" in capsys.readouterr().err
    with ResultStore(tmp_path / "any", {"a": 1}, COLS) as st:  # without the ids any non-negative id is a trial
        st.append(_rows([999]))
        assert st.done_ids == {999}


def test_one_id_with_different_values_sets_both_rows_aside(tmp_path, capsys):
    _with_line(tmp_path, b"1,11,galaxy-nexus,0.5,1,")  # trial 1 again (line 3), with another value
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {0, 2}
        assert [n for n, _ in st.set_aside] == [3, 4]
        assert "different values" in st.set_aside[0][1] and "also on line 3" in st.set_aside[1][1]
        st.append(_rows([1]))  # so trial 1 runs again
    assert "line 3:" in capsys.readouterr().err
    by = {r["trial_id"]: r for r in read_rows(tmp_path / "results.csv")}
    assert sorted(by) == [0, 1, 2] and by[1]["value"] == _rows([1])[0]["value"]


def test_an_exact_repeat_sets_the_later_copy_aside(tmp_path):
    lines = _with_line(tmp_path, b"").split(b"\n")
    (tmp_path / "results.csv").write_bytes(b"\n".join([*lines[:3], lines[2], *lines[3:]]))  # line 3 again as line 4
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {0, 1, 2}
        assert st.set_aside == [(4, "repeats the row of trial_id 1 on line 3")]
    assert [r["trial_id"] for r in read_rows(tmp_path / "results.csv")] == [0, 1, 2]


def test_declared_text_columns_make_every_other_column_numeric(tmp_path):
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        st.append([{"trial_id": 0, "value": "@@@"}])  # one row: no majority to infer a type from
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {0}
    with ResultStore(tmp_path, {"a": 1}, COLS, text_columns=["camera", "reason"]) as st:
        assert st.done_ids == set() and st.set_aside == [(2, "value '@@@' is not a number")]


def test_a_wrong_header_is_refused_with_file_and_line(tmp_path):
    ResultStore(tmp_path, {"a": 1}, COLS)
    other = b"trial_id,seed,range_m\n0,10,5.0\n"  # another study's results
    (tmp_path / "results.csv").write_bytes(other)
    with pytest.raises(InputError, match=r"results.csv' line 1: the header is 'trial_id,seed,range_m'.*another study"):
        ResultStore(tmp_path, {"a": 1}, COLS).open()
    with pytest.raises(InputError, match="line 1: the header"):
        read_rows(tmp_path / "results.csv", COLS)
    assert (tmp_path / "results.csv").read_bytes() == other  # refused, not changed
    assert not (tmp_path / "results.rejected.csv").exists()
    (tmp_path / "results.csv").write_bytes(b"")
    ResultStore(tmp_path, {"a": 1}, COLS).open().close()  # the refusal released the lock


def test_reading_refuses_a_malformed_row_and_changes_nothing(tmp_path):
    _with_line(tmp_path, b"999,this,is,not,a,row,@@@")
    before = (tmp_path / "results.csv").read_bytes()
    with pytest.raises(InputError, match=r"results.csv' has 1 malformed row: line 4: 7 fields where .*set them aside"):
        read_rows(tmp_path / "results.csv")
    with pytest.raises(InputError, match="line 4"):
        read_table(tmp_path / "results.csv", COLS)
    assert (tmp_path / "results.csv").read_bytes() == before


def test_a_torn_last_line_is_still_repaired_silently(tmp_path, capsys):
    _with_line(tmp_path, b"x,garbage")
    with open(tmp_path / "results.csv", "ab") as fh:
        fh.write(b"3,13,galaxy-nexus,0.30000")  # torn: no newline
    with ResultStore(tmp_path, {"a": 1}, COLS) as st:
        assert st.done_ids == {0, 1, 2}
        assert [n for n, _ in st.set_aside] == [4]  # the garbage line; the torn tail is no malformed row
    err = capsys.readouterr().err
    assert "line 4" in err and "0.30000" not in err and "line 6" not in err
    assert [r["row"] for r in _rejected(tmp_path)] == ["x,garbage"]
    assert (tmp_path / "results.csv").read_bytes().endswith(b"\n")


@pytest.mark.slow
def test_a_campaign_rerun_sets_a_garbage_line_aside_and_completes(tmp_path, capsys):
    from svgs_sim.cli.main import main

    def campaign(out):
        return main(["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "3",
                     "--ranges", "5", "--processes", "0", "--no-progress", "--out", str(out)])

    assert campaign(tmp_path / "clean") == 0
    assert campaign(tmp_path / "hurt") == 0
    results = tmp_path / "hurt" / "results.csv"
    with open(results, "a") as fh:
        fh.write("999,this,is,not,a,row,@@@\n")  # header + 3 trials: this is line 5
    capsys.readouterr()
    assert campaign(tmp_path / "hurt") == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"{results} line 5: 7 fields where the header has" in err
    assert [r["row"] for r in _rejected(tmp_path / "hurt")] == ["999,this,is,not,a,row,@@@"]

    def numbers(path):  # all but the timings
        return [{k: v for k, v in r.items() if k not in ("wall_s", "cpu_s")} for r in read_rows(path)]

    assert [r["trial_id"] for r in read_rows(results)] == [0, 1, 2]
    assert numbers(results) == numbers(tmp_path / "clean" / "results.csv")
    assert (tmp_path / "hurt" / "summary.csv").read_text() == (tmp_path / "clean" / "summary.csv").read_text()
    # a row that damages a trial's own row: set aside, and that trial runs again
    text = results.read_text().replace("\n1,", "\n1,x", 1)
    results.write_text(text)
    assert campaign(tmp_path / "hurt") == 0
    assert f"{results} line 3: seed 'x" in capsys.readouterr().err
    assert numbers(results) == numbers(tmp_path / "clean" / "results.csv")
    # another study's file is refused: exit 2, the file and line 1 named
    results.write_text("trial_id,seed,range_m\n0,1,5.0\n")
    assert campaign(tmp_path / "hurt") == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"{results}' line 1: the header is" in err


def test_a_store_without_a_parameter_added_since_is_upgraded_with_its_default(tmp_path, capsys):
    """A study folder written before its trial kind gained a parameter resumes: the new column is
    filled with the parameter's default in every stored row (which is what those trials ran with),
    every other value's text unchanged; a store that lacks a column not declared as added, or has
    one the study does not write, is still refused."""
    old_cols = ["trial_id", "seed", "range_m", "err_x_m"]
    with ResultStore(tmp_path / "s", {"n": 2}, old_cols) as store:
        store.append([{"trial_id": 0, "seed": 5, "range_m": 5.0, "err_x_m": 0.1},
                      {"trial_id": 1, "seed": 6, "range_m": 10.0, "err_x_m": 0.30000000000000004}])
    new_cols = ["trial_id", "seed", "range_m", "environment", "err_x_m"]
    with pytest.raises(InputError, match="environment"):  # not declared as added: another study
        ResultStore(tmp_path / "s", {"n": 2}, new_cols)
    with pytest.raises(InputError, match="different parameters"):  # a column dropped is never an upgrade
        ResultStore(tmp_path / "s", {"n": 2}, ["trial_id", "seed", "environment"], added_columns={"environment": "0.0"})
    with ResultStore(tmp_path / "s", {"n": 2}, new_cols, added_columns={"environment": "0.0", "other": "1"}) as store:
        assert store.done_ids == {0, 1}
        assert "environment added with environment = 0.0" in capsys.readouterr().err
    assert (tmp_path / "s" / "results.csv").read_text().splitlines() == [
        "trial_id,seed,range_m,environment,err_x_m", "0,5,5.0,0.0,0.1", "1,6,10.0,0.0,0.30000000000000004"]
    assert json.loads((tmp_path / "s" / "manifest.json").read_text())["columns"] == new_cols
    with ResultStore(tmp_path / "s", {"n": 2}, new_cols, added_columns={"environment": "0.0"}) as store:
        assert store.done_ids == {0, 1} and capsys.readouterr().err == ""  # upgraded once
