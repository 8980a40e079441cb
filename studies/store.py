"""An append-only, crash-safe results store for one study directory.

Layout of ``DIR``::

    manifest.json    the study's parameters (what the trials are); written once, atomically
    results.csv      one row per finished trial, in completion order, keyed by ``trial_id``
    .lock            held (``flock``) while a run writes, so two runs cannot share DIR

Guarantees
    - Rows are appended as trials finish: each batch of rows is one ``write`` of complete
      lines followed by ``fsync``. A run killed at any instant (SIGKILL, power loss after the
      fsync) loses at most the trials whose rows were not yet written.
    - A torn last line (a write cut short) is detected on the next open (the file does not
      end with a newline) and cut off; those trials are simply run again.
    - A rerun skips every ``trial_id`` already present; a trial never appears twice.
    - A rerun whose parameters differ from ``manifest.json`` is refused with the list of
      differences (:class:`~svgs.errors.InputError`) before any work starts.

Values are written with ``repr`` so floats round-trip exactly: a resumed study reads back
bit-identical numbers. Empty fields are ``None``/NaN.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

import numpy as np

from svgs.errors import InputError

MANIFEST = "manifest.json"
RESULTS = "results.csv"
LOCK = ".lock"
#: Bumped when the on-disk layout changes.
FORMAT_VERSION = 1


def _jsonable(obj):
    """Turn numpy scalars/arrays and tuples into plain JSON types (for manifests)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_jsonable(v) for v in obj.tolist()]
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    return obj


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


def _parse(text: str):
    if text == "":
        return None
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


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

    Raises
    ------
    InputError
        ``out_dir`` holds a study with other parameters or columns, or another run holds it.
    """

    def __init__(self, out_dir, manifest: dict, columns):
        self.dir = Path(out_dir)
        self.columns = list(columns)
        if not self.columns or self.columns[0] != "trial_id":
            raise ValueError("results store: the first column must be 'trial_id'")
        if len(set(self.columns)) != len(self.columns):
            raise ValueError(f"results store: duplicate column names in {self.columns}")
        self.manifest = _jsonable(dict(manifest))
        self._lock_fd = None
        self._fd = None
        self._done: set[int] = set()
        if self.dir.exists() and not self.dir.is_dir():
            raise InputError(f"--out: {str(self.dir)!r} exists and is not a directory")
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

    def _full_manifest(self) -> dict:
        return {"format_version": FORMAT_VERSION, "parameters": self.manifest, "columns": self.columns}

    def _check_manifest(self) -> None:
        want = self._full_manifest()
        if self.manifest_path.exists():
            try:
                have = json.loads(self.manifest_path.read_text())
            except (OSError, ValueError) as exc:
                raise InputError(f"--out: {str(self.manifest_path)!r} is not a readable study manifest ({exc}); "
                                 "choose another --out directory") from None
            diffs = _diff(have, want)
            if diffs:
                raise InputError(
                    f"--out: {str(self.dir)!r} holds a study with different parameters, so its results cannot be "
                    f"resumed or extended by this run. Differences (stored -> requested): {'; '.join(diffs[:12])}. "
                    "Rerun with the stored parameters to resume, or choose another --out directory."
                )
        else:
            stray = [p.name for p in self.dir.iterdir() if p.name in (RESULTS,)]
            if stray:
                raise InputError(f"--out: {str(self.dir)!r} holds {stray[0]} but no {MANIFEST}; "
                                 "choose another --out directory")
            tmp = self.manifest_path.with_suffix(".json.tmp")
            with open(tmp, "w") as fh:
                json.dump(want, fh, indent=2, sort_keys=True)
                fh.write("\n")
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.manifest_path)
            _fsync_dir(self.dir)

    # ------------------------------------------------------------------ open / close
    def open(self) -> "ResultStore":
        """Take the directory lock, repair a torn tail, read the finished trial ids."""
        import fcntl

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
            raise InputError(f"--out: {str(path)!r} has columns {first!r}, this study writes {header.decode().strip()!r}; "
                             "choose another --out directory")
        self._done = {int(r[0]) for r in csv.reader(io.StringIO(data[len(header):].decode())) if r}
        self._fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        return self

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None

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
        """All stored rows, sorted by ``trial_id`` (a torn tail is ignored)."""
        return read_rows(self.results_path)

    def read_table(self) -> dict:
        """All stored rows as columns (see :func:`read_table`)."""
        return read_table(self.results_path, self.columns)


def read_rows(path) -> list[dict]:
    """Rows of a ``results.csv``, sorted by ``trial_id``; values parsed as int, float or text.

    Raises
    ------
    InputError
        If the file is missing.
    """
    path = Path(path)
    try:
        data = path.read_text()
    except OSError as exc:
        raise InputError(f"results file {str(path)!r} cannot be read: {exc}") from None
    if not data.endswith("\n"):
        data = data[: data.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(data))
    try:
        header = next(reader)
    except StopIteration:
        return []
    rows = [dict(zip(header, (_parse(x) for x in r))) for r in reader if r]
    rows.sort(key=lambda r: r["trial_id"])
    return rows


def read_table(path, columns=None) -> dict:
    """Columns of a ``results.csv`` sorted by ``trial_id``.

    Returns
    -------
    dict of str -> ndarray, shape (n_rows,)
        float64 for numeric columns (empty -> NaN), object for text columns.
    """
    rows = read_rows(path)
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
