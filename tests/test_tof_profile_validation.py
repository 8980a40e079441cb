"""The ToF camera profile's ``[tof]``, ``[noise]``, ``[illumination]`` and the ToF target's
``[plate]``, ``[marker]`` values are checked when the file is loaded: a bad value ends a ToF
command with exit 2 before any render, in one line naming the file, the table, the key and the
allowed range, with nothing written; the shipped files and values at the edge of their ranges
load.

The bad files are the shipped ones (``assets/cameras/tof-epc660.toml``,
``assets/patterns/tof-8.toml``) with one value changed, written to ``tmp_path``. The ranges
the messages must name are the physical ones (a contrast, an efficiency, a duty cycle or a
reflectance is a fraction; a cone's full angle is below 180 deg; natural light is below
2e5 lux: direct sunlight is ~1.1e5 lux), and the choices are those the files' own comments list.
"""

import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from svgs_sim.assets import ASSETS_DIR
from svgs_sim.cli.main import main
from svgs_sim.base.profiles import CAMERAS_DIR, PATTERNS_DIR

TOF_CAMERA = CAMERAS_DIR / "tof-epc660.toml"
TOF_PATTERN = PATTERNS_DIR / "tof-8.toml"
#: The sheeting tables the renderer knows, read from the asset itself.
SHEETING_FILE = ASSETS_DIR / "materials" / "retroreflective-sheeting.toml"
SHEETINGS = [t["name"] for t in tomllib.loads(SHEETING_FILE.read_text(encoding="utf-8"))["sheeting"]]


def _edited(src: Path, changes: dict) -> dict:
    """``src`` parsed, with ``{(table, key): value}`` set (None: the key deleted)."""
    data = tomllib.loads(src.read_text(encoding="utf-8"))
    for (table, key), value in changes.items():
        if value is None:
            del data[table][key]
        else:
            data[table][key] = value
    return data


def _write(tmp_path, src: Path, changes: dict, name: str) -> Path:
    path = tmp_path / name
    path.write_bytes(tomli_w.dumps(_edited(src, changes)).encode())
    return path


# (table, key, bad value, what the one line must say besides the file: the table and key, the
# allowed range or choices). Per table: a wrong type, a value out of range, an unknown choice
# (where the table has text values) and an unknown key.
BAD_CAMERA = [
    ("tof", "modulation_frequency_hz", "10 MHz", ("[tof] modulation_frequency_hz", "(0, 1e+09]")),
    ("tof", "demodulation_contrast", 1.5, ("[tof] demodulation_contrast", "(0, 1]")),
    ("tof", "adc_bits", 12.5, ("[tof] adc_bits", "whole number")),
    ("tof", "depth_kind", "spherical", ("[tof] depth_kind", "'radial', 'z'")),
    ("tof", "integration_time_s", "manual", ("[tof] integration_time_s", "'auto' or")),
    ("tof", "gray_modes", ["active", "infrared"], ("[tof] gray_modes", "'active', 'passive'")),
    # the file's maximum is 1 ms: a minimum of 5 ms exceeds it
    ("tof", "integration_time_min_s", 5e-3, ("[tof] integration_time_min_s", "exceeds integration_time_max_s = 0.001")),
    ("tof", "modulation_freq_hz", 1e7, ("[tof]", "unknown key", "modulation_freq_hz")),
    ("noise", "read_noise_e", "30", ("[noise] read_noise_e", "[0, 10000]")),
    ("noise", "quantum_efficiency", 1.2, ("[noise] quantum_efficiency", "(0, 1]")),
    ("noise", "ambient_lux", 1e6, ("[noise] ambient_lux", "[0, 200000]")),
    ("noise", "ambient_suppression", -0.1, ("[noise] ambient_suppression", "[0, 1]")),
    ("noise", "shot_noise", True, ("[noise]", "unknown key", "shot_noise")),
    ("illumination", "model", 4715, ("[illumination] model", "text")),
    ("illumination", "n_emitters", 8.5, ("[illumination] n_emitters", "whole number")),
    ("illumination", "duty_cycle", 0.0, ("[illumination] duty_cycle", "(0, 1]")),
    ("illumination", "divergence_full_angle_deg", 180.0, ("[illumination] divergence_full_angle_deg", "(0, 180)")),
    ("illumination", "offset_from_lens_m", [0.0, 0.0], ("[illumination] offset_from_lens_m", "[x, y, z]")),
    ("illumination", "colour", "infrared", ("[illumination]", "unknown key", "colour")),
]

BAD_PATTERN = [
    ("plate", "width_m", "0.40", ("[plate] width_m", "(0, 100]")),
    ("plate", "width_m", -0.40, ("[plate] width_m", "(0, 100]")),
    ("plate", "albedo", 1.2, ("[plate] albedo", "[0, 1]")),
    ("plate", "material", "steel", ("[plate]", "unknown key", "material")),
    ("plate", "centre_m", [0.0, -0.125], ("[plate] centre_m", "[x, y, z]")),
    # the plate 25 mm nearer the faces than the file's standoffs put it: the posts would not reach
    ("plate", "centre_m", [-0.0225, 0.000625, -0.1], ("target 1: standoff_m = 0.1", "[plate] centre_m z = -0.1")),
    ("marker", "albedo", "white", ("[marker] albedo", "[0, 1]")),
    ("marker", "post_diameter_ratio", 1.0, ("[marker] post_diameter_ratio", "(0, 1)")),
    ("marker", "material", "mirror", ("[marker] material", "'retroreflective', 'lambertian'")),
    ("marker", "sheeting", "tinfoil", ("[marker] sheeting", *(repr(s) for s in SHEETINGS))),
    ("marker", "colour", "white", ("[marker]", "unknown key", "colour")),
]


@pytest.fixture(autouse=True)
def _warm():
    """Import what the ToF commands import first, so the time measured is the check's."""
    import importlib

    for module in ("svgs_sim.cli.tof", "svgs_sim.cli.tof_render", "svgs_sim.cli.tof_stability", "svgs_sim.sim.tof_closed_loop", "svgs_sim.render.tof.camera"):
        importlib.import_module(module)


def _run(argv, capsys):
    t0 = time.perf_counter()
    rc = main(argv)
    elapsed_s = time.perf_counter() - t0
    return rc, elapsed_s, capsys.readouterr()


def _assert_refused(rc, elapsed_s, cap, command, file, words):
    assert rc == 2, cap.err[-600:]
    assert "Traceback" not in cap.err and cap.out == ""
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(lines) == 1, cap.err
    assert lines[0].startswith(f"svgs {command}: error:") and str(file) in lines[0], lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert elapsed_s < 1.0, f"{elapsed_s:.2f} s: refused after some work"  # a render takes seconds


def _nothing_written(out: Path):
    assert not out.exists() or not any(out.iterdir()), sorted(p.name for p in out.iterdir())


def _ids(cases):
    return [f"{t}.{k}={v!r}" for t, k, v, _ in cases]


#: Every bad value of both files, with the option that passes the file and the file it edits.
BAD_FILES = ([("--camera", TOF_CAMERA, "bad-tof-camera.toml", *c) for c in BAD_CAMERA]
             + [("--pattern", TOF_PATTERN, "bad-tof-pattern.toml", *c) for c in BAD_PATTERN])


@pytest.mark.parametrize("option, base, name, table, key, value, words", BAD_FILES,
                         ids=[f"{o[2:]}:{i}" for (o, *_), i in zip(BAD_FILES, _ids(BAD_CAMERA) + _ids(BAD_PATTERN))])
def test_bad_tof_value_refused_before_the_render(tmp_path, capsys, option, base, name, table, key, value, words):
    bad = _write(tmp_path, base, {(table, key): value}, name)
    out = tmp_path / "out"
    rc, dt, cap = _run(["tof", "render-and-solve", option, str(bad), "--range", "5", "--out", str(out)], capsys)
    _assert_refused(rc, dt, cap, "tof render-and-solve", bad, words)
    _nothing_written(out)


@pytest.mark.parametrize("which", ["camera", "pattern"])
def test_the_other_tof_commands_refuse_the_same_files(tmp_path, capsys, which):
    """``svgs tof solve`` (real frames: no renderer at all) and ``svgs tof stability`` load the
    same files the same way."""
    if which == "camera":
        bad = _write(tmp_path, TOF_CAMERA, {("noise", "quantum_efficiency"): 1.2}, "bad.toml")
        words = ("[noise] quantum_efficiency", "(0, 1]")
    else:
        bad = _write(tmp_path, TOF_PATTERN, {("marker", "material"): "mirror"}, "bad.toml")
        words = ("[marker] material", "'retroreflective', 'lambertian'")
    gray, depth = tmp_path / "gray.npy", tmp_path / "depth.npy"
    np.save(gray, np.zeros((240, 320), np.float32))
    np.save(depth, np.full((240, 320), 5.0, np.float32))
    flag = ["--camera" if which == "camera" else "--pattern", str(bad)]
    out = tmp_path / "out"
    for command, argv in (("tof solve", ["--gray", str(gray), "--depth", str(depth)]),
                          ("tof stability", ["--range", "5", "--frames", "2", "--out", str(out)])):
        rc, dt, cap = _run([*command.split(), *argv, *flag], capsys)
        _assert_refused(rc, dt, cap, command, bad, words)
    _nothing_written(out)


# ---------------------------------------------------------------------------- values that are fine
def test_the_shipped_tof_files_pass_the_check(tmp_path, capsys):
    """Copies of the shipped files pass the profile check: the command gets as far as the pose,
    where a target 100 m to the side is outside the field of view (refused, still before any
    render: the message is the pose's, not the profile's)."""
    cam = _write(tmp_path, TOF_CAMERA, {}, "camera.toml")
    pat = _write(tmp_path, TOF_PATTERN, {}, "pattern.toml")
    rc, dt, cap = _run(["tof", "render-and-solve", "--camera", str(cam), "--pattern", str(pat), "--range", "5",
                        "--x", "100"], capsys)
    assert rc == 2 and "outside the field of view" in cap.err and str(cam) not in cap.err, cap.err


# Values at the closed ends of their ranges, or of the other kind a key allows: each is physical.
EDGE_CAMERA = {
    ("tof", "demodulation_contrast"): 1.0,  # an ideal pixel
    ("tof", "integration_time_s"): 1.0e-4,  # a fixed integration time instead of "auto"
    ("tof", "depth_kind"): "z",
    ("tof", "min_amplitude_dn"): 0.0,  # every depth pixel valid
    ("noise", "read_noise_e"): 0.0,
    ("noise", "ambient_lux"): 0.0,  # darkness (space)
    ("noise", "ambient_suppression"): 1.0,
    ("illumination", "ring_radius_m"): 0.0,  # every emitter at the lens centre
    ("illumination", "radiant_flux_per_emitter_w"): None,  # the intensity alone gives the power
}
EDGE_PATTERN = {
    ("plate", "albedo"): 0.0,  # a perfectly black plate
    ("marker", "albedo"): 1.0,
    ("marker", "material"): "lambertian",
    ("marker", "sheeting"): SHEETINGS[-1],
}


def test_values_at_the_edges_of_their_ranges_are_accepted(tmp_path):
    from svgs_sim.camera.amcw import TofSensor
    from svgs_sim.render.tof.camera import Illumination
    from svgs_sim.render.tof.scene import TofSceneOptions, resolve_geometry
    from svgs_sim.tof.camera import depth_kind, load_camera, load_target

    cam = load_camera(_write(tmp_path, TOF_CAMERA, EDGE_CAMERA, "edge-camera.toml"), render=True)
    sensor = TofSensor.from_camera(cam)
    assert (sensor.demodulation_contrast, sensor.integration_time_s, sensor.min_amplitude_dn) == (1.0, 1.0e-4, 0.0)
    assert (sensor.read_noise_e, sensor.ambient_lux, sensor.ambient_suppression) == (0.0, 0.0, 1.0)
    assert depth_kind(cam) == "z"
    assert Illumination.from_camera(cam).ring_radius_m == 0.0
    target = load_target(_write(tmp_path, TOF_PATTERN, EDGE_PATTERN, "edge-pattern.toml"))
    geo = resolve_geometry(target, TofSceneOptions())
    assert geo.albedo["plate"] == 0.0 and geo.albedo["marker"] == 1.0
    assert geo.materials["marker"] == "lambertian"


def test_the_shared_tof_tables_agree_with_their_users():
    """The allowed values live in svgs_sim.base.profile_schema; the models that read the tables agree."""
    from dataclasses import fields

    from svgs_sim.camera.amcw import TofSensor
    from svgs_sim.render.tof import retro, scene
    from svgs_sim.render.tof.camera import Illumination
    from svgs_sim.base import profile_schema as ps

    assert list(ps.SHEETINGS) == SHEETINGS == retro.sheeting_names()
    assert scene.MATERIALS is ps.TOF_MATERIALS
    defaults = {f.name: f.default for f in fields(TofSensor)}
    assert {k: defaults[k] for k in ps.TOF_DEFAULTS["tof"]} == ps.TOF_DEFAULTS["tof"]
    # every sensor parameter is a key of the profile table it is read from ([optics] transmittance)
    tof_noise = set(ps.TOF_CAMERA_TABLES["tof"]) | set(ps.TOF_CAMERA_TABLES["noise"])
    assert set(defaults) - tof_noise == {"transmittance"}
    assert set(ps.TOF_CAMERA_TABLES["illumination"]) - {f.name for f in fields(Illumination)} == {"model"}
