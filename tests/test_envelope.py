"""One envelope everywhere (issue 26, item 5): ``--range``, range lists, trajectory files and
``sensitivity`` bounds take the same ranges and attitudes, and refuse the same ones.

The envelope's ends are checked against the camera's own projection (:meth:`Camera.project`):
at the far end the pattern spans MIN_SPAN_PX pixels, at the near end MAX_FILL times the
shorter side of the frame.
"""

import numpy as np
import pytest

from svgs_sim.cli.main import build_parser
from svgs_sim.cli.validate import check_args
from refusal import refused
from svgs_sim.sim.approach.trajectory import Trajectory, check_envelope
from svgs_sim.studies.sensitivity import make_config
from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_from_scenario
from svgs_sim.svgs.envelope import ATTITUDE_LIMITS_DEG, MAX_FILL, MIN_SPAN_PX, check_range_m, range_envelope_m
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.sim.trials import GEOMETRIC_PARAMETERS


def _span_px(camera, pattern, range_m):
    R, t = pose_from_scenario(range_m, 0.0, 0.0)
    uv = camera.project(pattern.points_m @ R.T + t)
    return max(np.linalg.norm(a - b) for a in uv for b in uv)


@pytest.mark.parametrize("cam_name", ["galaxy-nexus", "htc-amaze-4g"])
def test_the_envelope_ends_are_where_the_projected_pattern_says(cam_name):
    cam, pat = load_camera(cam_name), load_pattern("svgs-3u")
    near, far = range_envelope_m(cam, pat)
    # the targets' depth offsets and the lens distortion move the span by a few percent
    assert _span_px(cam, pat, far) == pytest.approx(MIN_SPAN_PX, rel=0.05)
    assert _span_px(cam, pat, near) == pytest.approx(MAX_FILL * min(cam.width, cam.height), rel=0.1)


def _trajectory_file(tmp_path, z_far_m, yaw_deg=0.0):
    p = tmp_path / "traj.csv"
    p.write_text(f"t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,{z_far_m},0,0,{yaw_deg}\n1,0,0,10,0,0,0\n")
    return p


def _cli_refuses(argv):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        check_args(args, parser)
    except InputError as exc:
        return str(exc)
    return None


def test_range_is_the_same_for_every_input(tmp_path):
    cam, pat = load_camera("galaxy-nexus"), load_pattern("svgs-3u")
    near, far = range_envelope_m(cam, pat)
    inside, beyond, close = 0.99 * far, 1.01 * far, 0.99 * near
    for r, ok in ((inside, True), (beyond, False), (close, False)):
        msgs = [
            _cli_refuses(["render-and-solve", "--camera", "galaxy-nexus", "--range", f"{r!r}"]),
            _cli_refuses(["range-sweep", "--camera", "galaxy-nexus", "--ranges", f"5,{r!r}"]),
            _cli_refuses(["approach", "--camera", "galaxy-nexus", "--from", f"{r!r}", "--to", "5",
                          "--duration", "1", "--fps", "2", "--out", str(tmp_path / "o")]),
        ]
        traj = Trajectory.load(_trajectory_file(tmp_path, r))
        try:
            check_envelope(traj, cam, pat)
            msgs.append(None)
        except InputError as exc:
            msgs.append(str(exc))
        lo, hi = (5.0, r) if r > 5 else (r, 5.0)
        try:
            make_config("galaxy-nexus", [f"range_m={lo!r}:{hi!r}", "sigma_px=0.1:0.2"], n=8)
            msgs.append(None)
        except InputError as exc:
            msgs.append(str(exc))
        if ok:
            assert msgs == [None] * 5, msgs
        else:
            assert all(m is not None and f"allowed {near:.2f}-{far:.0f} m" in m for m in msgs), msgs
    assert "--range" in _cli_refuses(["render-and-solve", "--camera", "galaxy-nexus", "--range", f"{beyond!r}"])
    with pytest.raises(InputError, match="--fixed range_m"):
        make_config("galaxy-nexus", ["roll_deg=0:10", "sigma_px=0.1:0.2"], fixed=[f"range_m={beyond!r}"], n=8)


@pytest.mark.parametrize("angle", ["roll_deg", "pitch_deg", "yaw_deg"])
def test_attitude_limits_are_the_same_for_every_input(tmp_path, angle):
    lim = ATTITUDE_LIMITS_DEG[angle]
    flag = "--" + angle.split("_")[0]
    beyond = lim + 1.0
    assert GEOMETRIC_PARAMETERS[angle].lower == -lim and GEOMETRIC_PARAMETERS[angle].upper == lim
    for cmd, f in ((["render", "--camera", "galaxy-nexus", "--range", "5", "--out", str(tmp_path / "o")], flag),
                   (["render-and-solve", "--camera", "galaxy-nexus", "--range", "5"], flag),
                   (["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5"], flag)):
        assert _cli_refuses(cmd + [f, f"{lim:g}"]) is None
        msg = _cli_refuses(cmd + [f, f"{beyond:g}"])
        assert msg and f"{-lim:g} to {lim:g} deg" in msg, msg
    p = tmp_path / "att.csv"
    cols = {"roll_deg": "0", "pitch_deg": "0", "yaw_deg": "0", angle: f"{beyond:g}"}
    p.write_text("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10," + ",".join(cols[k] for k in
                 ("roll_deg", "pitch_deg", "yaw_deg")) + "\n1,0,0,5,0,0,0\n")
    with pytest.raises(InputError, match=f"line 2, column {angle}: expected {-lim:g} to {lim:g} deg"):
        Trajectory.load(p)
    with pytest.raises(InputError, match=f"--vary {angle} HIGH: expected {-lim:g} to {lim:g} deg"):
        make_config("galaxy-nexus", [f"{angle}=0:{beyond:g}", "sigma_px=0.1:0.2"], n=8)


def test_a_refused_trajectory_leaves_nothing_behind(tmp_path, capsys):
    far = range_envelope_m("galaxy-nexus", "svgs-3u")[1]
    out = tmp_path / "out"
    line = refused(["approach", "--camera", "galaxy-nexus", "--trajectory", str(_trajectory_file(tmp_path, 2 * far)),
                    "--fps", "2", "--out", str(out)], capsys, watch=[tmp_path])
    assert "spots merge into one" in line
    assert not out.exists()


def test_check_range_m_names_the_input():
    with pytest.raises(InputError, match="^my input: expected a range"):
        check_range_m(float("nan"), "galaxy-nexus", "svgs-3u", "my input")
