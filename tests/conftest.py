"""Shared fixtures. Paths are relative to this file, never to the working directory.

The markers (pyproject.toml): ``render`` - the test needs Mitsuba (it renders, or selects
a renderer variant); ``slow`` - the test takes more than a few seconds of CPU (a study run,
a process pool, a subprocess that imports the renderer). ``make test-fast`` runs neither;
:func:`_mitsuba_needs_the_render_marker` fails an unmarked test that imports Mitsuba.
"""

import os
import sys
from pathlib import Path


def _share_the_cores() -> None:
    """Under pytest-xdist (``make test``: three workers on two cores), give each worker's numba,
    OpenMP and BLAS thread pools its share of the cores, not one thread per core each: numba's
    busy-waiting pool slows down many times over when the processes' threads outnumber the cores
    (issue 40: the solver's 10,000-pose test 16.5 s -> 1.0 s, the suite 381 -> 349-353 s; the
    renderer's Dr.Jit pool made no difference either way and keeps its threads). Set before numpy
    and numba load; the subprocesses the tests start inherit it; a value already set is kept.
    A study's own process pool keeps numba's default (one thread per core measured faster there)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT") or 0)
    if workers > 1:
        try:
            cores = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):
            cores = os.cpu_count() or 1
        for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            os.environ.setdefault(var, str(max(1, cores // workers)))


_share_the_cores()

import numpy as np  # noqa: E402
import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
#: Modules only the renderer loads; a test that imports one needs the ``render`` marker.
RENDERER_MODULES = ("mitsuba", "drjit")


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist, the test files in order of their duration in ``tests/durations.json``,
    heaviest first (a file not in it: the median), each file's tests in their own order. ``make
    test`` hands the files out in this order (``--dist loadfile --no-loadscope-reorder``), so the
    long files start early and the short ones fill the end (tools/test_durations.py writes it)."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    import json

    path = Path(__file__).with_name("durations.json")
    seconds = json.loads(path.read_text())["files"] if path.is_file() else {}
    if not seconds:
        return
    default = float(np.median(list(seconds.values())))
    first = {}
    for i, item in enumerate(items):
        first.setdefault(item.nodeid.split("::")[0], i)
    items.sort(key=lambda it: (-seconds.get(it.nodeid.split("::")[0], default), first[it.nodeid.split("::")[0]]))


@pytest.fixture(autouse=True)
def _mitsuba_needs_the_render_marker(request):
    """Fail a test without the ``render`` marker that imports Mitsuba or Dr.Jit in this process.

    Checked when the renderer was not loaded before the test (always so in ``make test-fast``,
    which deselects the marked tests; in a full run, after the first marked test, an unmarked
    one that renders is no longer seen). Renders in a subprocess or a process pool's workers
    are not seen: mark those tests by hand."""
    if request.node.get_closest_marker("render") is not None:
        yield
        return
    before = {m for m in RENDERER_MODULES if m in sys.modules}
    yield
    loaded = [m for m in RENDERER_MODULES if m in sys.modules and m not in before]
    if loaded:
        pytest.fail(f"{request.node.nodeid} imported {', '.join(loaded)} without the 'render' marker: "
                    "add @pytest.mark.render (it needs Mitsuba)", pytrace=False)


@pytest.fixture(scope="session")
def nexus():
    from svgs_sim.base.profiles import Camera

    return Camera.load("galaxy-nexus", fitted=False)  # geometry for model tests: no fitted values


@pytest.fixture(scope="session")
def pattern():
    from svgs_sim.base.profiles import Pattern

    return Pattern.load("svgs-3u")


@pytest.fixture(scope="session")
def small_camera(tmp_path_factory):
    """The Galaxy Nexus profile scaled to 648 x 486 (the same lens delivering a quarter-size
    image): a path to its .toml, for rendered tests that need frames of about a second. Its own
    key: not the Galaxy Nexus's test set-up, so the app's default threshold."""
    from svgs_sim.base.profiles import Camera

    path = tmp_path_factory.mktemp("cam") / "nexus-small.toml"
    Camera.load("galaxy-nexus").scaled(648, 486).replace(name="nexus-small", key="nexus-small").save(path)
    return str(path)


def random_envelope_poses(n, seed, range_interval_m=(1.0, 40.0)):
    """Poses drawn over the paper's test envelope: range log-uniform, roll/pitch +/-25 deg,
    yaw +/-45 deg, lateral offsets up to +/-15 % of range. Returns (R (n,3,3), t (n,3))."""
    from svgs_sim.svgs.frames import pose_from_scenario, sample_envelope_scenario

    rng = np.random.default_rng(seed)
    Rs, ts = [], []
    for _ in range(n):
        R, t = pose_from_scenario(**sample_envelope_scenario(rng, range_interval_m=range_interval_m))
        Rs.append(R)
        ts.append(t)
    return np.array(Rs), np.array(ts)
