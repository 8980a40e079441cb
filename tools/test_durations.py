"""Write tests/durations.json: seconds per test file of a full run, which ``tests/conftest.py``
uses to hand the heaviest files out first under pytest-xdist (``make test``).

``make test`` keeps each file on one worker (``--dist loadfile``) and hands the files out in
collection order (``--no-loadscope-reorder``); xdist's own order (most tests first) left the
files with few but long tests (a rendered campaign on a pool, 42 s) to the end, where one worker
ran them while the others had finished: 344 s against 328 s handed out heaviest first (issue 40,
the same run's durations). The durations only order the files; a stale or missing entry costs
time, never a result.

Run: ``.venv/bin/python tools/test_durations.py`` (a full run, about 6 minutes on two cores), or
``--junit FILE`` to read a run's ``--junitxml`` report instead.
"""

from __future__ import annotations

import argparse
import collections
import json
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "durations.json"


def file_seconds(junit_path) -> dict[str, float]:
    """Seconds per test file (setup, call and teardown of its tests) from a pytest JUnit XML report."""
    total = collections.Counter()
    for case in ET.parse(junit_path).getroot().iter("testcase"):
        module = case.get("classname", "").split(".")
        # classname "tests.test_x" or "tests.test_x.TestClass"
        name = next((p for p in module if p.startswith("test_")), None)
        if name:
            total[f"tests/{name}.py"] += float(case.get("time") or 0.0)
    return dict(total)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--junit", help="a --junitxml report of a full run (default: run the suite now)")
    args = ap.parse_args(argv)
    if args.junit:
        seconds = file_seconds(args.junit)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            junit = Path(tmp) / "junit.xml"
            cmd = [sys.executable, "-m", "pytest", "-q", "-n", "3", "--dist", "loadfile", "--no-loadscope-reorder",
                   f"--junitxml={junit}"]
            print("running:", " ".join(cmd), file=sys.stderr, flush=True)
            rc = subprocess.run(cmd, cwd=ROOT).returncode
            if rc != 0:
                print(f"the run failed (exit {rc}): {OUT.name} is not written", file=sys.stderr)
                return 1
            seconds = file_seconds(junit)
    if not seconds:
        print("no test cases in the report: nothing written", file=sys.stderr)
        return 1
    body = {"about": "seconds per test file of a full run on three xdist workers (tools/test_durations.py); "
                     "tests/conftest.py hands the heaviest files out first",
            "files": {k: round(v, 1) for k, v in sorted(seconds.items(), key=lambda kv: -kv[1])}}
    OUT.write_text(json.dumps(body, indent=1) + "\n")
    print(f"{OUT.relative_to(ROOT)}: {len(seconds)} files, {sum(seconds.values()):.0f} s in all", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
