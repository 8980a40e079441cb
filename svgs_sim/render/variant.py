"""Mitsuba variant choice and LLVM discovery - the one place where it happens.

Dr.Jit 1.5 (Mitsuba 3.9) compiles its LLVM kernels through whatever ``libLLVM`` it
finds first. With LLVM 15 (what Debian 12 ships) the first kernel that uses
``fminimum`` *aborts the whole process* ("LLVM ERROR: Cannot select fminimum"), so the
library must be chosen *before* ``drjit`` is imported, and its version checked before
any kernel is compiled. :func:`select_variant` does that:

1. An explicit request (argument ``prefer`` or environment variable ``SVGS_MI_VARIANT``)
   names a full variant (``"llvm_ad_mono"``, ``"scalar_rgb"``...) or a backend
   (``"cuda"``, ``"llvm"``, ``"scalar"``).
2. Without drjit imported yet, candidate LLVM libraries are listed (``DRJIT_LIBLLVM_PATH``
   if set, the ``karellen-llvm-core`` wheel's ``lib/libLLVM.so.*`` inside this Python
   environment, then the system's), their major version is read from the library's
   file name (symlinks resolved) without loading it, and the newest compatible one is
   put in ``DRJIT_LIBLLVM_PATH``.
3. drjit is imported, and the *loaded* version (``drjit.detail.llvm_version()``) is
   checked before any kernel exists; cuda is used when a GPU is there, else llvm when
   its version is compatible, else ``scalar_rgb`` with a notice. Nothing here compiles a
   kernel, so nothing here can abort.

The decision logic is :func:`decide` (pure, unit-tested with faked probes); the rest
only gathers facts.
"""

from __future__ import annotations

import glob
import os
import re
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

from svgs_sim.base.errors import InputError

#: Environment variable that overrides the choice (full variant name or backend).
ENV_VARIANT = "SVGS_MI_VARIANT"
#: Dr.Jit's own variable naming the LLVM library to load.
ENV_LIBLLVM = "DRJIT_LIBLLVM_PATH"
#: Oldest LLVM major version accepted. 15 aborts (measured here with Dr.Jit 1.5);
#: 19 (Debian ``libllvm19``) and 23 (``karellen-llvm-core``) were verified to work.
#: 16-18 are untested; we accept them because the failing instruction selection
#: (vector ``fminimum`` on x86) was added in LLVM 16. Raise this if that proves wrong.
MIN_LLVM_MAJOR = 16
#: Variant used per backend: the flux is one band, so ``mono`` where it exists.
VARIANT_FOR_BACKEND = {"cuda": "cuda_ad_mono", "llvm": "llvm_ad_mono", "scalar": "scalar_rgb"}

_SELECTED: "VariantInfo | None" = None


@dataclass(frozen=True)
class VariantInfo:
    """What :func:`select_variant` chose and why.

    Attributes
    ----------
    name : str
        Mitsuba variant set, e.g. ``"llvm_ad_mono"``.
    backend : str
        ``"cuda"``, ``"llvm"`` or ``"scalar"``.
    llvm_path : str or None
        The LLVM library Dr.Jit was pointed at (``DRJIT_LIBLLVM_PATH``), if any.
    llvm_version : tuple of int or None
        Version of the LLVM library Dr.Jit loaded, when the LLVM backend initialised.
    notice : str
        Human-readable remark (fallbacks, overrides); empty when all went as preferred.
    requested : str or None
        The explicit request (argument or ``SVGS_MI_VARIANT``), if any.
    candidates : tuple
        ``(path, major_version_or_None)`` of the LLVM libraries considered.
    """

    name: str
    backend: str
    llvm_path: str | None = None
    llvm_version: tuple | None = None
    notice: str = ""
    requested: str | None = None
    candidates: tuple = field(default_factory=tuple)

    def to_json(self) -> dict:
        d = asdict(self)
        d["llvm_version"] = list(self.llvm_version) if self.llvm_version else None
        d["candidates"] = [list(c) for c in self.candidates]
        return d


# ----------------------------------------------------------------------------- probes
_VERSION_PATTERNS = (
    re.compile(r"libLLVM-(\d+)(?:[.\w]*)\.so"),  # libLLVM-15.so, libLLVM-14.0.6.so.1
    re.compile(r"libLLVM\.so\.(\d+)"),  # libLLVM.so.23.1
    re.compile(r"libLLVM-(\d+)"),  # libLLVM-19
    re.compile(r"llvm-(\d+)/"),  # /usr/lib/llvm-19/lib/libLLVM.so
)


def llvm_major_from_path(path) -> int | None:
    """LLVM major version from a library's file name, symlinks resolved; None if unknown.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    int or None
    """
    names = [str(path)]
    try:
        names.insert(0, os.path.realpath(path))
    except OSError:
        pass
    for name in names:
        for pat in _VERSION_PATTERNS:
            m = pat.search(name)
            if m:
                return int(m.group(1))
    return None


def _wheel_llvm_libraries() -> list[str]:
    """libLLVM shipped by the ``karellen-llvm-core`` wheel in this environment."""
    out = []
    try:
        import importlib.metadata as md

        dist = md.distribution("karellen-llvm-core")
        for f in dist.files or ():
            if re.search(r"libLLVM[.-]", Path(str(f)).name):
                p = Path(dist.locate_file(f)).resolve()
                if p.is_file():
                    out.append(str(p))
    except Exception:  # noqa: BLE001 - not installed or unreadable metadata: no candidate
        pass
    out += glob.glob(os.path.join(sys.prefix, "lib", "libLLVM.so.*"))
    # one entry per real file, highest version first
    seen, uniq = set(), []
    for p in sorted(out, key=lambda q: -(llvm_major_from_path(q) or 0)):
        rp = os.path.realpath(p)
        if rp not in seen:
            seen.add(rp)
            uniq.append(rp)
    return uniq


def _system_llvm_libraries() -> list[str]:
    pats = [
        "/usr/lib/llvm-*/lib/libLLVM*.so*",
        "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
        "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
        "/usr/lib64/libLLVM*.so*",
        "/usr/local/lib/libLLVM*.so*",
        "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
        "/usr/local/opt/llvm/lib/libLLVM.dylib",
    ]
    seen, out = set(), []
    for pat in pats:
        for p in sorted(glob.glob(pat)):
            rp = os.path.realpath(p)
            if rp not in seen and os.path.isfile(rp):
                seen.add(rp)
                out.append(rp)
    return out


def llvm_candidates(env: dict | None = None) -> list[tuple[str, int | None, str]]:
    """LLVM libraries Dr.Jit could use, in order of preference.

    Returns
    -------
    list of (path, major_version_or_None, origin)
        origin is ``"env"``, ``"wheel"`` or ``"system"``.
    """
    env = os.environ if env is None else env
    out = []
    user = env.get(ENV_LIBLLVM)
    if user:
        out.append((user, llvm_major_from_path(user), "env"))
    for p in _wheel_llvm_libraries():
        out.append((p, llvm_major_from_path(p), "wheel"))
    sys_libs = _system_llvm_libraries()
    sys_libs.sort(key=lambda q: -(llvm_major_from_path(q) or 0))
    for p in sys_libs:
        out.append((p, llvm_major_from_path(p), "system"))
    return out


def pick_llvm(candidates, exists=os.path.isfile) -> tuple[str | None, str]:
    """Choose the LLVM library to point Dr.Jit at.

    Parameters
    ----------
    candidates : sequence of (path, major_or_None, origin)
        As returned by :func:`llvm_candidates`.
    exists : callable
        File test (tests pass a fake one).

    Returns
    -------
    path : str or None
        The library to put in ``DRJIT_LIBLLVM_PATH`` (None: no compatible one known).
    notice : str
    """
    notes = []
    for path, major, origin in candidates:
        if origin == "env":
            if major is None or major >= MIN_LLVM_MAJOR:
                return path, ""  # the user's explicit choice; the loaded version is checked later
            notes.append(f"{ENV_LIBLLVM}={path} is LLVM {major}, which Dr.Jit 1.5 cannot use; ignoring it")
            continue
        if major is not None and major >= MIN_LLVM_MAJOR and exists(path):
            return path, "; ".join(notes)
    return None, "; ".join(notes)


def decide(requested: str | None, *, cuda_ok: bool, llvm_version: tuple | None,
           llvm_path: str | None = None, available=None) -> tuple[str, str, str]:
    """The variant decision, free of side effects (unit-tested with faked facts).

    Parameters
    ----------
    requested : str or None
        Full variant name or backend (``"cuda"``, ``"llvm"``, ``"scalar"``); None = auto.
    cuda_ok : bool
        Dr.Jit's CUDA backend initialised (a GPU is there).
    llvm_version : tuple of int or None
        Version of the LLVM library Dr.Jit loaded (None: LLVM backend unavailable).
    llvm_path : str or None
        For the notice only.
    available : collection of str, optional
        Variants Mitsuba was built with; default: the three of :data:`VARIANT_FOR_BACKEND`.

    Returns
    -------
    name, backend, notice : str

    Raises
    ------
    InputError
        If ``requested`` names no known backend or variant.
    """
    available = set(VARIANT_FOR_BACKEND.values()) if available is None else set(available)
    llvm_ok = llvm_version is not None and int(llvm_version[0]) >= MIN_LLVM_MAJOR
    llvm_why = (
        "Dr.Jit's LLVM backend did not initialise (no libLLVM found)" if llvm_version is None
        else f"Dr.Jit loaded LLVM {'.'.join(map(str, llvm_version))}"
             f"{' from ' + llvm_path if llvm_path else ''}, older than {MIN_LLVM_MAJOR} "
             f"(LLVM 15 aborts the process in Dr.Jit 1.5)"
    )
    fix = "install the 'karellen-llvm-core' wheel or Debian's libllvm19, or set DRJIT_LIBLLVM_PATH"

    def backend_of(name):
        return name.split("_")[0]

    if requested:
        req = requested.strip().lower()
        if req in VARIANT_FOR_BACKEND:
            name = VARIANT_FOR_BACKEND[req]
        elif req in available or "_" in req:
            name = req
        else:
            raise InputError(
                f"{ENV_VARIANT}/prefer: unknown Mitsuba variant or backend {requested!r}; expected one of "
                f"cuda, llvm, scalar or a variant such as {', '.join(sorted(available))}"
            )
        if name not in available:
            raise InputError(f"{ENV_VARIANT}/prefer: Mitsuba has no variant {name!r}; available: {', '.join(sorted(available))}")
        be = backend_of(name)
        if be == "cuda" and not cuda_ok:
            return _fallback("requested cuda, but no CUDA device is usable", cuda_ok, llvm_ok, llvm_why, fix)
        if be == "llvm" and not llvm_ok:
            return "scalar_rgb", "scalar", f"requested {name}, but {llvm_why}; falling back to scalar_rgb (slow); {fix}"
        return name, be, f"variant {name} chosen by request"
    return _fallback("", cuda_ok, llvm_ok, llvm_why, fix)


def _fallback(prefix, cuda_ok, llvm_ok, llvm_why, fix):
    lead = prefix + "; " if prefix else ""
    if cuda_ok:
        return VARIANT_FOR_BACKEND["cuda"], "cuda", prefix
    if llvm_ok:
        name = VARIANT_FOR_BACKEND["llvm"]
        return name, "llvm", f"{prefix}; rendering with {name} on the CPU instead" if prefix else ""
    return "scalar_rgb", "scalar", f"{lead}{llvm_why}; falling back to scalar_rgb (slow: expect minutes per frame); {fix}"


# ------------------------------------------------------------------------- wiring
def select_variant(prefer: str | None = None) -> VariantInfo:
    """Choose and set the Mitsuba variant, never aborting the process.

    Idempotent: the first call decides (Dr.Jit can load only one LLVM per process);
    later calls return the same :class:`VariantInfo` unless ``prefer`` asks for another
    variant, which is then set if possible.

    Parameters
    ----------
    prefer : str, optional
        Full variant name or backend (``"cuda"``, ``"llvm"``, ``"scalar"``). Default:
        environment variable ``SVGS_MI_VARIANT``, else automatic (cuda > llvm > scalar).

    Returns
    -------
    VariantInfo
    """
    global _SELECTED
    requested = prefer or os.environ.get(ENV_VARIANT) or None
    if _SELECTED is not None and (requested is None or requested in (_SELECTED.requested, _SELECTED.name, _SELECTED.backend)):
        return _SELECTED

    notices = []
    candidates = llvm_candidates()
    chosen_path = os.environ.get(ENV_LIBLLVM)
    if "drjit" not in sys.modules:
        path, note = pick_llvm(candidates)
        if note:
            notices.append(note)
        if path:
            os.environ[ENV_LIBLLVM] = path
            chosen_path = path
        elif os.environ.get(ENV_LIBLLVM):
            # only incompatible choices: do not let Dr.Jit load the user's bad library
            os.environ.pop(ENV_LIBLLVM)
            chosen_path = None
    elif _SELECTED is None:
        notices.append("drjit was imported before select_variant(); its LLVM library could not be chosen")

    import drjit as dr
    import mitsuba as mi

    want_llvm = True
    want_cuda = True
    if requested and requested.strip().lower().startswith("scalar"):
        want_llvm = want_cuda = False  # do not even initialise the JIT backends
    cuda_ok = bool(want_cuda and _has_backend(dr, "CUDA"))
    llvm_version = None
    if want_llvm and _has_backend(dr, "LLVM"):
        try:
            llvm_version = tuple(int(x) for x in dr.detail.llvm_version())
        except Exception:  # noqa: BLE001
            llvm_version = None
    name, backend, note = decide(requested, cuda_ok=cuda_ok, llvm_version=llvm_version,
                                 llvm_path=chosen_path, available=mi.variants())
    if note:
        notices.append(note)
    mi.set_variant(name)
    if is_fallback(requested, name):  # not silent: every command that renders says it, once
        print(f"svgs: note: {fallback_line(requested, name, notice=note)}", file=sys.stderr, flush=True)
    _SELECTED = VariantInfo(
        name=name, backend=backend, llvm_path=chosen_path if backend == "llvm" else chosen_path,
        llvm_version=llvm_version, notice="; ".join(n for n in notices if n), requested=requested,
        candidates=tuple((p, v) for p, v, _ in candidates),
    )
    return _SELECTED


def is_fallback(requested: str | None, name: str) -> bool:
    """Whether variant ``name`` is not what was asked: an explicit request (a backend or a
    variant) that could not be met, or the slow scalar variant chosen automatically.

    Parameters
    ----------
    requested : str or None
        The request (argument or ``SVGS_MI_VARIANT``); None = automatic.
    name : str
        The variant chosen.

    Returns
    -------
    bool
    """
    if not requested:
        return name.startswith("scalar")
    req = requested.strip().lower()
    return name != req and name != VARIANT_FOR_BACKEND.get(req)


def fallback_line(requested: str | None, name: str, notice: str = "") -> str:
    """The one line that says a fallback (:func:`is_fallback`): what was asked, what is used, why.

    Parameters
    ----------
    requested : str or None
    name : str
        The variant chosen.
    notice : str
        The reason (:func:`decide`'s notice).

    Returns
    -------
    str
    """
    asked = (f"{ENV_VARIANT}={requested}" if requested and os.environ.get(ENV_VARIANT) == requested
             else f"variant {requested!r} requested" if requested else "automatic variant choice")
    why = " ".join(notice.split()) or f"rendering with {name} instead"
    return f"{asked}: {why}"


def _has_backend(dr, which: str) -> bool:
    try:
        return bool(dr.has_backend(getattr(dr.JitBackend, which)))
    except Exception:  # noqa: BLE001 - a missing driver is "not available", not an error
        return False


def backend_report(info: VariantInfo) -> dict:
    """What the selected variant can use, for ``svgs doctor``.

    Parameters
    ----------
    info : VariantInfo
        From :func:`select_variant`.

    Returns
    -------
    dict
        ``mitsuba_variants`` (list of str) and ``backends`` (``{"cuda": bool, "llvm": bool}``).
    """
    import drjit as dr
    import mitsuba as mi

    return {
        "mitsuba_variants": list(mi.variants()),
        "backends": {"cuda": bool(info.backend == "cuda" or _has_backend(dr, "CUDA")),
                     "llvm": info.llvm_version is not None},
    }


def renderer_versions() -> dict:
    """``{"mitsuba": ..., "drjit": ...}`` version strings, or ``{}`` without Mitsuba."""
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError:  # pragma: no cover - the render extra is not installed
        return {}
    return {"mitsuba": mi.__version__, "drjit": dr.__version__}

