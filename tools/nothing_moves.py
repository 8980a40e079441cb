"""Run a fixed set of CLI commands and compare two such runs: the check that a refactoring moved
no number ("nothing moves": renders, render-and-solve, a range sweep, geometric and rendered
campaigns of both phones, ToF stability).

Run::

    python tools/nothing_moves.py run OUT [--svgs "python -m svgs_sim.cli.main"] [--only NAME ...]
    python tools/nothing_moves.py compare OLD NEW

``run`` executes every command with ``OUT`` as the working directory and relative output folders
(so that no path recorded in an output differs between two runs), keeping each command's stdout
(``NAME.stdout``; the ``--json`` objects) and output folder. ``--svgs`` is the command that starts
the CLI (default: the ``svgs`` console script beside this Python), so the same list runs against
an older checkout: ``PYTHONPATH=OLD_CHECKOUT python tools/nothing_moves.py run OUT --svgs
"python -m MAIN"`` with that checkout's CLI module as ``MAIN`` (``cli.main`` before 0.2.0).

``compare`` walks both trees and compares every file: JSON and JSON-lines objects key by key and
CSV files cell by cell after dropping the keys and columns of :data:`DROPPED_KEYS` (wall and CPU
times and versions, which are expected to differ) and mapping renamed columns to the current
results-store layout (:func:`_renamed`, :func:`_current_manifest`), HTML reports as text with the time they were
made and the project's version masked (:data:`MASKED_TEXT`), ``.npy`` arrays bit for bit, PNG images pixel by pixel
(their metadata may name a library version), any other file byte for byte. It prints one line per
difference and exits 1 if there is any, 0 if the runs are identical.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

#: Keys (JSON) and columns (CSV) that hold wall times, CPU times or software versions: dropped
#: before comparing, wherever they occur. Nothing else is dropped.
DROPPED_KEYS = frozenset({"timings_s", "cpu_s", "wall_s", "frames_s", "render_s", "expose_s", "solve_s",
                          "elapsed_s", "versions"})

#: Text in HTML reports that names the time it was made, its wall times or the project's version:
#: masked.
MASKED_TEXT = (
    (re.compile(r"Generated \d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[^ <]*"), "Generated TIME"),
    (re.compile(r"(Wall time of the trials: |\d trials in )[\d.]+ (s|min|h)\b"), r"\1TIME"),
    (re.compile(r'(<td class="t">svgs-sim</td><td class="t">)[^<]*'), r"\1VERSION"),
)

#: The commands: (name, arguments after ``svgs``). Two poses per phone for the renders; the
#: output folder of a command is ``OUT/NAME`` when the command writes one.
POSES = {
    "nexus-a": ["--camera", "galaxy-nexus", "--range", "5"],
    "nexus-b": ["--camera", "galaxy-nexus", "--range", "8", "--x", "0.1", "--roll", "10", "--pitch", "-5",
                "--yaw", "20"],
    "amaze-a": ["--camera", "htc-amaze-4g", "--range", "3"],
    "amaze-b": ["--camera", "htc-amaze-4g", "--range", "5", "--y", "-0.1", "--roll", "-8", "--pitch", "12",
                "--yaw", "-30"],
}
COMMANDS = (
    [(f"render-{k}", ["render", *v, "--seed", "1", "--out", f"render-{k}", "--json"]) for k, v in POSES.items()]
    + [(f"ras-{k}", ["render-and-solve", *v, "--seed", "1", "--json"]) for k, v in POSES.items()]
    + [("sweep-nexus", ["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5,10,20", "--trials", "3",
                        "--processes", "0", "--no-progress", "--out", "sweep-nexus", "--json"])]
    + [(f"campaign-geo-{p}", ["campaign", "--camera", c, "--trial-kind", "geometric", "--trials", "40",
                              "--processes", "0", "--no-progress", "--out", f"campaign-geo-{p}", "--json"])
       for p, c in (("nexus", "galaxy-nexus"), ("amaze", "htc-amaze-4g"))]
    + [(f"campaign-render-{p}", ["campaign", "--camera", c, "--trials", "8", "--ranges", r,
                                 "--processes", "0", "--no-progress", "--out", f"campaign-render-{p}", "--json"])
       for p, c, r in (("nexus", "galaxy-nexus", "5"), ("amaze", "htc-amaze-4g", "3"))]
    + [("tof-stability", ["tof", "stability", "--range", "5.712", "--frames", "20", "--json"])]
)


def run(out: Path, svgs: list[str], only: set[str] | None) -> int:
    """Run the commands into ``out``; returns the number of commands that exited with 2 or more."""
    out.mkdir(parents=True, exist_ok=True)
    bad = 0
    for name, args in COMMANDS:
        if only and name not in only:
            continue
        t0 = time.perf_counter()
        p = subprocess.run([*svgs, *args], cwd=out, capture_output=True, text=True)
        (out / f"{name}.stdout").write_text(p.stdout)
        (out / f"{name}.rc").write_text(f"{p.returncode}\n")
        print(f"{name}: exit {p.returncode} in {time.perf_counter() - t0:.1f} s", flush=True)
        if p.returncode >= 2:
            bad += 1
            print(p.stderr[-2000:], file=sys.stderr)
    return bad


#: Parameters added since an older run, with the values that mean what the older run did (its
#: default): a key or column of one of them at such a value is dropped before comparing, so an
#: older run's output compares with a newer one's; at any other value it stays (and differs).
ADDED_AT_DEFAULT = {"environment": ("lab", 0.0, "0.0", None), "sun_azimuth_deg": (None, ""),
                    "sun_elevation_deg": (None, ""), "sun_deg": (None,), "body_material": (None,),
                    "body_materials": (None,), "earth_azimuth_deg": (None, ""), "earth_elevation_deg": (None, ""),
                    "earth_deg": (None,), "altitude_km": (400.0, "400.0", 400, None), "earth_albedo": (0.3, "0.3", None),
                    }  # None: an option not given


#: Outputs added since an older run (new numbers, not moved ones): dropped before comparing.
NEW_OUTPUTS = frozenset({"match_err_max_px", "stray_px", "stray_saturated_px", "outside_test_envelope", "identified_px",
                         "wrong_lock", "wrong_locks", "paper_gates_reported", "paper_gates_match_err_max_px"})


def _added_at_default(key, value) -> bool:
    return key in NEW_OUTPUTS or (key in ADDED_AT_DEFAULT and value in ADDED_AT_DEFAULT[key])


def _drop(obj):
    if isinstance(obj, dict):
        return {k: _drop(v) for k, v in obj.items() if k not in DROPPED_KEYS and not _added_at_default(k, v)}
    if isinstance(obj, list):
        return [_drop(v) for v in obj if not (isinstance(v, str) and (v in ADDED_AT_DEFAULT or v in NEW_OUTPUTS))]
    return obj


def _json_docs(text: str) -> list:
    """Every JSON value in ``text``: one document, or one per line (JSON lines, progress noise skipped)."""
    try:
        return [json.loads(text)]
    except json.JSONDecodeError:
        docs = []
        for line in text.splitlines():
            line = line.strip()
            if line.startswith(("{", "[")):
                try:
                    docs.append(json.loads(line))
                except json.JSONDecodeError:
                    docs.append(line)
        return docs


def _diff(a, b, where: str, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{where}.{k}: only in {'new' if k in b else 'old'}")
            else:
                _diff(a[k], b[k], f"{where}.{k}", out)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            _diff(x, y, f"{where}[{i}]", out)
    elif a != b and not (isinstance(a, float) and isinstance(b, float) and np.isnan(a) and np.isnan(b)):
        out.append(f"{where}: {str(a)[:80]} -> {str(b)[:80]}")


def _csv_rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return [_renamed({k: v for k, v in row.items() if k not in DROPPED_KEYS and not _added_at_default(k, v)})
                for row in csv.DictReader(fh)]


def _renamed(row: dict) -> dict:
    """A results row in the store's current layout (format 2): a row of format 1 (``stand`` and
    ``range_m``, no ``rail_m``) had the stand's rail position in ``range_m``; it moves to ``rail_m``.
    Written here, not imported, so the mapping is checked against the store's own."""
    if "stand" not in row or "range_m" not in row or "rail_m" in row:
        return row
    on_stand = row["stand"] not in ("", None) and float(row["stand"]) == 1.0
    out = {}
    for k, v in row.items():
        if k == "range_m":
            out["range_m"], out["rail_m"] = ("", v) if on_stand else (v, "")
        else:
            out[k] = v
    return out


def _current_manifest(doc):
    """A store manifest of format 1 as format 2 writes it (the ``rail_m`` column after ``range_m``)."""
    if not (isinstance(doc, dict) and doc.get("format_version") == 1 and isinstance(doc.get("columns"), list)):
        return doc
    cols = list(doc["columns"])
    if "range_m" in cols and "stand" in cols and "rail_m" not in cols:
        cols.insert(cols.index("range_m") + 1, "rail_m")
    return {**doc, "format_version": 2, "columns": cols}


def compare_file(a: Path, b: Path, rel: str) -> list[str]:
    """The differences between two files of the same name, one line each."""
    out: list[str] = []
    suffix = a.suffix
    if suffix in (".json", ".jsonl", ".stdout"):
        x, y = _drop(_json_docs(a.read_text())), _drop(_json_docs(b.read_text()))
        if a.name == "manifest.json":
            x, y = [_current_manifest(d) for d in x], [_current_manifest(d) for d in y]
        _diff(x, y, rel, out)
    elif suffix == ".csv":
        _diff(_csv_rows(a), _csv_rows(b), rel, out)
    elif suffix == ".npy":
        x, y = np.load(a), np.load(b)
        if x.shape != y.shape or x.dtype != y.dtype or x.tobytes() != y.tobytes():
            out.append(f"{rel}: arrays differ")
    elif suffix == ".png":
        import cv2

        x, y = cv2.imread(str(a), cv2.IMREAD_UNCHANGED), cv2.imread(str(b), cv2.IMREAD_UNCHANGED)
        if x is None or y is None or x.shape != y.shape or not np.array_equal(x, y):
            out.append(f"{rel}: pixels differ")
    elif suffix == ".html":
        x, y = a.read_text(), b.read_text()
        for rx, repl in MASKED_TEXT:
            x, y = rx.sub(repl, x), rx.sub(repl, y)
        if x != y:
            import difflib

            # by sentence-sized pieces (a report is megabytes of base64 figures: never by character)
            xs, ys = re.split(r"(?<=[>.;])", x), re.split(r"(?<=[>.;])", y)
            for op, i1, i2, j1, j2 in difflib.SequenceMatcher(None, xs, ys, autojunk=False).get_opcodes():
                if op != "equal":
                    out.append(f"{rel}: text differs: {''.join(xs[i1:i2])[:160]!r} -> {''.join(ys[j1:j2])[:160]!r}")
    elif a.read_bytes() != b.read_bytes():
        out.append(f"{rel}: bytes differ")
    return out


def compare(old: Path, new: Path) -> list[str]:
    """Every difference between two ``run`` folders (lock files ignored)."""
    def files(root):
        return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and p.name != ".lock"}

    fa, fb = files(old), files(new)
    diffs = [f"{r}: only in old" for r in sorted(fa - fb)] + [f"{r}: only in new" for r in sorted(fb - fa)]
    for rel in sorted(fa & fb):
        diffs += compare_file(old / rel, new / rel, rel)
    return diffs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the commands into OUT")
    r.add_argument("out", type=Path)
    r.add_argument("--svgs", default=None,
                   help="command that starts the CLI (default: the svgs console script beside this Python)")
    r.add_argument("--only", nargs="*", default=None, help="run only these commands (by name)")
    c = sub.add_parser("compare", help="compare two run folders")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "run":
        svgs = shlex.split(args.svgs) if args.svgs else [str(Path(sys.executable).with_name("svgs"))]
        if svgs[0] == "python":
            svgs[0] = sys.executable
        return 1 if run(args.out.resolve(), svgs, set(args.only) if args.only else None) else 0
    diffs = compare(args.old, args.new)
    for line in diffs:
        print(line)
    n_files = sum(1 for p in args.old.rglob("*") if p.is_file())
    print(f"{len(diffs)} differences over {n_files} files (dropped keys: {', '.join(sorted(DROPPED_KEYS))}; "
          f"new outputs, not compared: {', '.join(sorted(NEW_OUTPUTS))}; parameters added since, dropped at their "
          f"default: {', '.join(sorted(ADDED_AT_DEFAULT))}; masked in HTML: the generation time, wall times, the "
          "svgs-sim version)")
    return 1 if diffs else 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    sys.exit(main())
