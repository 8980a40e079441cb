"""The sheeting tables of svgs_sim/render/tof/retro.py (numpy side; the rendered radiometry is in
tests/test_render_tof_render.py)."""

import tomllib

import numpy as np
import pytest

from svgs_sim.assets import ASSETS_DIR
from svgs_sim.render.tof.retro import SHEETING_FILE, load_sheeting, sheeting_names
from svgs_sim.base.errors import InputError

RAW = tomllib.loads((ASSETS_DIR / "materials" / "retroreflective-sheeting.toml").read_text())


def test_the_file_the_module_reads_is_the_asset():
    assert SHEETING_FILE.name == "retroreflective-sheeting.toml" and SHEETING_FILE.is_file()
    assert sorted(sheeting_names()) == sorted(t["name"] for t in RAW["sheeting"])


@pytest.mark.parametrize("row", RAW["sheeting"], ids=lambda r: r["name"])
def test_the_published_figures_are_returned_at_their_angles(row):
    tab = load_sheeting(row["name"])
    for i, a in enumerate(row["observation_deg"]):
        for j, b in enumerate(row["entrance_deg"]):
            assert float(tab.ra(a, b)) == pytest.approx(row["ra_cd_lx_m2"][i][j], rel=1e-9)
            assert float(tab.ra(-a, -b)) == pytest.approx(row["ra_cd_lx_m2"][i][j], rel=1e-9)  # signs name senses
    assert row["source"] and row["kind"] in ("glass-bead", "microprismatic")


def test_between_nodes_a_power_law_in_the_observation_angle_and_sane_limits():
    tab = load_sheeting("en12899-ra2-white")
    # geometric mean at the geometric mid-angle of 0.33 and 2.0 deg: log R linear in log alpha
    mid = np.sqrt(0.33 * 2.0)
    assert float(tab.ra(mid, 5.0)) == pytest.approx(np.sqrt(180.0 * 5.0), rel=1e-9)
    # flat below the first node, falls with the entrance angle, and vanishes at grazing incidence
    assert float(tab.ra(0.05, 5.0)) == pytest.approx(250.0)
    a = np.linspace(0.2, 3.0, 50)
    assert np.all(np.diff(tab.ra(a, 5.0)) < 0)
    b = np.linspace(5.0, 89.0, 50)
    assert np.all(np.diff(tab.ra(0.2, b)) <= 0)
    assert float(tab.ra(0.2, 90.0)) == pytest.approx(0.0, abs=1e-12)
    # the ToF camera's observation angles: 0.16 deg at 5.7 m, ~1.3 deg at 0.7 m (16 mm ring)
    far, near = np.degrees(np.arctan(0.016 / 5.712)), np.degrees(np.arctan(0.016 / 0.697))
    assert float(tab.ra(far, 5.0)) / float(tab.ra(near, 5.0)) > 10


def test_unknown_sheeting_names_the_known_ones():
    with pytest.raises(InputError, match="en12899-ra2-white"):
        load_sheeting("tinfoil")
