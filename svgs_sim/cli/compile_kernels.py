"""Compile the numba kernels once, ahead of the first command (``make`` runs this after it installs).

The collinearity solver (:mod:`svgs_sim.svgs._lm_kernel`, :mod:`svgs_sim.base.distortion`) and the
phone sensor (:mod:`svgs_sim.camera.phone.sensor`, with the approach's meter, optical composition and
deferred dark pixels in :mod:`svgs_sim.camera.phone.isp` and :mod:`svgs_sim.camera.phone.optics`) are
numba kernels cached on disk (``cache=True``): the first process that calls them spends about
15-20 s compiling the common signatures (about a minute with every signature of
:data:`EXTRA_SIGNATURES`), every later one loads them in well under a second. Compiling here, with
a status line, keeps that pause out of a fresh checkout's first ``make demo`` or solve.

Run: ``python -m svgs_sim.cli.compile_kernels``. Prints one line per kernel family on stderr.
"""

from __future__ import annotations

import sys
import time


#: Modules whose numba kernels are cached on disk (``cache=True``).
KERNEL_MODULES = ("svgs_sim.svgs._lm_kernel", "svgs_sim.base.distortion", "svgs_sim.camera.phone.sensor")


def numba_cache_folders(src) -> list:
    """The folders where numba may keep the cache of the kernels of the module file ``src``, in
    its order: ``NUMBA_CACHE_DIR`` if set; else the module's ``__pycache__`` and, where that is
    not writable (an install in a read-only site-packages), the user-wide cache
    (``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``, under ``<folder>_<sha1 of the folder's path>``,
    as ``numba.core.caching.UserWideCacheLocator`` names it)."""
    import hashlib
    import os
    from pathlib import Path

    src = Path(src).resolve()
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        return [Path(root)]
    folder = str(src.parent)
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba"
    return [src.parent / "__pycache__",
            user / f"{os.path.split(folder)[-1]}_{hashlib.sha1(folder.encode()).hexdigest()}"]


def kernels_cached() -> bool:
    """True when every kernel module has a numba cache index (``*.nbi``) in one of the places numba
    keeps it (:func:`numba_cache_folders`; the notice of a first compile printed on every run when
    the cache was in the user-wide folder, issue 41). Imports nothing heavy (``svgs solve`` must
    not load the camera package)."""
    from pathlib import Path

    project = Path(__file__).resolve().parents[2]  # the folder that holds svgs_sim/
    for mod in KERNEL_MODULES:
        src = project.joinpath(*mod.split(".")).with_suffix(".py")
        if not src.is_file():
            return False
        hits = [h for d in numba_cache_folders(src) if d.is_dir() for h in d.rglob(f"{src.stem}*.nbi")]
        if not hits:
            return False
    return True


#: The signatures the project's callers give each kernel, beyond those the calls of
#: :func:`compile_kernels` make: numba builds machine code per signature, and a read-only array
#: (a cached map, a view of a frozen profile table) or a strided crop is a signature of its own.
#: Compiled here, a fresh install compiles none of them in the middle of a run (issue 40: 17 of
#: them were compiled during the first test run of a fresh clone). Notation: ``f4[2]`` is a
#: C-contiguous float32 array of 2 dimensions; ``ro`` read-only; ``A`` any layout.
EXTRA_SIGNATURES = {
    "svgs_sim.camera.phone.sensor._charge_kernel": [
        "f4[2], f8, f4[2]ro, b1, f8, f4[2]ro, u8, u8, b1, b1, i8, i8, i8, f4[2]",
        "f4[2], f8, f4[2]Aro, b1, f8, f4[2]Aro, u8, u8, b1, b1, i8, i8, i8, f4[2]",
        "f4[2], f8, f4[2]ro, b1, f8, f4[2], u8, u8, b1, b1, i8, i8, i8, f4[2]",
        "f4[2], f8, f4[2], b1, f8, f4[2], u8, u8, b1, b1, i8, i8, i8, f4[2]",
        "f4[2], f8, f4[2]A, b1, f8, f4[2]A, u8, u8, b1, b1, i8, i8, i8, f4[2]"],
    "svgs_sim.camera.phone.sensor._charge_kernel_dark": [
        "f4[2], f8, f4[2]ro, b1, f8, f4[2], u8, u1[2], i8, i8[2]ro, i4[2]ro, f4[2]",
        "f4[2], f8, f4[2]ro, b1, f8, f4[2]ro, u8, u1[2], i8, i8[2]ro, i4[2]ro, f4[2]"],
    "svgs_sim.camera.phone.sensor._tile_max_kernel": ["f4[2], i8, f8[2]"],
    "svgs_sim.camera.phone.isp._meter_range": ["f8[1], f8, f8, f8, i8", "f4[1], f8, f8, f8, i8"],
    "svgs_sim.camera.phone.isp._meter_bins": [
        f"{x}[1], f8, f8, f8, f8[1]{ro}, f8, f8, f8, i8, i8, f8[2], f8[2], f8[1]"
        for x in ("f8", "f4") for ro in ("", "ro")],
    "svgs_sim.camera.phone.isp._meter_bins_f32": [
        f"f4[1], i4[1], f8, f8, f8, f8[1]{ro}, f8, i8, i8, i4[1], i8[1], i8, i8, f8[2], f8[2]" for ro in ("", "ro")],
    "svgs_sim.camera.phone.optics._compose_kernel": [
        f"f8[2], f8, f8[2], i8, f8, f8[2]{a}, f8, b1, f4[2]{b}, f8[2], f4[2]{c}, b1, f4[2]"
        for a, b, c in (("", "ro", ""), ("ro", "ro", ""), ("", "ro", "ro"), ("", "", ""))],
    "svgs_sim.camera.phone.cfa._plane_lut_kernel": ["u2[3], u1[2], u1[3]", "u2[3], f4[2], f4[3]"],
    "svgs_sim.camera.phone.cfa._luma_tone_kernel": ["u2[3], f8[2], u1[1], u1[2]"],
    "svgs_sim.svgs._lm_kernel.lm_batch": ["f8[3], f8[2], f8[2], f8[3], f8[4], i8, f8, b1[1]"],
    "svgs_sim.svgs._lm_kernel._solve_frame": [
        f"{k}, f8[3], f8[2], f8[2], f8[3], f8[4], i8, f8, b1[1], b1[1], i8[1], f8[2], f8[3], f8[1]" for k in ("i8", "u8")],
}


def parse_signature(text: str) -> tuple:
    """The numba argument types of one :data:`EXTRA_SIGNATURES` line.

    Parameters
    ----------
    text : str
        Comma-separated words: ``f8``, ``f4``, ``i8``, ``i4``, ``u8``, ``u2``, ``u1``, ``b1`` for a
        scalar; ``f4[2]`` a C-contiguous array of 2 dimensions, ``f4[2]A`` of any layout, a
        trailing ``ro`` read-only.

    Returns
    -------
    tuple
        numba types, one per argument.

    Raises
    ------
    ValueError
        A word that is none of these.
    """
    import re

    from numba import types

    scalars = {"f8": types.float64, "f4": types.float32, "i8": types.int64, "i4": types.int32, "u8": types.uint64,
               "u2": types.uint16, "u1": types.uint8, "b1": types.boolean}
    out = []
    for word in (w.strip() for w in text.split(",")):
        m = re.fullmatch(r"(\w\d)(?:\[(\d)\](A?)(ro)?)?", word)
        if not m or m.group(1) not in scalars:
            raise ValueError(f"not a kernel signature word: {word!r} in {text!r}")
        dt, nd, any_layout, ro = m.groups()
        out.append(scalars[dt] if nd is None else
                   types.Array(scalars[dt], int(nd), "A" if any_layout else "C", readonly=bool(ro)))
    return tuple(out)


def compile_signatures(table=None) -> int:
    """Compile (or load from numba's cache) every signature of :data:`EXTRA_SIGNATURES`.

    Parameters
    ----------
    table : dict, optional
        ``{"module.kernel": [signature, ...]}`` (default :data:`EXTRA_SIGNATURES`).

    Returns
    -------
    int
        Signatures compiled or loaded.
    """
    import importlib

    n = 0
    for path, sigs in (EXTRA_SIGNATURES if table is None else table).items():
        mod, name = path.rsplit(".", 1)
        kernel = getattr(importlib.import_module(mod), name)
        for text in sigs:
            kernel.compile(parse_signature(text))
            n += 1
    return n


def compile_kernels(out=None) -> dict:
    """Call each kernel family once on a small input, so numba compiles and caches it.

    Parameters
    ----------
    out : file, optional
        Where the status lines go (default stderr).

    Returns
    -------
    dict
        Seconds per family: ``{"solver_s": float, "sensor_s": float, "signatures_s": float}``.
    """
    import numpy as np

    out = sys.stderr if out is None else out
    print("compiling the solver and camera kernels (first run only; cached for later runs) ...", file=out, flush=True)
    from svgs_sim.sim.trials import geometric_warm_up
    from svgs_sim.svgs.frames import pose_from_scenario
    from svgs_sim.base.profiles import load_camera, load_pattern
    from svgs_sim.svgs.solver import solve_centroids

    t0 = time.perf_counter()
    geometric_warm_up()
    load_camera("galaxy-nexus").replace(dist=np.array([0.01, 0.0, 0.0, 0.0, 0.0])).undistort_normalized(
        np.zeros((4, 2)))  # the parallel undistortion kernel
    cam, pat = load_camera("galaxy-nexus"), load_pattern("svgs-3u")
    uv = cam.project_target(pat.points_m, *pose_from_scenario(10.0, 0.1, -0.1, 2.0, -3.0, 4.0))
    solve_centroids(np.stack([uv, uv]), cam, pat)  # the batch kernel
    solver_s = time.perf_counter() - t0
    print(f"  solver: {solver_s:.1f} s", file=out, flush=True)

    from svgs_sim.camera.phone import Exposer, PhoneCamera
    from svgs_sim.camera.phone.isp import ExposureSolver

    t0 = time.perf_counter()
    flux = np.zeros((cam.height, cam.width), np.float32)
    flux[cam.height // 2, cam.width // 2] = 1e9  # one bright spot: blooming and clipping paths too
    PhoneCamera(cam).expose(flux, seed=0)
    # the approach's path: the auto-exposure's meter, the optics' one-pass composition and the
    # deferred dark pixels (their tile bound)
    flux[:] = 1.0
    flux[cam.height // 2, cam.width // 2] = 1e9
    ex = Exposer(PhoneCamera(cam), flux, background=(1.0, np.ones_like(flux)))
    ex.expose(seed=0, dark_pixels="deferred", threshold_u8=64.0).detect_image
    for metering in ("mean", "center_weighted"):  # the meter of a float32 flux (both weightings)
        ExposureSolver.from_flux(ex.flux_optics.astype(np.float32), ex.phone.params.sensor, metering)
    sensor_s = time.perf_counter() - t0
    print(f"  camera sensor: {sensor_s:.1f} s", file=out, flush=True)
    t0 = time.perf_counter()
    n = compile_signatures()
    other_s = time.perf_counter() - t0
    print(f"  {n} more signatures (read-only and strided arrays, the meter's and the solver's): {other_s:.1f} s",
          file=out, flush=True)
    return {"solver_s": solver_s, "sensor_s": sensor_s, "signatures_s": other_s}


def main() -> int:
    compile_kernels()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
