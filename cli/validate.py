"""Input checks that run before any work: output locations (more checks land here with issue 14)."""

from __future__ import annotations

import os
from pathlib import Path

from svgs.errors import InputError


def check_out_dir(path, flag: str = "--out") -> Path:
    """An output folder that exists (and is a writable folder) or can be made.

    Raises
    ------
    InputError
        An existing file, an unwritable folder, or a parent that is a file or unwritable;
        the message names ``flag``.
    """
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise InputError(f"{flag}: {str(p)!r} exists and is not a folder")
        if not os.access(p, os.W_OK | os.X_OK):
            raise InputError(f"{flag}: folder {str(p)!r} is not writable")
        return p
    parent = p.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{flag}: cannot make {str(p)!r}: {str(parent)!r} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag}: cannot make {str(p)!r}: {str(parent)!r} is not writable")
    return p
