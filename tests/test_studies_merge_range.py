"""The merge-range study: the margin measured on images with a known answer, the crossing, the
physical parameters' validation, and the command end to end on a small grid."""

import json

import numpy as np
import pytest

from svgs_sim.cli.main import main
from svgs_sim.sim.render_trial import merge_margin_dn
from svgs_sim.studies.merge_range import PHYSICS, crossing, make_config
from svgs_sim.base.errors import InputError


def _two_gaussians(sep_px, sigma_px=3.0, peak=200.0, shape=(64, 96)):
    y, x = np.mgrid[: shape[0], : shape[1]].astype(float)
    c = np.array([[40.0 - sep_px / 2, 32.0], [40.0 + sep_px / 2, 32.0]])
    img = sum(peak * np.exp(-((x - u) ** 2 + (y - v) ** 2) / (2 * sigma_px**2)) for u, v in c)
    return img.astype(np.float32), c


def test_merge_margin_is_the_threshold_minus_the_saddle_between_two_spots():
    """Two Gaussian spots: the saddle midway is 2 peak exp(-(d/2)^2 / (2 s^2)); the margin is the
    threshold minus that, negative once the spots would join in the binary image."""
    for sep in (8.0, 12.0, 20.0):
        img, c = _two_gaussians(sep)
        saddle = 2 * 200.0 * np.exp(-((sep / 2) ** 2) / (2 * 9.0))
        assert merge_margin_dn(img, c, 50.0) == pytest.approx(50.0 - saddle, abs=0.5)
    img, c = _two_gaussians(8.0)
    assert merge_margin_dn(img, c, 50.0) < 0 < merge_margin_dn(*_two_gaussians(20.0), 50.0)


def test_the_merge_range_is_the_first_zero_crossing():
    r = [4.0, 5.0, 6.0, 7.0]
    assert crossing(r, [10.0, 5.0, -5.0, -10.0]) == (pytest.approx(5.5), "inside")
    assert crossing(r, [-1.0, -2.0, -3.0, -4.0]) == (4.0, "below")
    assert crossing(r, [3.0, 2.0, 1.0, 0.5]) == (7.0, "above")


def test_parameters_are_physical_and_checked_before_work():
    cfg = make_config("htc-amaze-4g")
    assert cfg.parameters == tuple(PHYSICS) and len(cfg.cases()) == 1 + 2 * len(PHYSICS)
    for name, (lo, hi, why) in PHYSICS.items():
        assert lo < hi and len(why) > 40  # every range says where it comes from
    with pytest.raises(InputError, match="physical parameters"):
        make_config("htc-amaze-4g", vary=["sigma_px"])
    with pytest.raises(InputError, match="LOW < HIGH"):
        make_config("htc-amaze-4g", vary=["f_number=2.8:2.0"])
    with pytest.raises(InputError, match="f_number"):
        make_config("htc-amaze-4g", vary=["f_number=0.5:2.0"])
    with pytest.raises(InputError, match="--ranges"):
        make_config("htc-amaze-4g", ranges_m=(8.0, 6.0))


@pytest.mark.render
@pytest.mark.slow
def test_merge_range_command_on_a_small_grid(tmp_path, capsys):
    """The Amaze at 6 and 8.5 m, the veiling glare at 1 % and 8 %: as profiled the spots are apart
    at 6 m and merged at 8.5 m (the paper's 6.5-8 m), more glare merges them sooner, less later."""
    out = tmp_path / "mr"
    assert main(["merge-range", "--camera", "htc-amaze-4g", "--ranges", "6,8.5", "--vary", "glare_veiling_fraction",
                 "--exposures", "1", "--out", str(out), "--processes", "0", "--no-progress", "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj == json.loads((out / "summary.json").read_text())
    nom = obj["nominal"]
    assert nom["bound"] == "inside" and 6.0 < nom["merge_range_m"] < 8.5
    (e,) = obj["effects"]
    assert e["parameter"] == "glare_veiling_fraction"
    assert e["merge_range_high_m"] < nom["merge_range_m"] < e["merge_range_low_m"]
    assert (out / "report.html").is_file() and (out / "merge_ranges.csv").is_file()
