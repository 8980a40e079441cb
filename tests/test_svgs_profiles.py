from pathlib import Path

import numpy as np
import pytest

from svgs_sim.svgs import Camera, Pattern, ProfileError
from svgs_sim.base.profiles import CAMERAS_DIR


def test_shipped_profiles_load(nexus):
    assert (nexus.width, nexus.height) == (2592, 1944)
    # 3.43 mm focal length over 1.4 um pixels (profile's sources)
    assert nexus.fx == pytest.approx(3.43e-3 / 1.4e-6)
    amaze = Camera.load("htc-amaze-4g")
    assert (amaze.width, amaze.height) == (3264, 2448)
    p = Pattern.load("svgs-3u")
    np.testing.assert_allclose(p.point(1), [0, 0.1375, 0])
    np.testing.assert_allclose(p.point(4), [0.0875, 0, 0])
    np.testing.assert_allclose(p.point(3), [0, 0, 0.05])


def test_load_by_path_and_roundtrip(tmp_path, nexus):
    cam = nexus.replace(dist=np.array([0.05, -0.1, 1e-4, -2e-4, 0.02]), name="x")
    path = cam.save(tmp_path / "cam.toml")
    back = Camera.load(str(path))
    assert back.fx == cam.fx and back.cx == cam.cx
    np.testing.assert_array_equal(back.dist, cam.dist)
    assert back.tables["sources"] == nexus.tables["sources"]


def test_geometry_only_profile(tmp_path):
    f = tmp_path / "g.toml"
    f.write_text("[intrinsics]\nwidth = 640\nheight = 480\nfx = 500\nfy = 500\ncx = 319.5\ncy = 239.5\n")
    cam = Camera.load(f)
    assert not cam.has_distortion and cam.name == "g"
    with pytest.raises(ProfileError, match=r"\[flash\]"):
        cam.table("flash")


@pytest.mark.parametrize(
    "body, match",
    [
        ("[intrinsics]\nwidth = 640\nheight = 480\nfx = nan\nfy = 500\ncx = 319.5\ncy = 239.5\n", "fx"),
        ("[intrinsics]\nwidth = 640\nheight = 480\nfx = -5\nfy = 500\ncx = 319.5\ncy = 239.5\n", "fx"),
        ("[intrinsics]\nwidth = 0\nheight = 480\nfx = 5\nfy = 500\ncx = 319.5\ncy = 239.5\n", "width"),
        ("[intrinsics]\nwidth = 640\nheight = 480\nfx = 5\nfy = 500\ncx = 9999\ncy = 239.5\n", "cx"),
        ("[intrinsics]\nwidth = 640\nheight = 480\nfx = 5\n", "lacks"),
        ("name = 'x'\n", "intrinsics"),
        ("[intrinsics\n", "not valid TOML"),
        ("[intrinsics]\nwidth = 640\nheight = 480\nfx = 5\nfy = 5\ncx = 1\ncy = 1\n[distortion]\nk9 = 1\n", "k9"),
    ],
)
def test_bad_profiles(tmp_path, body, match):
    f = tmp_path / "bad.toml"
    f.write_text(body)
    with pytest.raises(ProfileError, match=match):
        Camera.load(f)


def test_unknown_names():
    with pytest.raises(ProfileError, match="unknown camera profile 'nope'.*galaxy-nexus"):
        Camera.load("nope")
    with pytest.raises(ProfileError, match="does not exist"):
        Camera.load("missing/file.toml")
    with pytest.raises(ProfileError, match="unknown target pattern"):
        Pattern.load("nope")


def test_bad_patterns(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text("".join(f"[[target]]\nid = {i}\nx_m = {i * 0.1}\ny_m = 0\nz_m = 0\n" for i in range(4)))
    with pytest.raises(ProfileError, match="collinear"):
        Pattern.load(f)
    f.write_text("[[target]]\nid = 1\nx_m = 0\ny_m = 0\n")
    with pytest.raises(ProfileError, match="lacks z_m"):
        Pattern.load(f)


def test_distortion_inverse(nexus):
    cam = nexus.replace(dist=np.array([0.08, -0.15, 5e-4, -3e-4, 0.05]))
    rng = np.random.default_rng(3)
    uv = rng.uniform([0, 0], [cam.width - 1, cam.height - 1], (500, 2))
    back = cam.normalized_to_pixels(cam.pixels_to_normalized(uv))
    np.testing.assert_allclose(back, uv, atol=1e-8)
    # and the model agrees with OpenCV's projectPoints
    import cv2

    xyz = np.column_stack([rng.uniform(-0.5, 0.5, (50, 2)), np.ones(50)])
    ref = cv2.projectPoints(xyz, np.zeros(3), np.zeros(3), cam.K, cam.dist)[0][:, 0]
    np.testing.assert_allclose(cam.project(xyz), ref, atol=1e-9)


def test_scaled_camera_projects_consistently(nexus):
    """A preview stream (area downscale) sees the same field: a point's pixel position
    scales with the image, pixel centres at integers."""
    small = nexus.scaled(640, 480)
    sx = 640 / nexus.width
    rng = np.random.default_rng(4)
    p = np.column_stack([rng.uniform(-0.4, 0.4, (20, 2)), np.ones(20)])
    uv_full = nexus.project(p)
    uv_small = small.project(p)
    np.testing.assert_allclose(uv_small, (uv_full + 0.5) * sx - 0.5, atol=1e-9)
    assert small.fx == pytest.approx(nexus.fx * sx)


# ------------------------------------------------------------------ fitted overlays
def _raw_toml(path):
    import tomllib

    with open(path, "rb") as fh:
        return tomllib.load(fh)


def _flat(tables, skip=("sources", "fitted")):
    """{(table, key): value} over a profile's tables (the provenance tables left out)."""
    return {(t, k): v for t, tab in tables.items() if isinstance(tab, dict) and t not in skip for k, v in tab.items()}


def _overlays():
    from svgs_sim.base.profiles import CAMERAS_DIR

    return sorted((CAMERAS_DIR / "fitted").glob("*.toml"))


def test_every_fitted_overlay_belongs_to_a_shipped_profile():
    names = [p.stem for p in _overlays()]
    assert {"galaxy-nexus"} <= set(names)  # the Nexus carries its fitted exposure
    assert set(names) <= {p.stem for p in CAMERAS_DIR.glob("*.toml")}


@pytest.mark.parametrize("overlay", _overlays(), ids=lambda p: p.stem)
def test_overlay_changes_exactly_its_listed_keys(overlay):
    """The fitted camera differs from the unfitted one in the overlay's keys and nowhere
    else; the unfitted one is the profile file as written (read here with tomllib)."""
    fits = _raw_toml(overlay)["fit"]
    listed = {tuple(f["key"].split(".")): f["value"] for f in fits}
    base_file = _raw_toml(overlay.parent.parent / overlay.name)
    fitted, unfitted = Camera.load(overlay.stem), Camera.load(overlay.stem, fitted=False)
    assert _flat(unfitted.tables) == _flat({k: v for k, v in base_file.items() if k not in ("intrinsics", "distortion")})
    a, b = _flat(fitted.tables), _flat(unfitted.tables)
    changed = {k for k in a.keys() | b.keys() if a.get(k, None) != b.get(k, None)}
    assert changed == set(listed)
    for k, v in listed.items():
        assert a[k] == v
    # the geometry is never fitted
    assert (fitted.width, fitted.height, fitted.fx, fitted.fy, fitted.cx, fitted.cy) == (
        unfitted.width, unfitted.height, unfitted.fx, unfitted.fy, unfitted.cx, unfitted.cy)
    np.testing.assert_array_equal(fitted.dist, unfitted.dist)
    # the loaded camera records what was fitted, and the prior it replaced
    assert set(fitted.tables["fitted"]) == {f["key"] for f in fits}
    for f in fits:
        t, k = f["key"].split(".")
        rec = fitted.tables["fitted"][f["key"]]
        assert rec["fitted_to"] == f["fitted_to"] and rec.get("prior") == base_file[t].get(k)
    assert "fitted" not in unfitted.tables
    # by path, a shipped profile is the same camera as by name
    assert Camera.load(overlay.parent.parent / overlay.name).to_dict() == fitted.to_dict()


@pytest.mark.parametrize("overlay", _overlays(), ids=lambda p: p.stem)
def test_overlay_entries_name_their_fit_target_and_range(overlay):
    """Each fitted value says what it was fitted to (a paper's table or figure), lies in a
    plausible physical range and says where that range comes from; the profile's
    [sources] line for the table points at the overlay and states the prior."""
    base_file = _raw_toml(overlay.parent.parent / overlay.name)
    for f in _raw_toml(overlay)["fit"]:
        assert set(f) == {"key", "value", "fitted_to", "range", "range_source"}, f["key"]
        assert "2014" in f["fitted_to"] or "fitted/" in f["fitted_to"], f["key"]  # the paper, or the fit it shares
        assert ("Table" in f["fitted_to"]) or ("fitted/" in f["fitted_to"]), f["key"]
        assert len(f["range_source"]) > 20, f["key"]
        if isinstance(f["value"], str):
            assert f["value"] in f["range"]
        else:
            lo, hi = f["range"]
            assert lo <= f["value"] <= hi, f["key"]
            prior = base_file[f["key"].split(".")[0]].get(f["key"].split(".")[1])
            if prior is not None:  # the prior is a physical value too
                assert lo <= prior <= hi, f["key"]
        table = f["key"].split(".")[0]
        line = base_file["sources"][table]
        assert "PRIOR" in line and "fitted/" in line, table
    # no FITTED value is left in the base profile's sources
    assert not any(v.startswith("FITTED") for v in base_file["sources"].values())


def test_profiles_without_overlay_load_the_same_either_way():
    a, b = Camera.load("tof-epc660"), Camera.load("tof-epc660", fitted=False)
    assert a.to_dict() == b.to_dict()


def _write_profile(tmp_path, overlay_body):
    """A user's profile ``c.toml`` of the camera keyed ``my-phone``, with its overlay beside it
    (``fitted/<key>.toml``)."""
    (tmp_path / "fitted").mkdir()
    (tmp_path / "c.toml").write_text('key = "my-phone"\n'
                                     "[intrinsics]\nwidth = 64\nheight = 48\nfx = 50\nfy = 50\ncx = 31.5\ncy = 23.5\n"
                                     "[glare]\nveiling_fraction = 0.03\n")
    (tmp_path / "fitted" / "my-phone.toml").write_text(overlay_body)
    return tmp_path / "c.toml"


FIT_OK = ('[[fit]]\nkey = "glare.veiling_fraction"\nvalue = 0.05\nfitted_to = "Table 1"\nrange = [0.01, 0.1]\n'
          'range_source = "a standard"\n')


def test_user_profile_with_overlay(tmp_path):
    path = _write_profile(tmp_path, FIT_OK)
    assert Camera.load(path).key == "my-phone"
    assert Camera.load(path).tables["glare"]["veiling_fraction"] == 0.05
    assert Camera.load(path, fitted=False).tables["glare"]["veiling_fraction"] == 0.03
    # a saved fitted camera keeps its values and its record; loading it again changes nothing
    back = Camera.load(Camera.load(path).save(tmp_path / "saved" / "c.toml"))
    assert back.tables["glare"]["veiling_fraction"] == 0.05
    assert back.tables["fitted"]["glare.veiling_fraction"]["prior"] == 0.03


@pytest.mark.parametrize(
    "body, match",
    [
        (FIT_OK.replace("value = 0.05", "value = 0.5"), "outside its plausible range"),
        (FIT_OK.replace('fitted_to = "Table 1"\n', ""), "lacks fitted_to"),
        (FIT_OK.replace('range_source = "a standard"\n', 'range_source = ""\n'), "lacks range_source"),
        (FIT_OK.replace('"glare.veiling_fraction"', '"intrinsics.fx"'), r"\[intrinsics\] cannot be fitted"),
        (FIT_OK.replace('"glare.veiling_fraction"', '"veiling_fraction"'), "must be 'table.name'"),
        (FIT_OK.replace('"glare.veiling_fraction"', '"flash.cos_exponent"'), r"no \[flash\] table"),
        (FIT_OK + FIT_OK, "given twice"),
        ("camera = 'c'\n", r"expected \[\[fit\]\]"),
    ],
)
def test_bad_overlays_name_the_entry(tmp_path, body, match):
    path = _write_profile(tmp_path, body)
    with pytest.raises(ProfileError, match=match):
        Camera.load(path)
    Camera.load(path, fitted=False)  # the unfitted profile never reads the overlay


def test_lab_overlay_is_a_physical_fit():
    """The lab's fitted ambient light (assets/labs/fitted/msfc-frl.toml) says what it was
    fitted to, lies in its plausible range with its prior, and loads both ways."""
    import tomllib

    from svgs_sim.assets import ASSETS_DIR
    from svgs_sim.sim.lab import load_lab

    base = tomllib.loads((ASSETS_DIR / "labs" / "msfc-frl.toml").read_text())
    over = tomllib.loads((ASSETS_DIR / "labs" / "fitted" / "msfc-frl.toml").read_text())
    for f in over["fit"]:
        assert set(f) == {"key", "value", "fitted_to", "range", "range_source"}
        assert "2014" in f["fitted_to"] and "Tables 2-3" in f["fitted_to"]
        lo, hi = f["range"]
        table, name = f["key"].split(".")
        assert lo <= f["value"] <= hi and lo <= base[table][name] <= hi
        assert "PRIOR" in base["sources"]["ambient"] and "fitted/" in base["sources"]["ambient"]
    assert load_lab().ambient_radiance_w_m2_sr == over["fit"][0]["value"]
    assert load_lab(fitted=False).ambient_radiance_w_m2_sr == base["lab"]["ambient_radiance_w_m2_sr"]


def test_the_overlay_is_chosen_by_the_key_not_the_file_or_display_name(tmp_path):
    """The overlay is ``fitted/<key>.toml``: an overlay named after the file is not the camera's,
    and a profile without a key has none."""
    path = _write_profile(tmp_path, FIT_OK)
    (tmp_path / "fitted" / "my-phone.toml").rename(tmp_path / "fitted" / "c.toml")
    assert Camera.load(path).tables["glare"]["veiling_fraction"] == 0.03
    keyless = tmp_path / "keyless.toml"
    keyless.write_text(path.read_text().replace('key = "my-phone"\n', ""))
    (tmp_path / "fitted" / "keyless.toml").write_text(FIT_OK)
    cam = Camera.load(keyless)
    assert cam.key is None and "fitted" not in cam.tables


def test_a_copy_under_another_name_is_the_same_camera(tmp_path):
    """A copy of a shipped profile with another display name, anywhere on disk: the same key, so
    the same fitted overlay (from the package) and the same app threshold."""
    from svgs_sim.svgs.app import settings
    from svgs_sim.svgs.pipeline import camera_threshold

    src = Camera.load("galaxy-nexus", fitted=False).source
    copy = tmp_path / "elsewhere" / "my-copy.toml"
    copy.parent.mkdir()
    copy.write_text(Path(src).read_text().replace('name = "galaxy-nexus"', 'name = "my-copy"'))
    a, b = Camera.load("galaxy-nexus"), Camera.load(copy)
    assert b.name == "my-copy" and b.key == a.key == "galaxy-nexus"
    assert b.tables["fitted"] == a.tables["fitted"] and b.tables["fitted"]
    img = np.zeros((a.height, a.width), np.uint8)
    assert camera_threshold(img, b) == camera_threshold(img, a) == settings().threshold_for("galaxy-nexus") == 64
    assert settings().threshold_source("galaxy-nexus") == "by_camera[galaxy-nexus]"
    assert settings().threshold_source(None) == "default"


@pytest.mark.parametrize("key", ["Galaxy Nexus", "", "-x", 3])
def test_a_bad_key_is_refused(tmp_path, key):
    path = tmp_path / "c.toml"
    path.write_text(f"key = {key!r}\n".replace("'", '"') if isinstance(key, str) else f"key = {key}\n")
    path.write_text(path.read_text() + "[intrinsics]\nwidth = 64\nheight = 48\nfx = 50\nfy = 50\ncx = 31.5\ncy = 23.5\n")
    with pytest.raises(ProfileError, match="key"):
        Camera.load(path, fitted=False)


def test_a_saved_unfitted_camera_reads_back_unfitted(tmp_path):
    """``load(save(camera))`` is the camera: an unfitted camera with a key is written with an empty
    ``[fitted]`` record, so its overlay is not applied when the file is read back."""
    cam = Camera.load("galaxy-nexus", fitted=False)
    back = Camera.load(cam.save(tmp_path / "unfitted.toml"))
    assert back.key == "galaxy-nexus" and not back.tables.get("fitted")
    assert back.tables["exposure"] == cam.tables["exposure"] != Camera.load("galaxy-nexus").tables["exposure"]
