"""The wheel: one top-level import package (``svgs_sim``) holding every package-data file, and
the data found through :mod:`importlib.resources`, never by a path relative to a module's file."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> zipfile.ZipFile:
    """The wheel ``pip wheel --no-deps`` builds from a copy of the sources (the checkout itself
    gets no build folder)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "svgs_sim", src / "svgs_sim", ignore=shutil.ignore_patterns("__pycache__", ".*"))
    p = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                        str(src), "-w", str(tmp / "dist")], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    (whl,) = (tmp / "dist").glob("svgs_sim-*.whl")
    return zipfile.ZipFile(whl)


def test_the_wheel_installs_one_top_level_package(wheel):
    names = wheel.namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"svgs_sim"}
    (top_level,) = [n for n in names if n.endswith(".dist-info/top_level.txt")]
    assert wheel.read(top_level).decode().split() == ["svgs_sim"]


def test_the_wheel_holds_every_data_file_and_module(wheel):
    """Every file of the package in the checkout (TOML profiles, overlays, the papers' CSV tables,
    modules) is in the wheel."""
    names = set(wheel.namelist())
    want = {str(p.relative_to(ROOT)) for p in (ROOT / "svgs_sim").rglob("*")
            if p.is_file() and "__pycache__" not in p.parts and not any(x.startswith(".") for x in p.parts)}
    assert len(want) > 150
    assert want - names == set()


def test_the_console_script_names_the_package(wheel):
    (ep,) = [n for n in wheel.namelist() if n.endswith(".dist-info/entry_points.txt")]
    assert re.search(r"^svgs = svgs_sim\.cli\.main:main$", wheel.read(ep).decode(), re.M)


def test_no_module_finds_data_by_its_own_file_path():
    """Package data is found with importlib.resources (svgs_sim.assets.ASSETS_DIR): no module
    builds a path from ``__file__`` (the kernel-cache check of ``cli.compile_kernels`` looks for
    numba's cache files beside the modules, which are not data)."""
    uses = [f"{p.relative_to(ROOT)}:{i}" for p in sorted((ROOT / "svgs_sim").rglob("*.py"))
            for i, line in enumerate(p.read_text().splitlines(), 1) if "__file__" in line]
    assert len(uses) == 1 and uses[0].startswith("svgs_sim/cli/compile_kernels.py:"), uses
