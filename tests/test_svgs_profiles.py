import numpy as np
import pytest

from svgs import Camera, Pattern, ProfileError


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
