"""The calibration study's messages about its numbers of views name the option as typed,
``--views-list`` (issue 26), with what it may hold."""

from types import SimpleNamespace

import numpy as np
import pytest

from svgs_sim.studies.calibration.convergence import Detections, check_views_list
from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera


def _detections(n_found: int, n_skipped: int = 0) -> Detections:
    cam = load_camera("galaxy-nexus")
    pts = [np.zeros((4, 3))] * n_found
    return Detections(pts, [np.zeros((4, 2))] * n_found, [f"view_{k:03d}" for k in range(n_found)],
                      [(f"view_{n_found + k:03d}", SimpleNamespace(message="board not found")) for k in range(n_skipped)],
                      (cam.width, cam.height))


@pytest.mark.parametrize("views, message", [
    ([3, 12], "--views-list: 12 views asked but the board was found in only 7 (skipped: view_007 (board not found); "
              "view_008 (board not found)); give numbers from 3 to 7"),
    ([2, 5], "--views-list: a calibration needs at least 3 views, got 2"),
    ([], "--views-list: no number of views given"),
])
def test_views_list_messages_name_the_option(views, message):
    with pytest.raises(InputError) as exc:
        check_views_list(_detections(7, 2), load_camera("galaxy-nexus"), views)
    assert str(exc.value) == message


def test_a_views_list_the_detections_allow_passes():
    assert check_views_list(_detections(7), load_camera("galaxy-nexus"), [7, 3, 5, 5]) == [3, 5, 7]


def test_a_board_found_in_too_few_views_says_what_to_change_in_one_short_line():
    """Eight views skipped for one reason are named once, with their count; with fewer than 3
    views found the message says what would find more (not "give numbers from 3 to 0")."""
    with pytest.raises(InputError) as exc:
        check_views_list(_detections(0, 8), load_camera("galaxy-nexus"), [4, 8])
    assert str(exc.value) == ("--views-list: 8 views asked but the board was found in only 0 (skipped: 8 views, "
                              "view_000 to view_007 (board not found)); a calibration needs 3: a board with fewer, "
                              "larger squares, or a larger image")
