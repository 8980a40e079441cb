"""Output locations checked by doing, before any work: a folder is made and a probe file written.

A check by permission bits is no check as root (``os.access`` says yes to ``/proc/nope``, and
the render fails after it has run). Here a folder counts as writable when a file could be made
in it and removed again, and an output folder counts as usable once it exists and has passed
that probe. Every failure is an :class:`svgs_sim.base.errors.InputError` that names the option and the
path (``--out '/proc/nope': cannot create the folder (No such file or directory)``): exit 2, one
line, nothing written.

- :func:`check_output_folder`, :func:`check_output_file`: the checks of the validation layer,
  which create nothing: the probe goes into the nearest folder that exists.
- :func:`prepare_output_folder`, :func:`prepare_output_file`: what a command calls before its
  work: the folder (and its parents) made and probed; the folders it made are removed again
  when the probe fails.
- :func:`output_folder`, :func:`output_file`: the same as context managers that also remove the
  folders they made when the command is refused or stopped before it wrote anything there.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from svgs_sim.base.errors import InputError

#: Prefix of the probe file (a hidden name; removed at once).
PROBE_PREFIX = ".svgs-write-probe-"


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _where(option: str, path) -> str:
    return f"{option} {str(path)!r}"


def _probe(folder: Path) -> str | None:
    """Make a file in ``folder``, write it and remove it; None when that worked, else the reason."""
    import tempfile

    try:
        fd, name = tempfile.mkstemp(prefix=PROBE_PREFIX, dir=folder)
    except OSError as exc:
        return _reason(exc)
    try:
        try:
            os.write(fd, b"svgs\n")
        finally:
            os.close(fd)
    except OSError as exc:
        return _reason(exc)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(name)
    return None


def probe_folder(folder, option: str = "--out") -> None:
    """Write a probe file into the existing ``folder`` and remove it.

    Parameters
    ----------
    folder : str or Path
        An existing folder.
    option : str
        The option named in the message.

    Raises
    ------
    InputError
        The file could not be made, written or removed.
    """
    why = _probe(Path(folder))
    if why is not None:
        raise InputError(f"{_where(option, folder)}: cannot write in the folder ({why})")


def _nearest_existing(p: Path) -> Path:
    """``p`` or its nearest ancestor that exists (as the path is written, made absolute)."""
    q = p.absolute()
    while not q.exists() and q != q.parent:
        q = q.parent
    return q


def check_output_folder(path, option: str = "--out") -> Path:
    """An output folder that exists and takes a file, or could be made: checked, nothing made.

    The probe file goes into ``path`` when it is a folder, otherwise into its nearest existing
    ancestor, which must be a folder.

    Raises
    ------
    InputError
        ``path`` is a file, or the folder (or the folder it would be made in) is not one or
        does not take a file.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{_where(option, p)}: exists and is not a folder")
    base = _nearest_existing(p)
    if not base.is_dir():
        raise InputError(f"{_where(option, p)}: cannot create the folder ({str(base)!r} is not a folder)")
    if p.is_dir():
        probe_folder(p, option)
        return p
    why = _probe(base)
    if why is not None:
        raise InputError(f"{_where(option, p)}: cannot create the folder (cannot write in {str(base)!r}: {why})")
    return p


def check_output_file(path, option: str = "--out") -> Path:
    """An output file: not a folder, in a folder that takes a file or could be made (nothing made)."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{_where(option, p)}: is a folder; expected a file name")
    check_output_folder(p.absolute().parent, option)
    return p


def _missing_folders(p: Path) -> list[Path]:
    """The folders of ``p`` (itself included) that do not exist yet, outermost first."""
    missing = []
    q = p.absolute()
    while not q.exists() and q != q.parent:
        missing.append(q)
        q = q.parent
    return missing[::-1]


def _remove_empty(folders) -> None:
    """Remove the folders of ``folders`` (outermost first) that are empty, innermost first."""
    for d in reversed(list(folders)):
        try:
            d.rmdir()
        except FileNotFoundError:
            continue  # never made (the making failed below its parent)
        except OSError:
            return  # not empty: the folders above it are not empty either


def _prepare(path, option: str) -> tuple[Path, list[Path]]:
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{_where(option, p)}: exists and is not a folder")
    made = _missing_folders(p)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _remove_empty(made)
        raise InputError(f"{_where(option, p)}: cannot create the folder ({_reason(exc)})") from None
    try:
        probe_folder(p, option)
    except InputError:
        _remove_empty(made)
        raise
    return p, made


def prepare_output_folder(path, option: str = "--out") -> Path:
    """Make the output folder (parents too) and write and remove a probe file in it: before any work.

    Parameters
    ----------
    path : str or Path
    option : str
        The option named in the message (``--out``, ``--cache``).

    Returns
    -------
    Path
        ``path``, now an existing folder that takes files.

    Raises
    ------
    InputError
        ``path`` is a file, cannot be made, or does not take a file (the folders made here are
        removed again).
    """
    return _prepare(path, option)[0]


def _prepare_file(path, option: str) -> tuple[Path, list[Path]]:
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{_where(option, p)}: is a folder; expected a file name")
    folder, made = _prepare(p.absolute().parent, option)
    if p.exists():
        try:
            with open(p, "ab"):  # opened for appending, nothing written: the file takes writes
                pass
        except OSError as exc:
            raise InputError(f"{_where(option, p)}: cannot write the file ({_reason(exc)})") from None
    return p, made


def prepare_output_file(path, option: str = "--out") -> Path:
    """Make the folder of an output file and probe it (:func:`prepare_output_folder`); an
    existing file is opened for appending (nothing written), a new one is not made.

    Raises
    ------
    InputError
        ``path`` is a folder, its folder cannot be made or does not take a file, or the
        existing file cannot be written.
    """
    return _prepare_file(path, option)[0]


@contextlib.contextmanager
def output_folder(path, option: str = "--out"):
    """:func:`prepare_output_folder` for the length of a command.

    When the body raises (an :class:`InputError` found later, an interrupt), the folders made
    here are removed again if they are still empty: a refused run leaves nothing behind. A
    folder that holds anything - results to resume from - is kept.

    Yields
    ------
    Path
        The prepared folder.
    """
    p, made = _prepare(path, option)
    try:
        yield p
    except BaseException:
        _remove_empty(made)
        raise


@contextlib.contextmanager
def output_file(path, option: str = "--out"):
    """:func:`prepare_output_file` for the length of a command; the folders made for the file are
    removed again when the body raises and they are still empty."""
    p, made = _prepare_file(path, option)
    try:
        yield p
    except BaseException:
        _remove_empty(made)
        raise


def output_file_if(path, option: str = "--out"):
    """:func:`output_file` when ``path`` is given, else a context that yields None."""
    return output_file(path, option) if path else contextlib.nullcontext(None)


def output_folder_if(path, option: str = "--out"):
    """:func:`output_folder` when ``path`` is given, else a context that yields None."""
    return output_folder(path, option) if path else contextlib.nullcontext(None)


__all__ = ["check_output_file", "check_output_folder", "output_file", "output_file_if", "output_folder",
           "output_folder_if", "prepare_output_file", "prepare_output_folder", "probe_folder"]
