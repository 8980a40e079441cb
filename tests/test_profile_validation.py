"""Every camera profile and pattern value is checked when the file is loaded (issue 26, items 1
and 7): a bad value ends ``svgs render-and-solve`` with exit 2 before any render, in one line
naming the file, the key and the allowed range; an unknown reflector model is refused, never
replaced by the default; every shipped profile and pattern still loads, to the numbers its file
holds.

The bad files are the shipped ones (``assets/cameras``, ``assets/patterns``) with one value
changed, written to ``tmp_path``.
"""

import subprocess
import sys
import time
import tomllib
from dataclasses import fields
from pathlib import Path

import pytest
import tomli_w

from svgs_sim.cli.main import main
from svgs_sim.base.errors import InputError, ProfileError
from svgs_sim.base.profiles import CAMERAS_DIR, PATTERNS_DIR, Camera, Pattern

REPO = Path(__file__).resolve().parent.parent
PHONE_TABLES = ("sensor", "glare", "exposure", "cfa", "isp")


def _edited(src: Path, path, value):
    """``src`` parsed, with ``path`` (keys and list indices) set to ``value`` (None: deleted)."""
    data = tomllib.loads(src.read_text(encoding="utf-8"))
    node = data
    for k in path[:-1]:
        node = node[k]
    if value is None:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


# (path in the TOML structure, bad value, what the message must say: the key and the range or choices)
BAD_CAMERA = [
    (("sensor", "adc_bits"), 40, ("[sensor] adc_bits", "[1, 16]")),
    (("sensor", "adc_bits"), 10.5, ("[sensor] adc_bits", "whole number")),
    (("sensor", "qe"), 1.5, ("[sensor] qe", "(0, 1]")),
    (("sensor", "qe"), "0.5", ("[sensor] qe", "(0, 1]")),
    (("sensor", "full_well_e"), -5.0, ("[sensor] full_well_e", "(0, 1e+07]")),
    (("sensor", "full_well_e"), 1e300, ("[sensor] full_well_e", "(0, 1e+07]")),
    (("sensor", "black_level_dn"), 1023.0, ("[sensor] black_level_dn", "white level 1023")),
    (("sensor", "bloom_direction"), "sideways", ("[sensor] bloom_direction", "'isotropic', 'column'")),
    (("sensor", "qee"), 0.5, ("[sensor]", "unknown key", "qee")),
    (("exposure", "mode"), "magic", ("[exposure] mode", "'auto', 'manual'")),
    (("exposure", "metering"), "matrix", ("[exposure] metering", "'center_weighted'")),
    (("exposure", "min_iso"), 1000.0, ("[exposure] min_iso", "exceeds max_iso")),
    (("cfa", "pattern"), "RGBW", ("[cfa] pattern", "'RGGB'")),
    (("cfa", "demosaic"), "ahd", ("[cfa] demosaic", "'vng'")),
    (("cfa", "response"), [0.5, 1.0], ("[cfa] response", "[R, G, B]")),
    (("isp", "jpeg_subsampling"), "4:1:1", ("[isp] jpeg_subsampling", "'4:2:0'")),
    (("isp", "jpeg_quality"), 101, ("[isp] jpeg_quality", "[0, 100]")),
    (("isp", "stages"), ["glare", "magic"], ("[isp] stages", "'magic'")),
    (("glare", "wing_exponent"), 1.0, ("[glare] wing_exponent", "(1, 10]")),
    (("optics", "f_number"), 0.1, ("[optics] f_number", "[0.5, 100]")),
    (("optics", "band_nm"), [700.0, 400.0], ("[optics] band_nm", "low < high")),
    (("flash", "spectrum"), "sodium", ("[flash] spectrum", "'white-led'")),
    (("flash", "cos_exponent"), 60.0, ("[flash] cos_exponent", "[0, 50]")),
    (("intrinsics", "fx"), 1e300, ("[intrinsics] fx", "(0, 1e+07]")),
    (("sensr",), {"qe": 0.5}, ("unknown table", "sensr")),
]

BAD_PATTERN = [
    (("reflector", "model"), "acme-25mm", ("[reflector] model", "'edmund-nbk7-12.7mm', 'hollow-12.7mm'")),
    (("reflector", "diameter_m"), 0.05, ("[reflector] diameter_m", "at most")),
    (("reflector", "colour"), "red", ("[reflector]", "unknown key", "colour")),
    (("target", 3, "x_m"), "a", ("[target 4] x_m", "[-100, 100]")),
    (("target", 3, "x_m"), 1e9, ("[target 4] x_m", "[-100, 100]")),
    (("target", 3, "id"), 1.5, ("id", "whole number")),
    (("target", 3, "label"), "x", ("[target 4]", "unknown key", "label")),
]


def _run(argv, capsys):
    t0 = time.perf_counter()
    rc = main(argv)
    elapsed_s = time.perf_counter() - t0
    cap = capsys.readouterr()
    return rc, elapsed_s, cap


def _assert_refused(rc, elapsed_s, cap, file, words):
    assert rc == 2, cap.err[-600:]
    assert "Traceback" not in cap.err and cap.out == ""
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(lines) == 1, cap.err
    assert lines[0].startswith("svgs render-and-solve: error:") and str(file) in lines[0], lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert elapsed_s < 1.0, f"{elapsed_s:.2f} s: refused after some work"  # a render takes 3-7 s


@pytest.fixture(autouse=True)
def _warm():
    """Import what ``render-and-solve`` imports first, so the time measured is the check's."""
    import importlib

    for module in ("svgs_sim.cli.sim", "svgs_sim.sim.closed_loop"):
        importlib.import_module(module)


@pytest.mark.parametrize("path, value, words", BAD_CAMERA, ids=[f"{'.'.join(map(str, p))}={v!r}" for p, v, _ in BAD_CAMERA])
def test_bad_camera_value_refused_before_the_render(tmp_path, capsys, path, value, words):
    bad = tmp_path / "bad-camera.toml"
    bad.write_bytes(tomli_w.dumps(_edited(CAMERAS_DIR / "galaxy-nexus.toml", path, value)).encode())
    rc, dt, cap = _run(["render-and-solve", "--camera", str(bad), "--range", "5", "--out", str(tmp_path / "out")], capsys)
    _assert_refused(rc, dt, cap, bad, words)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("path, value, words", BAD_PATTERN, ids=[f"{'.'.join(map(str, p))}={v!r}" for p, v, _ in BAD_PATTERN])
def test_bad_pattern_value_refused_before_the_render(tmp_path, capsys, path, value, words):
    bad = tmp_path / "bad-pattern.toml"
    bad.write_bytes(tomli_w.dumps(_edited(PATTERNS_DIR / "svgs-3u.toml", path, value)).encode())
    rc, dt, cap = _run(["render-and-solve", "--camera", "galaxy-nexus", "--range", "5", "--pattern", str(bad)], capsys)
    _assert_refused(rc, dt, cap, bad, words)


def test_two_targets_at_one_position_is_bad_input(tmp_path, capsys):
    data = _edited(PATTERNS_DIR / "svgs-3u.toml", ("target", 3, "x_m"), 0.0)  # target 4 onto target 3 (0, 0, 0.05)
    data["target"][3]["z_m"] = 0.05
    bad = tmp_path / "twin.toml"
    bad.write_bytes(tomli_w.dumps(data).encode())
    rc, dt, cap = _run(["render-and-solve", "--camera", "galaxy-nexus", "--range", "5", "--pattern", str(bad)], capsys)
    _assert_refused(rc, dt, cap, bad, ("targets 3 and 4 share one position", "1e-06 m apart"))


@pytest.mark.parametrize("which", ["camera", "pattern"])
def test_a_file_that_is_not_text_names_the_file(tmp_path, capsys, which):
    src = CAMERAS_DIR / "galaxy-nexus.toml" if which == "camera" else PATTERNS_DIR / "svgs-3u.toml"
    bad = tmp_path / f"latin1-{which}.toml"
    bad.write_bytes(b"# caf\xe9 (Latin-1, not UTF-8)\n" + src.read_bytes())
    argv = ["render-and-solve", "--camera", str(bad) if which == "camera" else "galaxy-nexus", "--range", "5"]
    if which == "pattern":
        argv += ["--pattern", str(bad)]
    rc, dt, cap = _run(argv, capsys)
    _assert_refused(rc, dt, cap, bad, ("not UTF-8", "0xe9", "offset 5"))


def test_the_command_line_prints_one_line_and_no_traceback(tmp_path):
    """The same through a real process (the in-process tests above cannot see an uncaught exception's
    traceback printed by the interpreter)."""
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"\xff\xfe" + (CAMERAS_DIR / "galaxy-nexus.toml").read_bytes())
    p = subprocess.run([sys.executable, "-m", "svgs_sim.cli.main", "render-and-solve", "--camera", str(bad), "--range", "5"],
                       capture_output=True, text=True, cwd=REPO, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr and p.stdout == ""
    assert [ln for ln in p.stderr.splitlines() if ln.strip()] == [
        f"svgs render-and-solve: error: camera profile file {str(bad)!r} is not UTF-8 text (TOML files are): "
        "byte 0xff at offset 0"]


def test_an_unknown_reflector_model_is_never_replaced_by_the_default():
    from svgs_sim.render.geometry import Reflector

    good = Pattern.load("svgs-3u")
    with pytest.raises(InputError, match=r"model = 'acme'.*'edmund-nbk7-12\.7mm', 'hollow-12\.7mm'"):
        # a pattern built in code: refused when built (its parts are typed), before any render
        Pattern(name="made", ids=good.ids, points_m=good.points_m, tables={"reflector": {"model": "acme"}})
    hollow = Pattern(name="h", ids=good.ids, points_m=good.points_m, tables={"reflector": {"model": "hollow-12.7mm"}})
    assert Reflector.resolve(None, hollow).kind == "hollow"


def test_distinct_positions_are_checked_for_patterns_built_in_code():
    good = Pattern.load("svgs-3u")
    pts = good.points_m.copy()
    pts[1] = pts[0] + 1e-7
    with pytest.raises(ProfileError, match="share one position"):
        Pattern(name="p", ids=good.ids, points_m=pts)


# ---------------------------------------------------------------------------- the shipped files
SHIPPED_CAMERAS = sorted(CAMERAS_DIR.glob("*.toml"))
SHIPPED_PATTERNS = sorted(PATTERNS_DIR.glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED_CAMERAS, ids=lambda p: p.name)
@pytest.mark.parametrize("fitted", [True, False])
def test_every_shipped_camera_loads_to_its_file_values(path, fitted):
    """Each phone table's values, as built by svgs_sim.camera.phone.params, equal the file's own numbers
    (read here with tomllib, not by the code under test): the checks moved no number."""
    from svgs_sim.camera.phone.params import PhoneParams

    cam = Camera.load(path, fitted=fitted)
    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    if "tof" in raw:
        _assert_tof_models_hold_the_file_values(cam, raw)
    if not any(t in raw for t in PHONE_TABLES):
        return  # the ToF camera: no phone tables
    params = PhoneParams.from_camera(cam)
    fits = cam.tables.get("fitted", {})
    for table in PHONE_TABLES:
        for key, value in raw.get(table, {}).items():
            want = fits[f"{table}.{key}"]["value"] if f"{table}.{key}" in fits else value
            got = getattr(getattr(params, table), key)
            want = tuple(want) if isinstance(want, list) else want
            assert got == want, (table, key, got, want)
    assert params.f_number == raw["optics"]["f_number"]
    assert params.band_nm == tuple(raw["optics"]["band_nm"])


def _assert_tof_models_hold_the_file_values(cam, raw):
    """The ToF sensor, illumination and lens built from a loaded ToF profile carry the numbers of
    its ``[tof]``, ``[noise]``, ``[illumination]`` and ``[optics]`` tables (``raw``, read with
    tomllib), and the tables are kept as the file has them."""
    from svgs_sim.camera.amcw import TofSensor
    from svgs_sim.render.tof.camera import Illumination, TofOptics

    for table in ("tof", "noise", "illumination"):
        assert cam.tables[table] == raw[table], table
    sensor, light, lens = TofSensor.from_camera(cam), Illumination.from_camera(cam), TofOptics.from_camera(cam)
    for table, model in (("tof", sensor), ("noise", sensor), ("illumination", light)):
        for key, value in raw[table].items():
            if hasattr(model, key):
                want = None if value == "auto" else tuple(value) if isinstance(value, list) else value
                assert getattr(model, key) == want, (table, key, getattr(model, key), want)
    assert sensor.transmittance == raw["optics"]["transmittance"]
    assert (lens.focal_length_m, lens.f_number, lens.wavelength_m) == (
        raw["optics"]["focal_length_m"], raw["optics"]["f_number"], raw["tof"]["wavelength_m"])


@pytest.mark.parametrize("path", SHIPPED_PATTERNS, ids=lambda p: p.name)
def test_every_shipped_pattern_loads_to_its_file_values(path):
    pat = Pattern.load(path)
    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    by_id = {t["id"]: (t["x_m"], t["y_m"], t["z_m"]) for t in raw["target"]}
    assert sorted(by_id) == pat.ids.tolist()
    for i, p in zip(pat.ids, pat.points_m):
        assert tuple(p) == by_id[i]
    if "plate" in raw or "marker" in raw:  # the ToF target: its scene is built from the file's numbers
        from svgs_sim.render.tof.scene import TofSceneOptions, resolve_geometry
        from svgs_sim.tof.camera import load_target

        target = load_target(path)
        assert (target.plate, target.marker) == (raw["plate"], raw["marker"])
        assert target.diameter_m.tolist() == [t["diameter_m"] for t in sorted(raw["target"], key=lambda t: t["id"])]
        geo = resolve_geometry(target, TofSceneOptions())
        assert geo.plate_size_m == (raw["plate"]["width_m"], raw["plate"]["height_m"])
        assert geo.plate_thickness_m == raw["plate"]["thickness_m"]
        assert geo.albedo == {"plate": raw["plate"]["albedo"], "marker": raw["marker"]["albedo"],
                              "dark": raw["plate"]["albedo"]}
        assert geo.materials == {"marker": raw["marker"]["material"], "plate": "lambertian",
                                 "sheeting": raw["marker"]["sheeting"]}
        assert geo.post_radius_m.tolist() == [d / 2 * raw["marker"]["post_diameter_ratio"] for d in target.diameter_m]


def test_the_shared_tables_agree_with_their_users():
    """The allowed values live in svgs_sim.base.profile_schema; the models that use them agree."""
    from svgs_sim.camera.phone import params as pp
    from svgs_sim.render import geometry, optics
    from svgs_sim.base import profile_schema as ps

    assert set(ps.FLASH_SPECTRA) == set(optics.SPECTRA)
    assert geometry.REFLECTOR_MODELS is ps.REFLECTOR_MODELS
    for table, defaults in ps.PHONE_DEFAULTS.items():
        cls = {"sensor": pp.SensorParams, "exposure": pp.ExposureParams}[table]
        d = {f.name: f.default for f in fields(cls)}
        assert {k: d[k] for k in defaults} == defaults
    for table, cls in (("sensor", pp.SensorParams), ("glare", pp.GlareParams), ("exposure", pp.ExposureParams),
                       ("cfa", pp.CfaParams), ("isp", pp.IspParams)):
        assert set(ps.PHONE_TABLES[table]) == {f.name for f in fields(cls)}, table
