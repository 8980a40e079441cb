"""Every trial parameter has a physical lower and upper bound (issue 26): the CLI's for the same
quantity (one table, :mod:`svgs_sim.base.limits`), and ``svgs sensitivity --vary P=LOW:1e308`` is refused
before any work - exit 2, one line naming ``--vary P HIGH`` and the allowed range, nothing written.
"""

import math
import time

import pytest

from svgs_sim.cli.main import build_parser, main
from svgs_sim.cli.validate import check_args
from svgs_sim.sim.trials import get_trial_kind, known_trial_kinds
from svgs_sim.studies.seeding import check_seed
from svgs_sim.base.errors import InputError
from svgs_sim.base.limits import INPUT_BOUNDS, INT_BOUNDS, MAX_SEED, MAX_SPP
from svgs_sim.tof.camera import DESIGN_RANGE_M

#: Parameters whose quantity the CLI bounds under another name (parameter -> INPUT_BOUNDS key).
SAME_QUANTITY = {"backdrop_distance_m": "backdrop_m", "ambient_radiance_w_m2_sr": "ambient",
                 "pp_error_u_px": "true_pp_offset_px", "pp_error_v_px": "true_pp_offset_px"}


def _parameters(kinds=None):
    for name in kinds or known_trial_kinds():
        for p in get_trial_kind(name).parameters.values():
            yield name, p


def test_every_parameter_of_every_kind_has_both_bounds():
    assert {"geometric", "render", "tof"} <= set(known_trial_kinds())
    unbounded = [f"{k}.{p.name}" for k, p in _parameters()
                 if (p.lower is None or p.upper is None) and not p.choice_only]
    assert not unbounded, unbounded
    for k, p in _parameters():
        assert p.check(p.default) == p.default, (k, p.name)  # the default lies inside (or is a code)
        if p.choice_only:  # a choice (the demosaic): its words only, never varied
            assert [p.check(c.word) for c in p.codes] == [c.value for c in p.codes]
            continue
        assert math.isfinite(p.lower) and math.isfinite(p.upper) and p.lower < p.upper, (k, p)


def test_a_parameter_takes_the_cli_bounds_of_its_quantity():
    for k, p in _parameters():
        key = SAME_QUANTITY.get(p.name, p.name)
        if key in INPUT_BOUNDS:
            assert (p.lower, p.upper) == INPUT_BOUNDS[key][:2], (k, p.name)
    render = get_trial_kind("render").parameters
    # 0 is the phone's automatic ISO: a code, written 'phone', not a quantity
    assert render["iso"].word(0.0) == "phone" and render["iso"].check("phone") == 0.0
    assert render["spp"].upper == render["roi_spp"].upper == MAX_SPP == INT_BOUNDS["spp"][1]
    assert render["render_seed"].upper == MAX_SEED == INT_BOUNDS["seed"][1]
    tof = get_trial_kind("tof").parameters
    assert (tof["range_m"].lower, tof["range_m"].upper) == DESIGN_RANGE_M


RENDER = ["render", "--camera", "galaxy-nexus", "--range", "5"]
SENSITIVITY = ["sensitivity", "--camera", "galaxy-nexus", "--vary", "sigma_px=0:1", "--vary", "focal_error_frac=0:0.1"]


@pytest.mark.parametrize("argv, flag, value, largest", [
    (RENDER, "--spp", MAX_SPP + 1, MAX_SPP),
    (RENDER, "--roi-spp", 10**12, MAX_SPP),
    (RENDER, "--seed", MAX_SEED + 1, MAX_SEED),
    (SENSITIVITY, "--seed", 2**64, MAX_SEED),
])
def test_the_cli_bounds_samples_per_pixel_and_seeds(argv, flag, value, largest, tmp_path):
    parser = build_parser()
    out = ["--out", str(tmp_path / "out")]
    with pytest.raises(InputError) as exc:
        check_args(parser.parse_args([*argv, *out, flag, str(value)]), parser)
    assert str(exc.value).startswith(f"{flag}: expected ") and f" to {largest}" in str(exc.value), str(exc.value)
    check_args(parser.parse_args([*argv, *out, flag, str(largest)]), parser)  # the largest passes
    assert not (tmp_path / "out").exists()


def test_a_study_seed_is_bounded_like_the_option():
    assert check_seed(MAX_SEED) == MAX_SEED
    with pytest.raises(InputError, match=f"0 to {MAX_SEED}"):
        check_seed(MAX_SEED + 1)


def _other(p_name: str) -> str:
    return "k1_error=-0.1:0.1" if p_name == "focal_error_frac" else "focal_error_frac=-0.1:0.1"


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """One refused run first: the imports and the profile loads are not the refusal's time."""
    out = tmp_path_factory.mktemp("warm") / "out"
    main(["sensitivity", "--camera", "galaxy-nexus", "--vary", "sigma_px=0:1e308", "--vary", _other("sigma_px"),
          "--out", str(out)])


@pytest.mark.parametrize("kind, name", [(k, p.name) for k, p in _parameters(("geometric", "render"))])
def test_an_absurd_vary_high_is_refused_before_any_work(kind, name, warm, tmp_path, capsys):
    p = get_trial_kind(kind).parameters[name]
    out = tmp_path / "out"
    coded = any(p.default == c.value for c in p.codes)
    quantity = p.lower if not p.lower_open else p.lower + 0.5 * (p.upper - p.lower)
    low = quantity if p.default is None else p.default if not coded or p.choice_only else quantity
    argv = ["sensitivity", "--camera", "galaxy-nexus", "--trial-kind", kind, "--vary", f"{name}={low!r}:1e308",
            "--vary", _other(name), "--out", str(out)]
    t0 = time.perf_counter()
    rc = main(argv)
    elapsed_s = time.perf_counter() - t0
    cap = capsys.readouterr()
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and cap.out == "", cap.err
    if p.choice_only:  # a choice is held fixed, never varied: its LOW is refused already
        assert f"--vary {name} LOW" in lines[0] and "a choice, not a quantity" in lines[0], lines[0]
        assert elapsed_s < 1.0 and not out.exists()
        return
    assert f"--vary {name} HIGH" in lines[0] and "Traceback" not in cap.err, lines[0]
    if name == "range_m":  # the camera's envelope (svgs_sim.svgs.envelope.range_envelope_m)
        assert "allowed" in lines[0] and " m)" in lines[0], lines[0]
    else:
        assert p.domain(codes=False) in lines[0], lines[0]
    assert elapsed_s < 1.0 and not out.exists()


def test_a_code_is_written_and_shown_as_its_word_never_as_its_number(tmp_path, capsys):
    """'profile', 'renderer', 'phone', 'app'...: the store's -1 / 0 never reach the user."""
    render = get_trial_kind("render").parameters
    assert render["f_number"].check("profile") == -1.0 and render["f_number"].word(-1.0) == "profile"
    assert render["threshold"].check("otsu") == -1.0 and render["spp"].check("renderer") == -1.0
    msg = render["f_number"].domain()
    assert msg == "1 to 16, or 'profile' (the profile's [optics] f_number)" and "-1" not in msg
    with pytest.raises(InputError, match=r"f_number: expected 1 to 16, or 'profile'"):
        render["f_number"].check(0.2)  # once accepted: inside the sentinel's old range -1..16
    out = tmp_path / "out"
    rc = main(["sensitivity", "--camera", "galaxy-nexus", "--trial-kind", "render", "--vary", "range_m=5:10",
               "--vary", "f_number=2:4", "--fixed", "jpeg_quality=profile", "--fixed", "threshold=app",
               "--plan-only", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
