"""The input-checking layer: every ``svgs`` command's arguments are checked here before any work.

:func:`check_args` runs in :func:`svgs_sim.cli.main.main` between parsing and the command, by rules on
the argument names (one vocabulary across the commands, ``docs/architecture.md``):

- output locations (``--out``, ``--cache``): a folder that is a folder and writable (or can be
  made), or - where the metavar says ``.toml`` - a file whose folder is writable and that is not
  a folder;
- seeds (0 to 2**32 - 1), counts (>= 1: samples, trials, frames, views, workers...; samples
  per pixel at most :data:`svgs_sim.base.limits.MAX_SPP`), finite floats,
  positive physical quantities (exposure, ISO, sigmas, sizes), non-negative ones (jitter,
  ambient light) - a value equal to the option's default is the command's own choice and
  passes (some defaults are 0 for "none");
- ranges (``--range``, ``--ranges``, ``--focal-ranges``, ``--pose-ranges``, ``--from``, ``--to``): positive, finite,
  distinct, and inside the command's physical envelope, whose reason the message states - for
  the phone sensor :func:`svgs_sim.svgs.envelope.range_envelope_m` (beyond it the pattern spans fewer than
  :data:`MIN_SPAN_PX` pixels and its spots merge into one; trajectory files and sensitivity
  bounds take the same), for the ToF camera the paper's 0.27-15 m (``svgs_sim.tof.camera.DESIGN_RANGE_M``);
- every float argument: a physical bound (:data:`BOUNDS`; attitudes within
  :data:`svgs_sim.svgs.envelope.ATTITUDE_LIMITS_DEG`), so no absurd number (1e308) reaches the solver;
- the camera profile's kind: a ToF profile for ``svgs tof ...``, a phone profile elsewhere.

A failed check raises :class:`svgs_sim.base.errors.InputError` naming the input (exit 2, one line,
nothing written). Commands keep their own, more specific checks after this one.
"""

from __future__ import annotations

import math
from pathlib import Path

from svgs_sim.base.errors import InputError, number_items
from svgs_sim.svgs.envelope import MIN_SPAN_PX  # noqa: F401 - re-exported (the module notes name it)
from svgs_sim.svgs.envelope import check_attitude_deg, check_range_m, range_envelope_m
from svgs_sim.base.limits import INPUT_BOUNDS, INT_BOUNDS
from svgs_sim.cli.signals import GROUP_DESTS

#: Integer arguments that count something (>= 1).
COUNTS = {"spp", "roi_spp", "rim_spp_factor", "spot_samples", "trials", "poses", "frames", "views", "subsets",
          "focal_exposures", "poses_per_range", "exposures_per_render", "n", "exposures", "min_views", "persistence",
          "bounces", "max_active_pixels", "variant_frames", "sweep_frames", "chunk_size", "workers", "cols",
          "rows", "width", "height"}
#: Integer arguments that must be >= 0 (``--processes 0``: run inline).
NON_NEGATIVE_INTS = {"processes"}
#: Float arguments that must be > 0.
POSITIVE = {"centroid_sigma_px", "exposure_s", "iso", "focus_m", "integration_time_s",
            "modulation_frequency_hz", "spacing_mm", "marker_mm", "exposure_fill", "aspect_ratio",
            "range_m", "range", "from_m", "to_m", "duration_s", "fps"}
#: Float arguments that must be >= 0.
NON_NEGATIVE = {"attitude_deg", "sigma_px", "range_sigma_m", "merge_px", "jitter_deg", "jitter_m", "ambient", "ambient_lux", "backdrop_m"}
#: Physical bounds of every float argument (dest -> (low, high, unit)); inclusive, except a low of
#: 0 for the :data:`POSITIVE` ones: :data:`svgs_sim.base.limits.INPUT_BOUNDS`, the one table the study
#: parameters (:class:`svgs_sim.sim.trials.Parameter`) take their bounds from too. Far beyond any phone,
#: lab or ToF camera the simulator models, they keep absurd numbers (1e308) from overflowing the
#: solver and the calibrations. Ranges and attitudes are bounded by the envelope instead
#: (:func:`svgs_sim.svgs.envelope.range_envelope_m`, :data:`svgs_sim.svgs.envelope.ATTITUDE_LIMITS_DEG`);
#: tests/test_messages.py fails on a float option with neither (:func:`option_bounds`). An option
#: may carry its own as ``action.bounds``: the scene's (:func:`svgs_sim.sim.scene.add_scene_options`),
#: declared with the quantity.
BOUNDS = INPUT_BOUNDS
#: Attitude arguments (dest -> the envelope's angle).
ATTITUDES = {"roll_deg": "roll_deg", "pitch_deg": "pitch_deg", "yaw_deg": "yaw_deg"}

#: Comma-separated range lists (m).
RANGE_LISTS = {"ranges", "focal_ranges", "pose_ranges"}
#: Output locations: dest -> kind ("dir" or "file" by the metavar).
OUTPUTS = ("out", "cache")


def _flag(action) -> str:
    return max(action.option_strings, key=len) if action.option_strings else action.dest


def check_out_dir(path, flag: str = "--out") -> Path:
    """An output folder that takes a file (a probe written and removed), or could be made in a
    folder that does: :func:`svgs_sim.cli.outdir.check_output_folder` (nothing made; not fooled as root).

    Raises
    ------
    InputError
        An existing file, or a folder (or the folder it would be made in) that is not one or
        does not take a file; the message names ``flag``.
    """
    from svgs_sim.cli.outdir import check_output_folder

    return check_output_folder(path, flag)


def check_out_file(path, flag: str = "--out") -> Path:
    """An output file: not a folder, in a folder that takes a file or could be made
    (:func:`svgs_sim.cli.outdir.check_output_file`)."""
    from svgs_sim.cli.outdir import check_output_file

    return check_output_file(path, flag)


def parse_range_list(text, flag: str) -> list[float]:
    """Comma-separated ranges (m): finite, positive and distinct."""
    if not str(text).strip():
        raise InputError(f"{flag}: no range given")
    vals = number_items(text, flag)
    bad = [v for v in vals if not (math.isfinite(v) and v > 0)]
    if bad:
        raise InputError(f"{flag}: ranges must be positive, finite metres, got {bad}")
    dup = sorted({v for v in vals if vals.count(v) > 1})
    if dup:
        raise InputError(f"{flag}: repeated range(s) {dup}; each range is one row of the results")
    return vals


def phone_range_envelope_m(camera, pattern) -> tuple[float, float]:
    """(near, far) ranges of the phone sensor (m): :func:`svgs_sim.svgs.envelope.range_envelope_m`."""
    return range_envelope_m(camera, pattern)


def _interval(dest: str, bounds) -> str:
    lo, hi, unit = bounds
    unit = f" {unit}" if unit else ""
    if dest in POSITIVE and lo == 0:
        return f"a value > 0 and at most {hi:g}{unit}"
    return f"{lo:g} to {hi:g}{unit}"


def _command(args) -> str:
    words = [args.command]
    for k in GROUP_DESTS:
        if getattr(args, k, None):
            words.append(getattr(args, k))
    return " ".join(words)


def option_bounds(action):
    """The physical bounds ``(low, high, unit)`` of a float option: :data:`BOUNDS` by its dest, else
    the option's own ``bounds`` attribute; None if neither."""
    return BOUNDS.get(action.dest) or getattr(action, "bounds", None)


def check_args(args, parser) -> None:
    """Check ``args`` (a parsed namespace of ``parser``) by the rules of the module notes.

    Raises
    ------
    InputError
    """
    actions = {a.dest: a for a in _actions(parser, args)}
    cmd = _command(args)
    for dest, a in actions.items():
        if not hasattr(args, dest):
            continue
        v = getattr(args, dest)
        if v is None or isinstance(v, bool):
            continue
        flag = _flag(a)
        if dest in OUTPUTS and isinstance(v, str):
            meta = (a.metavar or "").lower()
            (check_out_file if meta.endswith(".toml") else check_out_dir)(v, flag)
            continue
        if v == a.default:
            continue  # the command's own default (0 may mean "none" or "automatic" there)
        vals = v if isinstance(v, list) else [v]
        for x in vals:
            if isinstance(x, bool):
                continue
            if isinstance(x, int):
                if dest == "seed" and x < 0:
                    raise InputError(f"{flag}: expected a non-negative integer seed, got {x}")
                if dest in COUNTS and x < 1:
                    raise InputError(f"{flag}: expected a positive whole number, got {x}")
                if dest in NON_NEGATIVE_INTS and x < 0:
                    raise InputError(f"{flag}: expected a whole number >= 0, got {x}")
                b = INT_BOUNDS.get(dest)  # whole numbers with an upper bound (samples per pixel, seeds)
                if b is not None and not b[0] <= x <= b[1]:
                    raise InputError(f"{flag}: expected {b[0]} to {b[1]}{' ' + b[2] if b[2] else ''}, got {x}")
            elif isinstance(x, float):
                if not math.isfinite(x):
                    raise InputError(f"{flag}: expected a finite number, got {x!r}")
                if dest in ATTITUDES:
                    check_attitude_deg(ATTITUDES[dest], x, flag)
                    continue
                b = option_bounds(a)
                if b is not None and not (b[0] <= x <= b[1] and not (dest in POSITIVE and x == b[0] == 0)):
                    raise InputError(f"{flag}: expected {_interval(dest, b)}, got {x!r}")
                if b is None and dest in POSITIVE and x <= 0:
                    raise InputError(f"{flag}: expected a positive value, got {x!r}")
                if b is None and dest in NON_NEGATIVE and x < 0:
                    raise InputError(f"{flag}: expected a value >= 0, got {x!r}")
    ranges = {}
    for dest in ("range_m", "range", "from_m", "to_m"):
        if dest in actions and getattr(args, dest, None) is not None:
            v = getattr(args, dest)
            ranges[_flag(actions[dest])] = [float(x) for x in (v if isinstance(v, list) else [v])]
    for dest in RANGE_LISTS:
        if dest in actions and isinstance(getattr(args, dest, None), str):
            ranges[_flag(actions[dest])] = parse_range_list(getattr(args, dest), _flag(actions[dest]))
    _check_profile_and_envelope(args, cmd, ranges)


def _actions(parser, args):
    """The actions of the subparser that parsed ``args`` (:func:`svgs_sim.cli.main.leaf_parser`)."""
    from svgs_sim.cli.main import leaf_parser

    p = leaf_parser(parser, args)
    return [a for a in p._actions if a.dest not in ("help",) and not a.__class__.__name__.startswith("_SubParsers")]


def _check_profile_and_envelope(args, cmd: str, ranges: dict) -> None:
    cam_name = getattr(args, "camera", None)
    if cmd.startswith("tof "):
        from svgs_sim.tof.camera import DESIGN_RANGE_M  # the ToF sensor's envelope (imported only for its commands)

        lo, hi = DESIGN_RANGE_M
        for flag, vals in ranges.items():
            bad = [v for v in vals if not lo <= v <= hi]
            if bad:
                raise InputError(f"{flag}: expected {lo}-{hi} m (the ToF paper's design range, inside the 15 m "
                                 f"unambiguous range of its 10 MHz modulation), got {bad}")
        return  # the ToF commands load their profile with tof.load_camera (refuses phone profiles)
    if not isinstance(cam_name, str) or cmd in ("calibrate board",):
        return
    from svgs_sim.base.profiles import load_camera, load_pattern

    cam = load_camera(cam_name)
    if cmd == "sensitivity" and getattr(args, "trial_kind", None) == "tof":
        if not cam.is_tof:  # the ToF kind renders the ToF camera: a phone profile is the wrong sensor
            raise InputError(f"--camera: {cam.name!r} is a phone (SVGS) profile; --trial-kind tof needs a "
                             "time-of-flight camera profile such as 'tof-epc660'")
        return
    if cam.is_tof:
        raise InputError(f"--camera: {cam.name!r} is a time-of-flight camera profile; this command needs a phone "
                         "(SVGS) profile such as 'galaxy-nexus' (the ToF sensor's commands are 'svgs tof ...')")
    if not ranges:
        return
    pat_name = getattr(args, "pattern", None) or "svgs-3u"
    try:
        pat = load_pattern(pat_name)
    except InputError:
        return  # the command reports the pattern itself
    for flag, vals in ranges.items():
        check_range_m(vals, cam, pat, flag)
