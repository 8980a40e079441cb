"""Variant selection: the decision logic with faked probes, and a real LLVM-15 fallback.

The decision (:func:`svgs_sim.render.variant.decide`, :func:`svgs_sim.render.variant.pick_llvm`) is pure, so
an LLVM-15-only machine is simulated by faking the facts; the last test loads this
machine's real LLVM 15 (Debian 12 ships it) in a subprocess, where Dr.Jit would abort on
the first kernel, and checks that the renderer falls back to scalar and renders.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from svgs_sim.render.variant import (
    MIN_LLVM_MAJOR,
    VARIANT_FOR_BACKEND,
    decide,
    llvm_major_from_path,
    pick_llvm,
)
from svgs_sim.base.errors import InputError

REPO = Path(__file__).resolve().parents[1]
ALL = ["scalar_rgb", "llvm_ad_mono", "llvm_ad_rgb", "cuda_ad_mono"]


@pytest.mark.parametrize(
    "path, major",
    [
        ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15),
        ("/usr/lib/x86_64-linux-gnu/libLLVM-14.0.6.so.1", 14),
        ("/venv/lib/libLLVM.so.23.1", 23),
        ("/usr/lib/llvm-19/lib/libLLVM.so", 19),
        ("/opt/lib/libLLVM-19.so", 19),
        ("/opt/lib/libfoo.so", None),
    ],
)
def test_llvm_major_from_file_name(path, major):
    assert llvm_major_from_path(path) == major


def test_llvm15_only_machine_falls_back_to_scalar():
    # what Debian 12 without the wheel looks like: only LLVM 15 (and 14) on the system
    cands = [("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15, "system"),
             ("/usr/lib/x86_64-linux-gnu/libLLVM-14.so.1", 14, "system")]
    path, note = pick_llvm(cands, exists=lambda p: True)
    assert path is None  # no library is handed to Dr.Jit ...
    # ... so Dr.Jit loads its default (15): the decision must avoid the llvm variant
    name, backend, notice = decide(None, cuda_ok=False, llvm_version=(15, 0, 6), available=ALL)
    assert (name, backend) == ("scalar_rgb", "scalar")
    assert "LLVM 15" in notice and "karellen-llvm-core" in notice


def test_wheel_llvm_preferred_over_system_15():
    cands = [("/venv/lib/libLLVM.so.23.1", 23, "wheel"),
             ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15, "system")]
    assert pick_llvm(cands, exists=lambda p: True)[0] == "/venv/lib/libLLVM.so.23.1"
    assert decide(None, cuda_ok=False, llvm_version=(23, 1, 4), available=ALL)[:2] == ("llvm_ad_mono", "llvm")


def test_user_llvm_path_of_version_15_is_ignored():
    cands = [("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15, "env"),
             ("/usr/lib/llvm-19/lib/libLLVM.so.1", 19, "system")]
    path, note = pick_llvm(cands, exists=lambda p: True)
    assert path == "/usr/lib/llvm-19/lib/libLLVM.so.1"
    assert "cannot use" in note


def test_cuda_preferred_when_present():
    assert decide(None, cuda_ok=True, llvm_version=(23, 1, 4), available=ALL)[0] == VARIANT_FOR_BACKEND["cuda"]


@pytest.mark.parametrize("req, expect", [("scalar", "scalar_rgb"), ("llvm", "llvm_ad_mono"), ("llvm_ad_rgb", "llvm_ad_rgb")])
def test_explicit_request_wins(req, expect):
    assert decide(req, cuda_ok=True, llvm_version=(23, 1, 4), available=ALL)[0] == expect


def test_request_for_llvm_with_llvm15_still_falls_back():
    name, backend, notice = decide("llvm", cuda_ok=False, llvm_version=(15, 0, 6), available=ALL)
    assert name == "scalar_rgb" and "requested" in notice


def test_request_for_cuda_without_gpu_falls_back_to_llvm():
    assert decide("cuda", cuda_ok=False, llvm_version=(19, 1, 0), available=ALL)[0] == "llvm_ad_mono"


def test_unknown_request_is_input_error():
    with pytest.raises(InputError, match="unknown Mitsuba variant"):
        decide("vulkan", cuda_ok=False, llvm_version=None, available=ALL)
    with pytest.raises(InputError, match="no variant"):
        decide("llvm_ad_spectral_weird", cuda_ok=False, llvm_version=(19, 0, 0), available=ALL)


def test_no_llvm_at_all_means_scalar():
    name, _, notice = decide(None, cuda_ok=False, llvm_version=None, available=ALL)
    assert name == "scalar_rgb" and "did not initialise" in notice
    assert MIN_LLVM_MAJOR > 15


LLVM15 = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"

_SCRIPT = r"""
import json, os, sys
import numpy as np
import drjit  # imported first, with DRJIT_LIBLLVM_PATH -> LLVM 15, as on a plain Debian 12
from svgs_sim.render import select_variant
info = select_variant()
from svgs_sim.render.api import Renderer
from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.svgs.frames import pose_from_scenario
cam = Camera(name="tiny", width=16, height=16, fx=2450.0, fy=2450.0, cx=7.5, cy=7.5,
             tables={"optics": {"focal_length_m": 0.00343, "f_number": 2.4, "focus_distance_m": 1.8},
                     "flash": {"led_offsets_m": [[0.004, 0, 0]], "emitter_diameter_m": 0.0012,
                               "radiant_intensity_w_sr": 0.03}})
pat = Pattern(name="one", ids=np.arange(1, 5), points_m=np.array([[0, 0, 0], [3, 0, 0], [0, 3, 0], [3, 3, -1.0]]))
r = Renderer(cam, pat, reflector="hollow", scene_options={"body": "none"}, spp=0, roi_spp=4, roi_size_px=8,
             spot_samples=3000)
R, t = pose_from_scenario(2.0)
res = r.render(R, t, seed=1)
print(json.dumps({"variant": info.name, "llvm": info.llvm_version, "notice": info.notice,
                  "flux": float(res.flux.sum())}))
"""


@pytest.mark.render
@pytest.mark.skipif(not os.path.exists(LLVM15), reason="needs the system's LLVM 15 to demonstrate the fallback")
def test_real_llvm15_process_falls_back_to_scalar_and_renders():
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=LLVM15)
    env.pop("SVGS_MI_VARIANT", None)
    p = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, cwd=REPO, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["variant"] == "scalar_rgb"
    assert out["llvm"][0] == 15
    assert "falling back to scalar" in out["notice"]
    # the cube return is there: I/(2R)^2 * A_ap / E_ph ~ 1.3e9 photons/s at 2 m (hollow, perfect)
    assert out["flux"] > 1e8
