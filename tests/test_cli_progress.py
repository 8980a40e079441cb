"""Progress from the first second (issue 14, item 4): long work says what it is doing."""

import importlib.util

import numpy as np
import pytest

from svgs_sim.cli.main import main


def test_a_fresh_install_says_it_is_compiling(monkeypatch, tmp_path, capsys):
    import cv2

    import svgs_sim.cli.compile_kernels as ck

    img = tmp_path / "dark.png"
    cv2.imwrite(str(img), np.zeros((1944, 2592), np.uint8))
    monkeypatch.setattr(ck, "kernels_cached", lambda: False)
    assert main(["solve", str(img), "--camera", "galaxy-nexus"]) == 1  # nothing to solve in a dark frame
    err = capsys.readouterr().err
    assert "compiling the solver" in err and "first run only" in err
    monkeypatch.setattr(ck, "kernels_cached", lambda: True)
    main(["solve", str(img), "--camera", "galaxy-nexus"])
    assert "compiling" not in capsys.readouterr().err


def test_the_kernel_cache_is_found_where_numba_keeps_it(monkeypatch, tmp_path):
    import io

    from svgs_sim.cli.compile_kernels import compile_kernels, kernels_cached

    compile_kernels(out=io.StringIO())  # cached by `make`; cheap when already compiled
    assert kernels_cached()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty"))
    assert not kernels_cached()


@pytest.mark.render
@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba is not installed")
def test_the_stability_run_shows_a_progress_bar_and_a_status_line(capsys):
    assert main(["tof", "stability", "--range", "5.712", "--frames", "30", "--spp", "8"]) == 0
    err = capsys.readouterr().err
    assert err.splitlines()[0].startswith("rendering tof-epc660")
    assert "frames:" in err and "30/30" in err


def test_every_extra_signature_names_a_cached_kernel_and_its_arity():
    """``make``'s compile step (issue 40): each listed signature is a cached numba kernel of the
    project with as many arguments as the kernel's Python function takes, so a renamed kernel or a
    changed argument list fails here, not as a compile in the middle of a user's first run."""
    import importlib
    import inspect

    from svgs_sim.cli.compile_kernels import EXTRA_SIGNATURES, parse_signature

    assert len(EXTRA_SIGNATURES) >= 10
    for path, sigs in EXTRA_SIGNATURES.items():
        mod, name = path.rsplit(".", 1)
        kernel = getattr(importlib.import_module(mod), name)
        assert type(kernel._cache).__name__ != "NullCache", path  # @njit(cache=True): kept on disk
        n_args = len(inspect.signature(kernel.py_func).parameters)
        assert sigs and len(set(sigs)) == len(sigs), path
        for text in sigs:
            assert len(parse_signature(text)) == n_args, (path, text)
    with pytest.raises(ValueError, match="not a kernel signature word"):
        parse_signature("f8[2], x9")
