"""An append-only, crash-safe results store for one study directory.

Layout of ``DIR``::

    manifest.json          the study's parameters (what the trials are); written once, atomically
    results.csv            one row per finished trial, in completion order, keyed by ``trial_id``
    results.rejected.csv   malformed rows set aside by :meth:`ResultStore.open` (only if there were any)
    .lock                  held (``flock``) while a run writes, so two runs cannot share DIR

Guarantees
    - Rows are appended as trials finish: each batch of rows is one ``write`` of complete
      lines followed by ``fsync``. A run killed at any instant (SIGKILL, power loss after the
      fsync) loses at most the trials whose rows were not yet written.
    - A torn last line (a write cut short) is detected on the next open (the file does not
      end with a newline) and cut off silently; those trials are simply run again.
    - A rerun skips every ``trial_id`` already present; a trial never appears twice.
    - A rerun whose parameters differ from ``manifest.json`` is refused with the list of
      differences (:class:`~svgs_sim.base.errors.InputError`) before any work starts.
    - A malformed row is never counted as a result (see below).
    - A store made by a run that ends before its first row is stored (refused, or stopped at
      once) is removed again when it closes (:meth:`ResultStore.close`): a refused run leaves
      nothing behind, and the corrected rerun into the same folder runs.

Malformed rows
    Every complete data row is checked on open and on read: it has one field per column,
    its ``trial_id`` is a non-negative integer (one of the study's ids when the store is
    given ``trial_ids``), its ``seed`` (if not empty) is an integer, numeric columns hold
    numbers (or are empty), and no ``trial_id`` appears twice. The numeric columns are all
    but ``text_columns`` when those are given; otherwise :meth:`ResultStore.open` takes a
    column as numeric when most of its non-empty values are numbers (reads do not guess).

    - *Set aside* (resumable): :meth:`ResultStore.open` moves malformed rows to
      ``results.rejected.csv`` (columns ``line``, ``problem``, ``row``: the original line
      number, what is wrong, the line's text), rewrites ``results.csv`` without them
      (atomically) and warns on stderr with the file and line of each. Their trials are not
      done, so they run again. Of two rows with one ``trial_id`` and different values both
      are set aside; an exact repeat sets aside the later copy.
    - *Refused* (:class:`~svgs_sim.base.errors.InputError`, CLI exit 2): a header that is not the
      study's columns (another study's file, or a damaged one), and any malformed row met by
      :func:`read_rows` / :func:`read_table`, which only read and never move rows.

Values are written with ``repr`` so floats round-trip exactly: a resumed study reads back
bit-identical numbers. Empty fields are ``None``/NaN.
"""

from __future__ import annotations

import csv
import fcntl
import io
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.jsonable import to_jsonable

MANIFEST = "manifest.json"
RESULTS = "results.csv"
#: Where :meth:`ResultStore.open` sets malformed rows aside.
REJECTED = "results.rejected.csv"
LOCK = ".lock"
#: Malformed rows named one by one in a warning or error (the rest are counted).
MAX_WARNINGS = 10
#: Bumped when the on-disk layout changes. A store of an older format is read in the current
#: layout (:func:`read_rows`) and upgraded on disk when its study is run again
#: (:class:`ResultStore`); a store of a newer format is refused.
#:
#: - 1 -> 2: the test stand's rail position got its own column, ``rail_m`` (after ``range_m``).
#:   Format 1 held it in ``range_m`` on rows with ``stand = 1``; ``range_m`` is now only the
#:   boresight distance, empty on stand rows, and ``rail_m`` is empty on the others.
FORMAT_VERSION = 2


def _jsonable(obj):
    """Plain JSON types for a manifest (:func:`svgs_sim.base.jsonable.to_jsonable`: numpy values as Python
    ones, tuples as lists, NaN kept; a value of another type is left for ``json`` to refuse)."""
    return to_jsonable(obj, other=None)


def _format(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "1" if value else "0"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return "" if math.isnan(v) else repr(v)
    s = str(value)
    if "\n" in s or "\r" in s:
        raise ValueError(f"results store: a text field may not contain a newline: {s!r}")
    return s


def cell_text(value) -> str:
    """How a row writes ``value`` in ``results.csv`` (``repr`` of a float, empty for None/NaN)."""
    return _format(value)


def _parse(text: str):
    if text == "":
        return None
    try:
        v = float(text)
    except ValueError:
        return text
    if not any(c in text for c in ".eEnNiI"):  # an integer (exact: float has 53 bits)
        try:
            return int(text)
        except ValueError:
            pass
    return v


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _describe_ids(ids) -> str:
    ids = sorted(ids)
    if not ids:
        return "this study has no trials"
    if ids == list(range(ids[0], ids[-1] + 1)):
        return f"this study's ids are {ids[0]}..{ids[-1]}"
    return f"not one of this study's {len(ids)} ids"


def _check_lines(lines, columns, *, first_line: int = 2, trial_ids=None, text_columns=None, infer: bool = False):
    """Check the data lines of a ``results.csv``; split them into good rows and malformed ones.

    Parameters
    ----------
    lines : list of bytes
        Complete data lines without their newline (the header excluded).
    columns : list of str
        The header's columns (the first is ``trial_id``).
    first_line : int
        File line number of ``lines[0]`` (the header is line 1).
    trial_ids : collection of int, optional
        The study's trial ids; a row with another id is malformed.
    text_columns : collection of str, optional
        Columns that may hold text; every other column must be empty or a number.
    infer : bool
        Without ``text_columns``, take a column as numeric when most of its non-empty
        values are numbers (a stray word among numbers is then malformed).

    Returns
    -------
    good : list of (int, list of str)
        File line number and fields of each well-formed row, in file order.
    bad : list of (int, str, bytes)
        File line number, the problem and the raw line of each malformed row.
    """
    n = len(columns)
    ids = None if trial_ids is None else {int(i) for i in trial_ids}
    seed_col = columns.index("seed") if "seed" in columns else None
    bad, rows = [], []
    for k, raw in enumerate(lines):
        line_no = first_line + k
        if not raw.strip():
            continue  # a blank line holds no row
        fields, problem = _split_line(raw, n, ids, seed_col)
        if problem is not None:
            bad.append((line_no, problem, raw))
        else:
            rows.append((line_no, fields, raw))
    numeric = _numeric_columns(columns, rows, text_columns, infer)
    typed = []
    for line_no, fields, raw in rows:
        wrong = next((j for j in numeric if fields[j] != "" and not _is_number(fields[j])), None)
        if wrong is not None:
            bad.append((line_no, f"{columns[wrong]} {fields[wrong]!r} is not a number", raw))
        else:
            typed.append((line_no, fields, raw))
    good = _one_row_per_trial(typed, bad)
    bad.sort(key=lambda b: b[0])
    return [(line_no, fields) for line_no, fields, _ in good], bad


def _split_line(raw: bytes, n: int, ids, seed_col):
    """Split one data line of a ``results.csv`` into its fields, or say what is wrong with it.

    Parameters
    ----------
    raw : bytes
        The line, without its newline (not blank).
    n : int
        Number of columns in the header.
    ids : set of int or None
        The study's trial ids (None: any non-negative id).
    seed_col : int or None
        Index of the ``seed`` column, if any.

    Returns
    -------
    fields : list of str or None
        The ``n`` fields; None when the line is malformed.
    problem : str or None
        What is wrong with the line; None when it is well formed.
    """
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        return None, "not UTF-8 text"
    try:
        fields = next(csv.reader((text,), strict=True), [])
    except csv.Error as exc:
        return None, f"not a CSV row ({exc})"
    if len(fields) != n:
        return None, f"{len(fields)} fields where the header has {n}"
    tid = fields[0]
    if not tid.isascii() or not tid.isdigit():
        return None, f"trial_id {tid!r} is not a non-negative integer"
    if ids is not None and int(tid) not in ids:
        return None, f"trial_id {int(tid)} is not a trial of this study ({_describe_ids(ids)})"
    if seed_col is not None and fields[seed_col] != "" and not isinstance(_parse(fields[seed_col]), int):
        return None, f"seed {fields[seed_col]!r} is not an integer"
    return fields, None


def _numeric_columns(columns, rows, text_columns, infer: bool) -> list[int]:
    """Indices of the columns that must hold numbers (see :func:`_check_lines`).

    Parameters
    ----------
    columns : list of str
        The header's columns.
    rows : list of (int, list of str, bytes)
        Line number, fields and raw line of each row that split cleanly.
    text_columns : collection of str or None
        Columns that may hold text (all others are numeric).
    infer : bool
        Without ``text_columns``: a column is numeric when most of its non-empty values are numbers.

    Returns
    -------
    list of int
        Column indices, ascending.
    """
    if text_columns is not None:
        return [j for j, c in enumerate(columns) if c not in set(text_columns)]
    numeric = []
    if infer:
        for j in range(1, len(columns)):
            vals = [f[j] for _, f, _ in rows if f[j] != ""]
            n_num = sum(_is_number(v) for v in vals)
            if n_num > len(vals) - n_num:
                numeric.append(j)
    return numeric


def _one_row_per_trial(typed, bad: list) -> list:
    """Keep one row per ``trial_id``; append repeated and conflicting rows to ``bad``.

    A row that repeats an earlier one exactly is dropped; when two rows of one id differ, all
    rows of that id are malformed.

    Parameters
    ----------
    typed : list of (int, list of str, bytes)
        Line number, fields and raw line of each otherwise well-formed row, in file order.
    bad : list of (int, str, bytes)
        Malformed rows so far; extended in place.

    Returns
    -------
    list of (int, list of str, bytes)
        The kept rows, in file order.
    """
    first: dict[int, tuple[int, list]] = {}
    conflicting: set[int] = set()
    good = []
    for line_no, fields, raw in typed:
        tid = int(fields[0])
        if tid not in first:
            first[tid] = (line_no, fields)
            good.append((line_no, fields, raw))
        elif first[tid][1] == fields:
            bad.append((line_no, f"repeats the row of trial_id {tid} on line {first[tid][0]}", raw))
        else:
            conflicting.add(tid)
            bad.append((line_no, f"trial_id {tid} is also on line {first[tid][0]}, with different values", raw))
    if conflicting:
        for line_no, fields, raw in good:
            tid = int(fields[0])
            if tid in conflicting:
                bad.append((line_no, f"trial_id {tid} appears again later with different values", raw))
        good = [g for g in good if int(g[1][0]) not in conflicting]
    return good


def _diff(a: dict, b: dict, prefix: str = "") -> list[str]:
    out = []
    for k in sorted(set(a) | set(b)):
        key = f"{prefix}{k}"
        if k not in a:
            out.append(f"{key}: (absent) -> {b[k]!r}")
        elif k not in b:
            out.append(f"{key}: {a[k]!r} -> (absent)")
        elif isinstance(a[k], dict) and isinstance(b[k], dict):
            out.extend(_diff(a[k], b[k], key + "."))
        elif isinstance(a[k], list) and isinstance(b[k], list) and len(a[k]) + len(b[k]) > 12 and a[k] != b[k]:
            add = [x for x in b[k] if x not in a[k]]
            rem = [x for x in a[k] if x not in b[k]]
            out.append(f"{key}: " + " ".join(x for x in (f"added {add}" if add else "", f"removed {rem}" if rem else "") if x)
                       + ("" if add or rem else "same entries in another order"))
        elif a[k] != b[k]:
            out.append(f"{key}: {a[k]!r} -> {b[k]!r}")
    return out


def _is_format1_header(columns) -> bool:
    """A header of format 1 with the stand's rail position in ``range_m`` (see :data:`FORMAT_VERSION`)."""
    return "range_m" in columns and "stand" in columns and "rail_m" not in columns


def upgraded_columns(columns) -> list:
    """``columns`` of a format-1 store in the current layout (``rail_m`` after ``range_m``);
    current columns come back unchanged."""
    cols = list(columns)
    if _is_format1_header(cols):
        cols.insert(cols.index("range_m") + 1, "rail_m")
    return cols


def upgraded_fields(header, fields) -> list:
    """One format-1 row's fields (text, as in the file) in the current layout: on a stand row
    (``stand`` is 1) the ``range_m`` text moves to ``rail_m``; otherwise ``rail_m`` is empty.
    The text is moved, never reformatted, so the numbers are the same bits. A row of another
    header, or with the wrong number of fields (malformed either way), comes back unchanged."""
    header, fields = list(header), list(fields)
    if not _is_format1_header(header) or len(fields) != len(header):
        return fields
    i = header.index("range_m")
    on_stand = _parse(fields[header.index("stand")]) == 1
    distance = fields[i]
    fields[i] = "" if on_stand else distance
    fields.insert(i + 1, distance if on_stand else "")
    return fields


def _current_manifest(have):
    """A stored manifest as the current format would write it (in memory; see :func:`_upgrade_store`)."""
    if not isinstance(have, dict) or have.get("format_version") != 1:
        return have
    out = {**have, "format_version": FORMAT_VERSION}
    if isinstance(have.get("columns"), list):
        out["columns"] = upgraded_columns(have["columns"])
    return out


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _with_added_columns(have, columns, added):
    """A stored manifest whose columns are ``columns`` but for some of ``added`` (the columns a newer
    version of the study writes, a parameter with its default), with those columns in: the stored
    rows then read as rows of ``columns`` (:func:`_upgrade_store`). Any other difference is kept,
    and refused by the comparison."""
    if not added or not isinstance(have, dict) or not isinstance(have.get("columns"), list) or columns is None:
        return have
    cols, want = have["columns"], list(columns)
    missing = [c for c in want if c not in cols]
    if not missing or set(missing) - set(added) or [c for c in want if c in cols] != cols:
        return have
    return {**have, "columns": want}


def _with_added_parameters(have, parameters, added):
    """A stored manifest with the study parameters a newer version added (a trial kind's new
    parameter, e.g. a scene quantity, in ``added``) filled in where ``parameters`` (the requested
    ones) hold that parameter's default: a study stored before the parameter existed ran with it."""
    if not added or not isinstance(have, dict) or not isinstance(have.get("parameters"), dict) \
            or not isinstance(parameters, dict):
        return have
    fill = {k: v for k, v in parameters.items() if k not in have["parameters"] and k in added and _format(v) == added[k]}
    return {**have, "parameters": {**have["parameters"], **fill}} if fill else have


def _upgrade_store(out_dir: Path, columns=None, added=None, parameters=None) -> bool:
    """Rewrite an older store in ``out_dir`` in the current layout: the current format (see
    :data:`FORMAT_VERSION`) and, given ``columns`` and ``added`` (column -> the text a row written
    before that column existed stands for: the parameter's default), the columns a newer version
    of the study added. ``results.csv`` first (its complete lines, each value's text moved, never
    reformatted; a torn tail is dropped, as :meth:`ResultStore.open` would), then
    ``manifest.json``, each atomically. A crash between the two leaves a results file already
    upgraded, which the next upgrade recognises by its header. Returns whether anything was
    rewritten."""
    path = out_dir / MANIFEST
    have = json.loads(path.read_text())
    new = _with_added_parameters(_with_added_columns(_current_manifest(have), columns, added), parameters, added)
    if new == have:
        return False
    results = out_dir / RESULTS
    moved = isinstance(have.get("columns"), list) and _is_format1_header(have["columns"])
    target = new.get("columns")
    if results.exists() and isinstance(target, list):
        data = results.read_bytes().replace(b"\r\n", b"\n")
        lines = data.split(b"\n")[:-1]
        header = next(csv.reader((lines[0].decode("utf-8", errors="replace"),)), []) if lines else []
        if lines and header != target:
            current = upgraded_columns(header)
            buf = io.StringIO()
            w = csv.writer(buf, lineterminator="\n")
            w.writerow(target)
            for raw in lines[1:]:
                try:
                    fields = next(csv.reader((raw.decode("utf-8"),), strict=True), [])
                except (UnicodeDecodeError, csv.Error):
                    fields = None
                if fields is None or len(fields) != len(header):
                    buf.write(raw.decode("utf-8", errors="surrogateescape") + "\n")  # malformed: kept as is
                    continue
                row = dict(zip(current, upgraded_fields(header, fields)))
                w.writerow([row[c] if c in row else (added or {}).get(c, "") for c in target])
            _write_atomic(results, buf.getvalue().encode("utf-8", errors="surrogateescape"))
    _write_atomic(path, (json.dumps(new, indent=2, sort_keys=True) + "\n").encode())
    _fsync_dir(out_dir)
    what = []
    if moved:
        what.append("the stand's rail position moved from range_m to its own column rail_m")
    extra = [c for c in (target or ()) if c not in upgraded_columns(have.get("columns") or [])]
    params = sorted(set(new.get("parameters") or {}) - set(have.get("parameters") or {}))
    if params:
        what.append(f"parameter{'s' if len(params) > 1 else ''} {', '.join(params)} recorded at the default")
    if extra:
        what.append(f"column{'s' if len(extra) > 1 else ''} {', '.join(extra)} added with "
                    + ", ".join(f"{c} = {added[c] or 'empty'}" for c in extra) + " in every stored row")
    old = have.get("format_version")
    change = (f"a store of format {old} upgraded to format {FORMAT_VERSION}" if old != FORMAT_VERSION
              else "a store upgraded to this version's columns")
    _warn(f"{out_dir}: {change} ({'; '.join(what) or 'no column changed'}; no stored value changed)")
    return True


def _refuse_other_study(out_dir: Path, want: dict, ignore=(), added=None) -> None:
    """:class:`InputError` when ``out_dir``'s manifest is unreadable or differs from ``want`` (a
    full manifest: format, parameters, columns) in anything but the parameters in ``ignore`` and
    the columns in ``added`` that it lacks (see :func:`_upgrade_store`)."""
    path = Path(out_dir) / MANIFEST
    try:
        have = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"--out: {str(path)!r} is not a readable study manifest ({exc}); "
                         "choose another --out directory") from None
    version = have.get("format_version") if isinstance(have, dict) else None
    if isinstance(version, int) and version > FORMAT_VERSION:
        raise InputError(f"--out: {str(out_dir)!r} holds a study of results-store format {version}, written by a "
                         f"newer svgs-sim (this one reads formats 1 to {FORMAT_VERSION}); upgrade svgs-sim or "
                         "choose another --out directory")
    have = _with_added_columns(_current_manifest(have), want.get("columns"), added)
    have = _with_added_parameters(have, want.get("parameters"), added)
    if ignore and isinstance(have, dict) and isinstance(have.get("parameters"), dict):
        have = {**have, "parameters": {k: v for k, v in have["parameters"].items() if k not in ignore}}
        want = {**want, "parameters": {k: v for k, v in want["parameters"].items() if k not in ignore}}
    diffs = _diff(have, want)
    if diffs:
        raise InputError(
            f"--out: {str(out_dir)!r} holds a study with different parameters, so its results cannot be "
            f"resumed or extended by this run. Differences (stored -> requested): {'; '.join(diffs[:12])}. "
            "Rerun with the stored parameters to resume, or choose another --out directory."
        )


#: Files a study writes into its folder beside its store: in a folder without a study's manifest
#: they are someone else's (a user's own report), and a study would overwrite them (issue 41).
STUDY_OUTPUT_NAMES = frozenset({RESULTS, "report.html", "report.md", "summary.csv", "summary.json", "summary.md",
                                "verdicts.csv", "budget.csv", "honest_count.json", "indices.csv", "merge_ranges.csv",
                                "trials.csv", "measurements.csv"})


def refuse_foreign_outputs(out_dir) -> None:
    """:class:`InputError` when ``out_dir`` holds files a study would write (:data:`STUDY_OUTPUT_NAMES`)
    but no study's manifest: they are not a study's, and nothing may overwrite them.

    Parameters
    ----------
    out_dir : str or Path
        A study's folder (it may not exist yet).
    """
    out_dir = Path(out_dir)
    if not out_dir.is_dir() or (out_dir / MANIFEST).exists():
        return
    theirs = sorted(p.name for p in out_dir.iterdir() if p.name in STUDY_OUTPUT_NAMES)
    if theirs:
        raise InputError(f"--out: {str(out_dir)!r} holds {', '.join(theirs)} but no {MANIFEST}: files no study made, "
                         "which a study would overwrite; choose another --out directory or move them")


def check_resumable(out_dir, manifest: dict, columns=None, *, ignore=(), added_columns=None) -> bool:
    """Whether ``out_dir`` holds this study's store, refusing one with other parameters - as
    :class:`ResultStore` would, but without making, changing or locking anything (a study checks
    it before work that comes before its store, and before it writes beside the store).

    Parameters
    ----------
    out_dir : str or Path
    manifest : dict
        The study's parameters (as given to :class:`ResultStore`).
    columns : sequence of str, optional
        The store's columns; None: not compared (not known yet).
    ignore : collection of str
        Parameters not compared (decided by work still to come).
    added_columns : mapping of str -> str, optional
        As for :class:`ResultStore`.

    Returns
    -------
    bool
        True: ``out_dir`` holds a store with these parameters; False: no store there.

    Raises
    ------
    InputError
        A store with other parameters (the same message as :class:`ResultStore`), an unreadable
        manifest, or a results file without a manifest.
    """
    out_dir = Path(out_dir)
    if not (out_dir / MANIFEST).exists():
        refuse_foreign_outputs(out_dir)
        return False
    want = {"format_version": FORMAT_VERSION, "parameters": _jsonable(dict(manifest)),
            "columns": None if columns is None else list(columns)}
    if columns is None:
        try:
            want["columns"] = _current_manifest(json.loads((out_dir / MANIFEST).read_text())).get("columns")
        except (OSError, ValueError, AttributeError):
            pass  # refused as unreadable below
    _refuse_other_study(out_dir, want, ignore, added_columns)
    return True


def _missing_dirs(path: Path) -> list[Path]:
    """The folders of ``path`` (itself included) that do not exist yet, outermost first."""
    missing = []
    q = Path(path).absolute()
    while not q.exists() and q != q.parent:
        missing.append(q)
        q = q.parent
    return missing[::-1]


class ResultStore:
    """The results of one study in directory ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Study directory (created if needed).
    manifest : dict
        The study's parameters - everything that decides *what* the trials compute (command,
        camera, trial kind, seed, trial count, ...), but nothing that only decides *how*
        (worker count, executor). JSON-serialisable.
    columns : sequence of str
        Column names; the first must be ``trial_id``.
    trial_ids : collection of int, optional
        The study's trial ids. When given, a stored row with another id is malformed (set
        aside on :meth:`open`) and :meth:`append` refuses one. Otherwise any non-negative
        integer id is accepted.
    text_columns : collection of str, optional
        Columns that may hold text; all others must hold numbers. When not given,
        :meth:`open` infers the numeric columns from the stored rows (see the module
        docstring).
    added_columns : mapping of str -> str, optional
        Columns a newer version of the study added (a trial kind's new parameter), each with
        the text a row stored before it existed stands for (the parameter's default, as a row
        writes it). A store that lacks only some of them is rewritten with them filled in when
        opened (a warning says so); without this, it is refused as another study's.

    Raises
    ------
    InputError
        ``out_dir`` holds a study with other parameters or columns, or another run holds it.

    Attributes
    ----------
    set_aside : list of (int, str)
        Line number in ``results.csv`` and problem of each malformed row the last
        :meth:`open` moved to ``results.rejected.csv``.
    """

    def __init__(self, out_dir, manifest: dict, columns, *, trial_ids=None, text_columns=None, added_columns=None):
        self.dir = Path(out_dir)
        self.added_columns = dict(added_columns or {})
        self.columns = list(columns)
        if not self.columns or self.columns[0] != "trial_id":
            raise ValueError("results store: the first column must be 'trial_id'")
        if len(set(self.columns)) != len(self.columns):
            raise ValueError(f"results store: duplicate column names in {self.columns}")
        self.trial_ids = None if trial_ids is None else frozenset(int(i) for i in trial_ids)
        self.text_columns = None if text_columns is None else frozenset(text_columns)
        if self.text_columns is not None and {"trial_id", "seed"} & self.text_columns:
            raise ValueError("results store: trial_id and seed are integer columns, not text columns")
        self.set_aside: list[tuple[int, str]] = []
        self.manifest = _jsonable(dict(manifest))
        self._lock_fd = None
        self._fd = None
        self._done: set[int] = set()
        self._fresh = False  # this store wrote the manifest: it holds nothing from an earlier run
        if self.dir.exists() and not self.dir.is_dir():
            raise InputError(f"--out: {str(self.dir)!r} exists and is not a directory")
        self._made_dirs = _missing_dirs(self.dir)
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"--out: cannot create directory {str(self.dir)!r}: {exc}") from None
        self._check_manifest()

    # ------------------------------------------------------------------ manifest
    @property
    def manifest_path(self) -> Path:
        return self.dir / MANIFEST

    @property
    def results_path(self) -> Path:
        return self.dir / RESULTS

    @property
    def rejected_path(self) -> Path:
        return self.dir / REJECTED

    def _full_manifest(self) -> dict:
        return {"format_version": FORMAT_VERSION, "parameters": self.manifest, "columns": self.columns}

    def _check_manifest(self) -> None:
        want = self._full_manifest()
        if self.manifest_path.exists():
            _refuse_other_study(self.dir, want, added=self.added_columns)  # in the current layout, then upgraded
            self._upgrade()
        else:
            refuse_foreign_outputs(self.dir)
            tmp = self.manifest_path.with_suffix(".json.tmp")
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(want, fh, indent=2, sort_keys=True)
                fh.write("\n")
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.manifest_path)
            _fsync_dir(self.dir)
            self._fresh = True

    def _upgrade(self) -> None:
        """Rewrite this study's older-format store in the current format, under the directory lock."""
        lock_fd = os.open(self.dir / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            try:
                fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                raise InputError(f"--out: another run is writing to {str(self.dir)!r}; wait for it or choose "
                                 "another --out") from None
            _upgrade_store(self.dir, self.columns, self.added_columns, _jsonable(self.manifest))
        finally:
            os.close(lock_fd)

    # ------------------------------------------------------------------ open / close
    def open(self) -> ResultStore:
        """Take the directory lock, repair a torn tail, set malformed rows aside, read the finished ids.

        Malformed rows are moved to ``results.rejected.csv`` with a warning on stderr naming
        ``results.csv`` and the line (see the module docstring); they are not counted as done.

        Raises
        ------
        InputError
            Another run holds the directory, or the header of ``results.csv`` is not this
            study's columns.
        """

        if self._fd is not None:
            return self
        lock_fd = os.open(self.dir / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(lock_fd)
            raise InputError(f"--out: another run is writing to {str(self.dir)!r}; wait for it or choose another --out") from None
        self._lock_fd = lock_fd
        header = (",".join(self.columns) + "\n").encode()
        path = self.results_path
        if not path.exists() or path.stat().st_size == 0:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            _write_all(fd, header)
            os.fsync(fd)
            os.close(fd)
            _fsync_dir(self.dir)
        data = path.read_bytes()
        if b"\r\n" in data:  # saved with Windows line endings (an editor): rewritten with \n, rows kept
            data = data.replace(b"\r\n", b"\n")
            tmp = path.with_suffix(".csv.tmp")
            with open(tmp, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
            _fsync_dir(self.dir)
            _warn(f"{path}: Windows line endings (CRLF) rewritten as \\n; its rows are kept")
        if not data.endswith(b"\n"):  # a torn final write: drop the partial line
            keep = data.rfind(b"\n") + 1
            with open(path, "r+b") as fh:
                fh.truncate(keep)
                if keep == 0:  # even the header was torn
                    fh.write(header)
                fh.flush()
                os.fsync(fh.fileno())
            data = data[:keep] if keep else header
        if not data.startswith(header):
            first = data.split(b"\n", 1)[0].decode(errors="replace")
            self.close()
            raise InputError(f"--out: {str(path)!r} line 1: the header is {first!r}, but this study writes "
                             f"{header.decode().strip()!r} (the file belongs to another study or is damaged); "
                             "choose another --out directory")
        lines = data[len(header):].split(b"\n")[:-1]
        good, bad = _check_lines(lines, self.columns, trial_ids=self.trial_ids, text_columns=self.text_columns,
                                 infer=True)
        self.set_aside = [(line_no, problem) for line_no, problem, _ in bad]
        if bad:
            try:
                self._set_aside(header, lines, bad)
            except BaseException:
                self.close()
                raise
        self._done = {int(fields[0]) for _, fields in good}
        self._fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        return self

    def _set_aside(self, header: bytes, lines: list, bad: list) -> None:
        """Append the malformed rows to ``results.rejected.csv``; rewrite ``results.csv`` without them."""
        rejected = self.rejected_path
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        if not rejected.exists() or rejected.stat().st_size == 0:
            w.writerow(["line", "problem", "row"])
        for line_no, problem, raw in bad:
            w.writerow([line_no, problem, raw.decode("utf-8", errors="backslashreplace").replace("\r", "\\r")])
        with open(rejected, "ab") as fh:  # first keep the rows, then drop them from results.csv
            fh.write(buf.getvalue().encode())
            fh.flush()
            os.fsync(fh.fileno())
        drop = {line_no - 2 for line_no, _, _ in bad}
        tmp = self.results_path.with_suffix(".csv.tmp")
        with open(tmp, "wb") as fh:
            fh.write(header + b"".join(raw + b"\n" for k, raw in enumerate(lines) if k not in drop))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.results_path)
        _fsync_dir(self.dir)
        shown = bad[:MAX_WARNINGS]
        for line_no, problem, _ in shown:
            _warn(f"{self.results_path} line {line_no}: {problem}; moved to {REJECTED}, not counted as a result")
        if len(bad) > len(shown):
            _warn(f"{self.results_path}: {len(bad) - len(shown)} more malformed rows moved to {REJECTED}")
        _warn(f"{self.results_path}: {len(bad)} malformed row{'s' if len(bad) > 1 else ''} set aside (not counted "
              "as results); trials without a good row run again")

    def close(self) -> None:
        """Release the file and the lock. A store this run made that ends without a stored row (the
        run was refused or stopped before its first trial finished) is removed again - its
        ``manifest.json``, the empty ``results.csv``, ``.lock`` and the folders made for it - so
        that a corrected rerun into the same folder is not refused for other parameters. A
        folder holding anything else is kept as it is."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None
            if self._fresh and not self._done:
                self._remove_unused()

    def _remove_unused(self) -> None:
        """Remove this run's store files and folders when no row was stored (see :meth:`close`)."""
        header = len(",".join(self.columns)) + 1
        try:
            names = set(os.listdir(self.dir))
            if names - {MANIFEST, RESULTS, LOCK} or (RESULTS in names and self.results_path.stat().st_size > header):
                return  # something else is there (or a row): keep the study as it is
            for name in (RESULTS, MANIFEST, LOCK):
                if name in names:
                    (self.dir / name).unlink()
        except OSError:
            return
        self._fresh = False
        for d in reversed(self._made_dirs):
            try:
                d.rmdir()
            except OSError:
                return

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ rows
    @property
    def done_ids(self) -> set[int]:
        """Trial ids whose rows are stored."""
        return set(self._done)

    def append(self, rows) -> int:
        """Append finished trials' rows (one write + fsync); rows already stored are skipped.

        Parameters
        ----------
        rows : iterable of dict
            Each with a ``trial_id`` and only keys among :attr:`columns` (missing keys are
            written empty).

        Returns
        -------
        int
            Rows written.
        """
        if self._fd is None:
            raise RuntimeError("ResultStore.append before open()")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        new = []
        for row in rows:
            extra = set(row) - set(self.columns)
            if extra:
                raise ValueError(f"results store: row has keys not among the study's columns: {sorted(extra)}")
            tid = int(row["trial_id"])
            if self.trial_ids is not None and tid not in self.trial_ids:
                raise ValueError(f"results store: trial_id {tid} is not a trial of this study")
            if tid in self._done or tid in new:
                continue
            w.writerow([_format(row.get(c)) for c in self.columns])
            new.append(tid)
        if new:
            _write_all(self._fd, buf.getvalue().encode())
            os.fsync(self._fd)
            self._done.update(new)
        return len(new)

    def read_rows(self) -> list[dict]:
        """All stored rows, sorted by ``trial_id`` (a torn tail is ignored; see :func:`read_rows`)."""
        return read_rows(self.results_path, self.columns, trial_ids=self.trial_ids, text_columns=self.text_columns)

    def read_table(self) -> dict:
        """All stored rows as columns (see :func:`read_table`)."""
        return _table(self.read_rows(), self.columns)


def read_rows(path, columns=None, *, trial_ids=None, text_columns=None) -> list[dict]:
    """Rows of a ``results.csv``, sorted by ``trial_id``; values parsed as int, float or text.

    Reading never changes the file: a malformed row is refused, not skipped (opening the
    study's :class:`ResultStore`, i.e. rerunning its command, sets such rows aside).

    Parameters
    ----------
    path : str or Path
    columns : sequence of str, optional
        The header the file must have (default: whatever it has; its first column must be
        ``trial_id``).
    trial_ids : collection of int, optional
        The study's trial ids; a row with another id is malformed.
    text_columns : collection of str, optional
        Columns that may hold text; all others must hold numbers.

    Raises
    ------
    InputError
        If the file is missing, its header is wrong, or a complete row is malformed (the
        message names the file and line of each).
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"results file {str(path)!r} cannot be read: {exc}") from None
    # the part after the last newline is a torn write: ignored; Windows line endings are read as \n
    lines = data.replace(b"\r\n", b"\n").split(b"\n")[:-1]
    if not lines:
        return []
    try:
        header = next(csv.reader((lines[0].decode("utf-8"),), strict=True), [])
    except (UnicodeDecodeError, csv.Error):
        header = None
    old_header = header if header and _is_format1_header(header) else None
    if old_header:  # format 1: read in the current layout (see FORMAT_VERSION)
        header = upgraded_columns(old_header)
    if header is None or (columns is not None and header != list(columns)) or not header or header[0] != "trial_id":
        want = f"{','.join(columns)!r}" if columns is not None else "one starting with 'trial_id'"
        raise InputError(f"results file {str(path)!r} line 1: the header is "
                         f"{lines[0].decode(errors='replace')!r}, expected {want}")
    body = lines[1:]
    if old_header:
        body = [_upgraded_line(old_header, raw) for raw in body]
    good, bad = _check_lines(body, header, trial_ids=trial_ids, text_columns=text_columns)
    if bad:
        where = "; ".join(f"line {line_no}: {problem}" for line_no, problem, _ in bad[:MAX_WARNINGS])
        more = f" (and {len(bad) - MAX_WARNINGS} more)" if len(bad) > MAX_WARNINGS else ""
        raise InputError(f"results file {str(path)!r} has {len(bad)} malformed row{'s' if len(bad) > 1 else ''}: "
                         f"{where}{more}. Rerun the study's command to set them aside (into {REJECTED}; their "
                         "trials run again), or remove those lines")
    rows = [dict(zip(header, (_parse(x) for x in fields))) for _, fields in good]
    rows.sort(key=lambda r: r["trial_id"])
    return rows


def _upgraded_line(header, raw: bytes) -> bytes:
    """One data line of a format-1 file in the current layout (a line that does not parse is kept)."""
    try:
        fields = next(csv.reader((raw.decode("utf-8"),), strict=True), [])
    except (UnicodeDecodeError, csv.Error):
        return raw
    buf = io.StringIO()
    csv.writer(buf, lineterminator="").writerow(upgraded_fields(header, fields))
    return buf.getvalue().encode()


def read_table(path, columns=None, *, trial_ids=None, text_columns=None) -> dict:
    """Columns of a ``results.csv`` sorted by ``trial_id``.

    Parameters
    ----------
    path : str or Path
    columns : sequence of str, optional
        The columns returned (default: the file's); absent ones come back as NaN.
    trial_ids, text_columns
        As for :func:`read_rows`.

    Returns
    -------
    dict of str -> ndarray, shape (n_rows,)
        float64 for numeric columns (empty -> NaN), object for text columns.

    Raises
    ------
    InputError
        As :func:`read_rows`.
    """
    return _table(read_rows(path, trial_ids=trial_ids, text_columns=text_columns), columns)


def _table(rows: list, columns=None) -> dict:
    if columns is None:
        columns = list(rows[0]) if rows else []
    out = {}
    for c in columns:
        vals = [r.get(c) for r in rows]
        if all(v is None or isinstance(v, (int, float)) for v in vals):
            out[c] = np.array([np.nan if v is None else float(v) for v in vals], dtype=float)
        else:
            out[c] = np.array(vals, dtype=object)
    return out


def _warn(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr, flush=True)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
