"""A black board render is a simulated physical failure, not bad input (issue 26): no light reaches
the sensor, so no manual exposure exists - :class:`svgs_sim.base.errors.SimulationFailure` (exit 1 with its
reason), not :class:`svgs_sim.base.errors.InputError` (exit 2)."""

from types import SimpleNamespace

import numpy as np
import pytest

import svgs_sim.sim.boards
from svgs_sim.camera.phone import PhoneCamera
from svgs_sim.cli.main import main
from svgs_sim.sim.boards import manual_exposure
from svgs_sim.base.errors import InputError, SimulationFailure


def test_a_black_image_has_no_manual_exposure():
    phone = PhoneCamera("galaxy-nexus")
    with pytest.raises(SimulationFailure) as exc:
        manual_exposure(phone, SimpleNamespace(flux_optics=np.zeros((8, 8))))
    assert not isinstance(exc.value, InputError) and exc.value.reason == "no_signal"
    assert str(exc.value).startswith("board render: the image is black (no light reaches the sensor")
    with pytest.raises(InputError, match="exposure fill"):  # a bad fill stays bad input
        manual_exposure(phone, SimpleNamespace(flux_optics=np.ones((8, 8))), fill=1.5)


class _BlackRenderer:
    """Stands in for svgs_sim.render.boards.BoardRenderer: every view renders black (no Mitsuba)."""

    def __init__(self, cam, board, **kw):
        self.cam = cam

    def render(self, R_cam_board, t_cam_board_m, seed=0):
        return SimpleNamespace(flux=np.zeros((self.cam.height, self.cam.width)))


def test_svgs_calibrate_render_board_exits_1_with_the_reason(monkeypatch, tmp_path, capsys):
    import svgs_sim.cli.compile_kernels as ck

    monkeypatch.setattr(ck, "kernels_cached", lambda: True)
    monkeypatch.setattr(svgs_sim.sim.boards, "BoardRenderer", _BlackRenderer)
    out = tmp_path / "set"
    rc = main(["calibrate", "render-board", "--camera", "galaxy-nexus", "--width", "160", "--height", "120",
               "--board", "chessboard", "--cols", "9", "--rows", "6", "--spacing-mm", "20", "--views", "1",
               "--out", str(out)])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 1 and len(err) == 1, err
    assert err[0].startswith("svgs calibrate render-board: no solution (no_signal): board render: the image is black")
    assert not out.exists()
