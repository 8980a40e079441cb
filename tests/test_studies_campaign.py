"""The campaign: the paper's numbers from assets, statistics beside them, the CLI, and the HTML
report opened in a real headless browser (Debian's Chromium)."""

import base64
import csv
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest

from svgs_sim.assets.papers import SVGS_2014_CSV, svgs_2014_results
from svgs_sim.studies.campaign import PAPER_RANGES_M, campaign_trials, make_config, summarize
from svgs_sim.cli.main import main
from svgs_sim.base.errors import InputError

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def test_paper_tables_come_from_assets():
    assert SVGS_2014_CSV.parent.name == "data" and SVGS_2014_CSV.parent.parent.name == "assets"
    paper = svgs_2014_results()
    assert paper[("galaxy-nexus", "mean_error", 30.0)]["y_m"] == 1.53  # Table 4
    assert paper[("htc-amaze-4g", "std", 6.5)]["roll_deg"] == 0.44  # Table 3
    for phone, ranges in PAPER_RANGES_M.items():
        assert all((phone, s, r) in paper for r in ranges for s in ("mean_error", "std"))


def test_campaign_design_follows_the_sensor_mount_envelope():
    """The phone on the stand: settings drawn over the gimbal's envelope, kept in view, each
    rendered once and exposed exposures_per_render times; the target's range is the rail's."""
    from svgs_sim.sim.stand import TestStand, targets_in_view
    from svgs_sim.base.profiles import Camera, Pattern

    cfg = make_config("htc-amaze-4g", trials_per_range=200, seed=1)
    assert cfg.trial_kind == "render" and cfg.calibration == "paper" and cfg.poses_per_range == 50
    trials = campaign_trials(cfg)
    assert len(trials) == 5 * 200 and [t.trial_id for t in trials] == list(range(1000))
    s = {k: np.array([t.scenario[k] for t in trials]) for k in ("roll_deg", "pitch_deg", "yaw_deg", "rail_m", "stage_m",
                                                                 "nominal_range_m", "pose_index", "stand",
                                                                 "rail_err_m")}
    # the recorded range (the rangefinder's reading) plus its error is the rail's true position
    assert np.all(s["stand"] == 1) and np.allclose(s["rail_m"] + s["rail_err_m"], s["nominal_range_m"])
    assert 0 < np.abs(s["rail_err_m"]).max() < 0.1
    assert np.abs(s["roll_deg"]).max() <= 25 and np.abs(s["pitch_deg"]).max() <= 25
    assert np.abs(s["yaw_deg"]).max() <= 45 and np.abs(s["yaw_deg"]).max() > 43  # about the line of sight: in view
    assert np.abs(s["stage_m"]).max() <= 0.15 and np.abs(s["stage_m"]).max() > 0.14
    assert sorted(set(s["nominal_range_m"])) == [1.0, 2.0, 3.0, 4.0, 6.5]
    # four exposures of each setting, with their own seeds
    first = trials[:4]
    assert len({(t.scenario["roll_deg"], t.scenario["yaw_deg"]) for t in first}) == 1 and len({t.seed for t in first}) == 4
    assert trials[4].scenario["roll_deg"] != trials[0].scenario["roll_deg"]
    cam, pat = Camera.load("htc-amaze-4g"), Pattern.load("svgs-3u")
    stand = TestStand()
    assert all(targets_in_view(cam, pat, *stand.pose(t.scenario["nominal_range_m"], stage_m=t.scenario["stage_m"],
                                                      roll_deg=t.scenario["roll_deg"], pitch_deg=t.scenario["pitch_deg"],
                                                      yaw_deg=t.scenario["yaw_deg"])) for t in trials[::4])
    # the design of trial i does not depend on how many trials or ranges there are
    small = campaign_trials(make_config("htc-amaze-4g", trials_per_range=200, seed=1, ranges_m=(1.0,)))
    assert [t.scenario for t in small] == [t.scenario for t in trials[:200]]


def test_paper_calibration_is_drawn_once_per_campaign():
    a = make_config("galaxy-nexus", calibration="paper", seed=4, trial_kind="geometric")
    b = make_config("galaxy-nexus", calibration="paper", seed=4, trial_kind="geometric")
    assert a.calibration_error == b.calibration_error and a.calibration_error["focal_error_frac"] != 0
    trials = campaign_trials(make_config("galaxy-nexus", calibration="paper", seed=4, trials_per_range=3,
                                         trial_kind="geometric"))
    assert {t.scenario["focal_error_frac"] for t in trials} == {a.calibration_error["focal_error_frac"]}
    with pytest.raises(InputError, match="draws the calibration error itself"):
        make_config("galaxy-nexus", calibration="paper", calibration_error={"focal_error_frac": 0.01})
    # rendered: the true lens has the drawn principal-point offset and distortion; the solver
    # assumes the image centre and none (its errors are the opposite of the lens')
    r = make_config("galaxy-nexus", seed=4)
    assert r.lens["lens_pp_u_px"] != 0 and r.calibration_error["pp_error_u_px"] == -r.lens["lens_pp_u_px"]
    assert r.calibration_error["k1_error"] == -r.lens["lens_k1"]
    t = campaign_trials(make_config("galaxy-nexus", seed=4, trials_per_range=2, ranges_m=(10.0,)))[0].scenario
    assert t["lens_k1"] == r.lens["lens_k1"] and t["k1_error"] == -r.lens["lens_k1"]
    with pytest.raises(InputError, match="--budget"):
        make_config("galaxy-nexus", trial_kind="geometric", budget=True)
    with pytest.raises(InputError, match="misalignment"):
        make_config("galaxy-nexus", misalignment_deg=(0.0, 0.0, 20.0))
    with pytest.raises(InputError, match="--exposures-per-render"):
        make_config("galaxy-nexus", exposures_per_render=0)


def test_other_cameras_need_ranges(tmp_path):
    from svgs_sim.base.profiles import Camera

    path = Camera.load("galaxy-nexus").replace(name="modern-phone", key="modern-phone").save(tmp_path / "modern-phone.toml")
    with pytest.raises(InputError, match="give the test ranges"):
        make_config(str(path))
    assert make_config(str(path), ranges_m=(2.0, 8.0)).ranges_m == (2.0, 8.0)
    with pytest.raises(InputError, match="--ranges"):
        make_config(str(path), ranges_m=(2.0, -1.0))


def test_summary_statistics_and_ratios():
    cfg = make_config("galaxy-nexus", ranges_m=(5.0, 10.0), trials_per_range=4)
    e = np.array([0.1, -0.3, 0.2, -0.2, 1.0, 1.0, 1.0, 1.0])
    table = {"nominal_range_m": np.repeat([5.0, 10.0], 4), "ok": np.array([1, 1, 1, 1, 1, 1, 1, 0.0]),
             "reason": np.array([None] * 7 + ["diverged"], dtype=object)}
    for c in ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"):
        table[f"err_{c}"] = e
        table[f"crlb_{c}"] = np.full(8, 0.5)
    s = summarize(table, cfg)
    assert s[0]["mean_abs_x_m"] == pytest.approx(0.2) and s[0]["bias_x_m"] == pytest.approx(-0.05)
    assert s[0]["std_x_m"] == pytest.approx(np.std(e[:4], ddof=1))
    assert s[0]["ratio_mean_abs_x_m"] == pytest.approx(0.2 / 0.05)  # Table 4: 0.05 m at 5 m
    assert s[1]["n_ok"] == 3 and s[1]["reasons"] == {"diverged": 1} and s[1]["std_x_m"] == 0.0
    assert s[1]["ratio_std_yaw_deg"] == pytest.approx(0.0)


@pytest.fixture(scope="module")
def campaign_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("campaign") / "nexus"
    import io
    from contextlib import redirect_stdout

    buf = io.StringIO()
    with redirect_stdout(buf):
        code = main(["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "30", "--out",
                     str(out), "--processes", "0", "--no-progress", "--calibration", "paper"])
    assert code == 0
    return out, buf.getvalue()


@pytest.mark.slow
def test_campaign_cli_writes_tables_beside_the_paper(campaign_report):
    out, text = campaign_report
    assert "X std  /paper" in text and "report.html" in text
    with open(out / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    r = [x for x in rows if x["range_m"] == "30.0" and x["component"] == "y_m" and x["statistic"] == "mean_abs_error"][0]
    assert float(r["paper"]) == 1.53 and float(r["ratio"]) == pytest.approx(float(r["simulated"]) / 1.53)
    # errors grow with range (Cramer-Rao grows as range squared for X)
    crlb = {float(x["range_m"]): float(x["simulated"]) for x in rows if x["component"] == "x_m"
            and x["statistic"] == "crlb_std"}
    assert crlb[30.0] / crlb[5.0] > 20
    html = (out / "report.html").read_text()
    assert "svgs campaign --camera galaxy-nexus --trials 30" in html and "numpy" in html


#: The browsers the report test drives, by executable name (Debian's, Chromium's, Google's).
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def _chromium():
    """The installed Chromium-family browser and None, or None and why the test skips. The test
    suite never installs one (``apt-get install chromium`` does, on Debian)."""
    for name in BROWSERS:
        exe = shutil.which(name)
        if exe:
            return exe, None
    return None, f"no headless browser installed (none of {', '.join(BROWSERS)} on PATH); install Chromium to run it"


class _Dom(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.tables, self.headers, self._in_th = [], 0, [], False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.images.append(a.get("src", ""))
        elif tag == "table":
            self.tables += 1
        self._in_th = tag == "th"

    def handle_data(self, data):
        if self._in_th:
            self.headers.append(data)


@pytest.mark.slow
def test_report_opens_in_headless_chromium(request, tmp_path):
    exe, why = _chromium()
    if exe is None:
        pytest.skip(why)
    out, _ = request.getfixturevalue("campaign_report")  # the campaign runs only when a browser is there
    proc = subprocess.run([exe, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--dump-dom",
                           (out / "report.html").resolve().as_uri()], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    dom = _Dom()
    dom.feed(proc.stdout)
    import cv2

    pngs = [s for s in dom.images if s.startswith("data:image/png;base64,")]
    assert len(pngs) >= 5  # errors versus range + 4 histogram figures (paper Figures 6-13)
    for src in pngs:
        raw = base64.b64decode(src.split(",", 1)[1])
        assert raw[:8] == b"\x89PNG\r\n\x1a\n"
        img = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and img.shape[0] > 100 and img.shape[1] > 100
    assert dom.tables >= 5
    assert {"X sim", "X paper", "X ratio", "yaw ratio"} <= set(dom.headers)
