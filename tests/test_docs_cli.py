"""docs/cli.md is generated from the commands' help: it must be current."""

import importlib.util
from pathlib import Path

TOOL = Path(__file__).resolve().parents[1] / "tools" / "make_cli_doc.py"


def test_cli_doc_is_current():
    spec = importlib.util.spec_from_file_location("make_cli_doc", TOOL)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.DOC.read_text() == mod.render(), "docs/cli.md is stale: run tools/make_cli_doc.py"


def test_every_command_is_documented():
    text = (TOOL.parents[1] / "docs" / "cli.md").read_text()
    for cmd in ("solve", "render", "render-and-solve", "range-sweep", "exposure-study", "campaign", "sensitivity",
                "calibrate focal", "calibrate board", "tof solve", "tof render-and-solve", "tof stability", "tof study",
                "doctor", "approach"):
        assert f"## `svgs {cmd}`" in text, cmd
