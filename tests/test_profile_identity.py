"""A profile is read once and known by its key: along one ``svgs render-and-solve``, one short
``svgs approach`` and one ``svgs render``, run one after another in a process through the console
script's entry point, each TOML file is opened at most once (an audit hook on ``open``), and a
copy of a profile under another display name is the same camera (the same threshold, overlay and
solution)."""

from __future__ import annotations

import collections
import json
import subprocess
import sys
from pathlib import Path

import pytest

from svgs_sim.base.profiles import Camera
from svgs_sim.cli.main import main

#: Runs the ``svgs`` console script's entry point (found with importlib.metadata) once for each
#: command line given as JSON in argv[1], in one process, with an audit hook that counts every open
#: of a ``.toml`` file; prints each command's exit code and counts as JSON on stderr's last line.
AUDITED = """\
import collections, json, sys
from importlib.metadata import entry_points
opens = collections.Counter()
def hook(event, args):
    if event == "open" and isinstance(args[0], (str, bytes)) and str(args[0]).endswith(".toml"):
        opens[str(args[0])] += 1
sys.addaudithook(hook)
(ep,) = [e for e in entry_points(group="console_scripts") if e.name == "svgs"]
runs = []
for args in json.loads(sys.argv[1]):
    opens.clear()
    sys.argv = ["svgs", *args]
    try:
        rc = ep.load()()
    except SystemExit as exc:
        rc = exc.code
    runs.append({"rc": rc, "opens": dict(opens)})
print(json.dumps(runs), file=sys.stderr)
"""


def _audited(commands, cwd) -> list[dict]:
    p = subprocess.run([sys.executable, "-c", AUDITED, json.dumps(commands)], cwd=cwd, capture_output=True,
                       text=True, timeout=600)
    return json.loads(p.stderr.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.render
def test_each_toml_file_is_opened_at_most_once(tmp_path):
    """The three commands run one after another in one process (one start-up of the renderer):
    the first reads each profile once, the later ones find it loaded. Each command's files are
    opened at most once, and over the three together too."""
    ras, appr, render = runs = _audited([
        ["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--seed", "1"],
        ["approach", "--camera", "galaxy-nexus", "--from", "10", "--to", "8", "--duration", "2",
         "--fps", "1", "--out", str(tmp_path / "approach"), "--no-progress"],
        ["render", "--camera", "galaxy-nexus", "--range", "10", "--seed", "1",
         "--out", str(tmp_path / "render")],  # the same route as render-and-solve
    ], tmp_path)
    total = collections.Counter()
    for run in runs:
        assert run["rc"] == 0
        assert not run["opens"] or max(run["opens"].values()) == 1, run["opens"]
        total.update(run["opens"])
    names = {Path(p).name for p in ras["opens"]}
    assert {"galaxy-nexus.toml", "svgs-3u.toml", "svgs-app.toml"} <= names  # the hook sees the reads
    assert max(total.values()) == 1, total  # a profile read once is known by its key afterwards


@pytest.mark.slow
@pytest.mark.render
def test_a_copied_profile_under_another_name_renders_and_solves_the_same(tmp_path, capsys):
    src = Path(Camera.load("galaxy-nexus", fitted=False).source)
    copy = tmp_path / "my-copy.toml"
    copy.write_text(src.read_text().replace('name = "galaxy-nexus"', 'name = "my-copy"'))
    runs = []
    for camera in ("galaxy-nexus", str(copy)):
        assert main(["render-and-solve", "--camera", camera, "--range", "10", "--seed", "1", "--json"]) == 0
        runs.append(json.loads(capsys.readouterr().out))
    a, b = runs
    assert a["detector"] == b["detector"] == {"camera_key": "galaxy-nexus", "threshold": 64.0,
                                              "threshold_source": "app by_camera[galaxy-nexus]",
                                              "fitted_overlay": "fitted/galaxy-nexus.toml"}
    assert a["state"] == b["state"] and a["exposure_s"] == b["exposure_s"]


# --------------------------------------------------------------------------- one loader
PACKAGE = Path(__file__).resolve().parents[1] / "svgs_sim"
#: The loader: the only module that reads a profile's tables, parses TOML or loads uncached.
LOADER = PACKAGE / "base" / "profiles.py"


def _loader_breaches(source: str) -> list[str]:
    """What in ``source`` bypasses the loader: a ``.tables`` read, ``tomllib``, an uncached
    ``Camera.load``/``Pattern.load``."""
    import ast

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr == "tables":
            found.append(f"line {node.lineno}: .tables (read the typed parts: camera.optics, camera.flash...)")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] + ([node.module] if isinstance(node, ast.ImportFrom) else [])
            if "tomllib" in names:
                found.append(f"line {node.lineno}: tomllib (read files with svgs_sim.base.profiles.read_toml)")
        elif (isinstance(node, ast.Attribute) and node.attr == "load" and isinstance(node.value, ast.Name)
              and node.value.id in ("Camera", "Pattern")):
            found.append(f"line {node.lineno}: {node.value.id}.load (use load_camera / load_pattern: one cache)")
    return found


def test_no_module_but_the_loader_reads_raw_profile_tables_or_toml():
    """Profiles are parsed and checked once, by the loader; every other module reads frozen
    objects (svgs_sim.base.profile_parts) and loads through the one cache."""
    breaches = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == LOADER:
            continue
        found = _loader_breaches(path.read_text(encoding="utf-8"))
        if found:
            breaches[str(path.relative_to(PACKAGE.parent))] = found
    assert not breaches, breaches


def test_the_loader_check_finds_each_kind_of_breach():
    src = ("import tomllib\n"
           "def f(cam):\n"
           "    return cam.tables.get('optics'), Camera.load('x')\n")
    found = _loader_breaches(src)
    assert sorted(f.split(":")[1].split()[0] for f in found) == [".tables", "Camera.load", "tomllib"], found


def test_a_profile_is_a_tree_of_frozen_parts():
    import dataclasses

    from svgs_sim.base.profiles import load_camera, load_pattern

    cam = load_camera("galaxy-nexus")
    assert cam.optics.f_number == 2.4 and cam.sensor.pixel_pitch_m == 1.4e-6
    assert cam.flash.led_offsets_m == ((0.008, 0.0, 0.0),)  # one LED, normalised to a list of them
    assert not cam.tof and cam.optics  # a phone has no [tof] table
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.optics.f_number = 2.8
    assert {f.key for f in cam.fitted} >= {"exposure.mode"}
    tof = load_camera("tof-epc660")
    assert tof.tof.modulation_frequency_hz == 10e6 and tof.is_tof and not cam.is_tof
    pat = load_pattern("svgs-3u")
    assert pat.reflector.model == "edmund-nbk7-12.7mm" and [t.id for t in pat.targets] == list(pat.ids)
    # a value changed through the loader is checked by the schema
    from svgs_sim.base.errors import ProfileError
    with pytest.raises(ProfileError, match=r"\[optics\] f_number = 0.1"):
        cam.with_values([("optics", "f_number", 0.1)])
    assert cam.with_values([("optics", "f_number", 2.8)]).optics.f_number == 2.8  # parts built again
    assert cam.replace(fx=cam.fx * 1.01).optics is cam.optics  # a copy's geometry only: parts shared
