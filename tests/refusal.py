"""One check for a refused command line (issue 26's acceptance): the exit code, one line on
stderr, no traceback, the time from the call to the exit, and nothing written.

``refused(argv, capsys, watch=[folder])`` runs ``svgs ARGV`` in this process and returns its
one error line. "Nothing written" is checked on the folders in ``watch``: every file's name,
size and modification time, and every folder, before and after (a folder that did not exist
must still not exist).
"""

from __future__ import annotations

import time
from pathlib import Path

from svgs_sim.cli.main import main

#: Seconds from the call to the exit of a command refused before any work. The work such a
#: refusal saves is a render (3-7 s), a board set or a study; parsing and checking take ~0.2 s,
#: a cold process with its imports 0.2-0.8 s on two cores.
REFUSED_WITHIN_S = 1.0
#: The longest one-line message (issue 41 found 460-1144 characters): a sentence a reader takes in,
#: the paths it names included (those of pytest's temporary folders run to ~80 characters).
MAX_MESSAGE_CHARS = 450
#: Lines a first run may print before its error, once per installation (not part of a message).
_NOTICES = ("compiling the solver",)


def tree(path) -> tuple | None:
    """Every file (name, size, mtime) and folder under ``path``; None if it does not exist."""
    p = Path(path)
    if not p.exists():
        return None
    if p.is_file():
        st = p.stat()
        return (("", st.st_size, st.st_mtime_ns),)
    out = []
    for q in sorted(p.rglob("*")):
        st = q.stat()
        out.append((str(q.relative_to(p)), st.st_size if q.is_file() else -1, st.st_mtime_ns if q.is_file() else 0))
    return tuple(out)


def error_lines(err: str) -> list[str]:
    """The message lines of stderr: without argparse's usage block and the first-run notice."""
    return [ln for ln in err.splitlines()
            if ln.strip() and not ln.startswith(("usage:", " ")) and not ln.startswith(_NOTICES)]


def refused(argv, capsys, *, watch=(), code: int = 2, within_s: float | None = REFUSED_WITHIN_S,
            json_out: bool = False, after_work: bool = False) -> str:
    """Run ``svgs ARGV`` and check it was refused cleanly; returns the one error line.

    Parameters
    ----------
    argv : list of str
    capsys : pytest fixture
    watch : iterable of path
        Folders (or files) that must be unchanged afterwards.
    code : int
        The expected exit code (2: bad input; 1: a simulated failure).
    within_s : float or None
        Bound on the seconds from the call to the exit (None: no bound).
    after_work : bool
        The refusal comes after some work by design (its status lines precede it): the error is
        then the last line and the only one that says ``error``.
    json_out : bool
        ``--json`` was given: stdout holds one JSON object with ``"ok": false`` (else it is empty).
    """
    import json

    watch = [Path(w) for w in watch]
    before = [tree(w) for w in watch]
    t0 = time.perf_counter()
    rc = main(list(argv))
    took_s = time.perf_counter() - t0
    cap = capsys.readouterr()
    assert rc == code, (argv, cap.err[-600:])
    assert "Traceback" not in cap.err and "Traceback" not in cap.out, cap.err[-3000:]
    lines = error_lines(cap.err)
    if after_work:
        lines = lines[-1:] if lines and sum(": error:" in ln for ln in lines) == 1 else lines
    assert len(lines) == 1 and (not after_work or ": error:" in lines[0]), cap.err
    assert len(lines[0]) <= MAX_MESSAGE_CHARS, f"{len(lines[0])} characters: {lines[0]}"
    if within_s is not None:
        assert took_s < within_s, f"{took_s:.2f} s before the exit: refused after some work ({argv})"
    if json_out:
        obj = json.loads(cap.out)
        assert obj["ok"] is False and obj["error"], cap.out
    else:
        assert cap.out == "", cap.out
    for w, b in zip(watch, before):
        assert tree(w) == b, f"{w} changed: {b} -> {tree(w)}"
    return lines[0]
