"""Compile the numba kernels once, ahead of the first command (``make`` runs this after it installs).

The collinearity solver (:mod:`svgs_sim.svgs._lm_kernel`, :mod:`svgs_sim.base.distortion`) and the
phone sensor (:mod:`svgs_sim.camera.phone.sensor`, with the approach's meter, optical composition and
deferred dark pixels in :mod:`svgs_sim.camera.phone.isp` and :mod:`svgs_sim.camera.phone.optics`) are
numba kernels cached on disk (``cache=True``):
the first process that calls them spends about 15-20 s compiling, every later one loads them in well under a second. Compiling here,
with a status line, keeps that pause out of a fresh checkout's first ``make demo`` or solve.

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


def compile_kernels(out=None) -> dict:
    """Call each kernel family once on a small input, so numba compiles and caches it.

    Parameters
    ----------
    out : file, optional
        Where the status lines go (default stderr).

    Returns
    -------
    dict
        Seconds per family: ``{"solver_s": float, "sensor_s": float}``.
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
    return {"solver_s": solver_s, "sensor_s": sensor_s}


def main() -> int:
    compile_kernels()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
