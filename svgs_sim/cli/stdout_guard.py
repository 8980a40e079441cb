"""The command's stdout, guarded: a reader that went away (a broken pipe, ``| head``) or a stdout
that was closed before the command started (``>&-``) does not stop the command half-way.

Every write goes through :class:`GuardedStdout`; the first one that fails (a broken pipe, a full
disk behind a redirection, a closed descriptor) marks the stream
``broken`` and the rest are dropped, so the command finishes and writes its files, and
:func:`svgs_sim.cli.main.main` then exits 3 (``io_error``) with one line on stderr saying what was
not printed and where the files are. Issue 41: a study piped into ``head`` lost its
``summary.json``; ``svgs solve --json`` with stdout closed exited 0 having printed nothing.
"""

from __future__ import annotations

import io


class GuardedStdout(io.TextIOBase):
    """A text stream over ``stream`` (None: a closed stdout) that never raises on a lost reader.

    Attributes
    ----------
    broken : bool
        A write or flush failed (or there was no stream): output was lost.
    error : OSError or None
        The failure (None for a closed stdout).
    """

    def __init__(self, stream):
        self._stream = stream
        self.broken = stream is None
        self.error = None

    @property
    def encoding(self):  # noqa: D401 (the wrapped stream's)
        return getattr(self._stream, "encoding", "utf-8")

    def writable(self) -> bool:
        return True

    def isatty(self) -> bool:
        try:
            return bool(self._stream is not None and not self.broken and self._stream.isatty())
        except (OSError, ValueError):  # a closed stream
            return False

    def fileno(self) -> int:
        if self._stream is None:
            raise io.UnsupportedOperation("stdout is closed")
        return self._stream.fileno()

    def write(self, text: str) -> int:
        if self.broken:
            return len(text)
        try:
            return self._stream.write(text)
        except (OSError, ValueError) as exc:  # ValueError: the stream was closed
            self._fail(exc)
            return len(text)

    def flush(self) -> None:
        if self.broken:
            return
        try:
            self._stream.flush()
        except (OSError, ValueError) as exc:
            self._fail(exc)

    def _fail(self, exc) -> None:
        self.broken = True
        self.error = exc if isinstance(exc, OSError) else None


__all__ = ["GuardedStdout"]
