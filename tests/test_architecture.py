"""The layered package graph (docs/architecture.md) and what ``svgs solve`` loads.

The contracts live in ``pyproject.toml`` (``[tool.importlinter]``); import-linter counts
function-level (lazy) imports too. The second test proves the contract can fail: the same
configuration on a copy of the tree with one lazy import that closes a cycle is broken.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The subpackages of svgs_sim (the layers of docs/architecture.md).
PACKAGES = tuple(sorted(p.name for p in (ROOT / "svgs_sim").iterdir() if (p / "__init__.py").is_file()))
LINT = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or shutil.which("lint-imports")


def _lint(cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run([LINT, "--config", "pyproject.toml", "--no-cache"], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def lint_available():
    if LINT is None:
        pytest.fail("lint-imports not found: install the test extra (pip install -e '.[test]')")
    return LINT


def test_import_contracts_are_kept(lint_available):
    r = _lint(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


def test_import_contract_fails_on_a_cycle(lint_available, tmp_path):
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    shutil.copytree(ROOT / "svgs_sim", tmp_path / "svgs_sim", ignore=shutil.ignore_patterns("__pycache__"))
    # a lazy import from the sensor layer up to the closed loop: svgs -> sim -> svgs
    with open(tmp_path / "svgs_sim" / "svgs" / "frames.py", "a") as fh:
        fh.write("\n\ndef _cycle():\n    from svgs_sim.sim.closed_loop import Scenario\n\n    return Scenario\n")
    r = _lint(tmp_path)
    assert r.returncode != 0
    assert "svgs_sim.svgs.frames -> svgs_sim.sim.closed_loop" in r.stdout


def test_svgs_solve_loads_no_renderer_study_or_calibration_code(tmp_path):
    import cv2
    import numpy as np

    img = tmp_path / "dark.png"
    cv2.imwrite(str(img), np.zeros((1944, 2592), np.uint8))
    code = (
        "import json, sys\n"
        "from svgs_sim.cli.main import main\n"
        f"rc = main(['solve', {str(img)!r}, '--camera', 'galaxy-nexus', '--json'])\n"
        "mods = sorted({'.'.join(m.split('.')[:2]) for m in sys.modules})\n"
        "print(json.dumps({'rc': rc, 'mods': mods}))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["rc"] == 1  # a dark frame: no solution, a clean exit
    loaded = set(out["mods"])
    assert "svgs_sim.svgs" in loaded and "svgs_sim.base" in loaded  # the scan sees the project's packages
    for forbidden in ("svgs_sim.render", "svgs_sim.sim", "svgs_sim.studies", "svgs_sim.calibration", "svgs_sim.camera",
                      "svgs_sim.tof", "mitsuba", "drjit"):
        assert forbidden not in loaded, f"svgs solve loaded {forbidden}"


def test_every_registered_command_is_in_the_parser():
    """The registry (svgs_sim.cli.main.COMMANDS) is the parser: each command and group exists once."""
    from svgs_sim.cli.main import COMMANDS, build_parser

    parser = build_parser()
    top = next(a for a in parser._actions if a.dest == "command")
    for group, _module, names in COMMANDS:
        choices = top.choices
        if group is not None:
            sub = next(a for a in top.choices[group]._actions if hasattr(a, "choices") and a.choices)
            choices = sub.choices
        for name in names:
            assert name in choices, (group, name)


def test_building_one_command_registers_only_its_modules():
    from svgs_sim.cli.main import _selected

    assert _selected(["solve", "x.png", "--camera", "galaxy-nexus"]) == {"svgs_sim.cli.solve"}
    assert _selected(["calibrate", "focal"]) == {"svgs_sim.cli.calibrate", "svgs_sim.cli.calibrate_study"}
    assert _selected(["tof", "solve"]) == {"svgs_sim.cli.tof", "svgs_sim.cli.tof_render", "svgs_sim.cli.tof_stability"}
    assert _selected(["--help"]) is None and _selected(["no-such-command"]) is None


# --------------------------------------------------------------------------- private names
def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_cross_package_uses(source: str, module: str, packages=PACKAGES) -> list[str]:
    """Where the module ``module`` (dotted name ``svgs_sim.PKG...``; its package is ``PKG``) uses a
    private name (``_x``, not ``__x__``) of another of the project's ``packages``.

    Found: ``from pkg.mod import _x``, ``from pkg import _mod``, ``import pkg._mod`` and
    ``from pkg._mod import x`` (a private module), and ``pkg.mod._x`` / ``m._x`` attribute
    access through a name an import bound to one of those packages' modules.

    Returns
    -------
    list of str
        ``"line N: what"`` for each use.
    """
    import ast

    def package(path: str) -> str | None:
        parts = path.split(".")
        return parts[1] if parts[0] == "svgs_sim" and len(parts) > 1 else None

    own = package(module)
    here = module.split(".")[:-1]  # the module's package (for a package's __init__: the package)
    found, bound = [], {}  # bound: local name -> dotted path in a project package

    def foreign(path: str) -> bool:
        top = package(path)
        return top in packages and top != own

    def check_path(path: str, line: int, what: str) -> None:
        if foreign(path) and any(_is_private(p) for p in path.split(".")[2:]):
            found.append(f"line {line}: {what}")

    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                check_path(a.name, node.lineno, f"import {a.name}")
                if a.asname:
                    bound[a.asname] = a.name
                else:
                    bound[a.name.split(".")[0]] = a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - (node.level - 1)] if node.level > 1 else here
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for a in node.names:
                full = f"{mod}.{a.name}"
                check_path(full, node.lineno, f"from {mod} import {a.name}")
                bound[a.asname or a.name] = full
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            chain, cur = [node.attr], node.value
            while isinstance(cur, ast.Attribute):
                chain.append(cur.attr)
                cur = cur.value
            if isinstance(cur, ast.Name) and cur.id in bound and _is_private(node.attr):
                path = ".".join([bound[cur.id], *reversed(chain)])
                if foreign(path):
                    found.append(f"line {node.lineno}: {cur.id}.{'.'.join(reversed(chain))} ({path})")
    return found


def test_the_private_import_scan_finds_each_form():
    """The scan below is not vacuous: each form of reaching into another package is found, and
    a package's own private names, dunders and public names are not."""
    src = (
        "import svgs_sim.sim.trials\n"
        "import svgs_sim.sim.closed_loop as cl\n"
        "from svgs_sim.sim import trials as tr, closed_loop\n"
        "from svgs_sim.sim.trials import _camera\n"         # 4: a private name
        "import svgs_sim.sim._private_mod\n"                # 5: a private module
        "from svgs_sim.sim import _mod\n"                   # 6: a private module by from-import
        "from svgs_sim.sim._mod import public\n"            # 7: a name of a private module
        "x = svgs_sim.sim.trials._pattern('svgs-3u')\n"     # 8: attribute access through the import
        "y = cl._helper({})\n"                              # 9: through an alias
        "z = tr._camera, closed_loop.Scenario, svgs_sim.sim.__name__\n"   # 10: through a from-imported module
        "from .store import _format\n"                      # own package (relative): allowed
        "from svgs_sim.studies.store import _parse\n"       # own package: allowed
    )
    got = private_cross_package_uses(src, "svgs_sim.studies.example")
    assert [g.split(":")[0] for g in got] == ["line 4", "line 5", "line 6", "line 7", "line 8", "line 9", "line 10"], got
    # in sim, sim's private names are its own; studies' is not
    assert [g.split(":")[0] for g in private_cross_package_uses(src, "svgs_sim.sim.example")] == ["line 12"]


def test_no_module_uses_another_packages_private_names():
    """A package's private names (``_x``) are its own: another package imports only public ones."""
    bad = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / "svgs_sim" / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            module = ".".join(rel.parts)  # a package's __init__ as pkg.__init__: its package is pkg
            for use in private_cross_package_uses(path.read_text(), module):
                bad.append(f"{rel.with_suffix('.py')} {use}")
    assert not bad, "private names of another package:\n" + "\n".join(bad)


#: A function whose code (its docstring not counted) is longer than this many lines says why in
#: its docstring, in the form "This function is long (~N lines) because ...".
MAX_FUNCTION_LINES = 90
_REASON = r"\blong \(~?\d+ lines\) because\b"


def long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``"name (N lines)"`` of every function in ``source`` whose code (docstring excluded) is
    longer than ``limit`` lines and whose docstring gives no reason (see :data:`_REASON`)."""
    import ast
    import re

    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant) \
                    and isinstance(first.value.value, str):
                n -= first.end_lineno - first.lineno + 1
            if n > limit and not re.search(_REASON, ast.get_docstring(node) or "", re.IGNORECASE):
                out.append(f"{node.name} ({n} lines)")
    return out


def test_long_function_check_can_fail():
    body = "\n".join(f"    x{i} = {i}" for i in range(100))
    assert long_functions(f"def f():\n{body}\n") == ["f (101 lines)"]
    assert long_functions(f'def f():\n    """This function is long (~100 lines) because ..."""\n{body}\n') == []
    assert long_functions(f"def f():\n{body}\n", limit=200) == []
    assert long_functions(f'def f():\n    """Slow at long range; lines of sight."""\n{body}\n') == ["f (101 lines)"]
    doc = '    """Doc.\n' + "\n" * 30 + '    """\n'
    short = "\n".join(f"    x{i} = {i}" for i in range(80))
    assert long_functions(f"def f():\n{doc}{short}\n") == []  # the docstring does not count


def test_no_function_is_long_without_a_reason():
    """No function over ~90 lines without a reason in its docstring (the project's packages,
    tools, examples and benchmarks)."""
    bad = []
    for folder in ("svgs_sim", "tools", "examples", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            bad += [f"{path.relative_to(ROOT)}: {f}" for f in long_functions(path.read_text())]
    assert not bad, "functions over %d lines without a reason in the docstring:\n" % MAX_FUNCTION_LINES + "\n".join(bad)


# ----------------------------------------------------------------------------- function-level imports
#: Libraries slow to import or optional (and Mitsuba/Dr.Jit, which must not load before the LLVM
#: library is chosen, svgs_sim.render.variant): a module may import them inside a function.
HEAVY_LIBRARIES = {"mitsuba", "drjit", "matplotlib", "dask", "distributed", "Basilisk", "cupy", "cupyx", "galsim",
                   "pvlib", "trimesh", "astropy", "numba", "scipy", "skimage", "cv2", "PIL", "sklearn", "tqdm"}
#: Packages whose names load on first use (``__getattr__``): the renderer, so that importing it
#: loads no Mitsuba.
LAZY_PACKAGES = {"svgs_sim/render/__init__.py", "svgs_sim/render/tof/__init__.py"}
#: Function-level imports that break an import cycle: (module, imported module) -> why.
LAZY_FOR_A_CYCLE = {
    ("svgs_sim.sim.scene", "svgs_sim.sim.trials"):
        "the trial kinds' scenarios hold the closed loop's Scenario, which holds a Scene",
}


def _module_name(path: Path) -> str:
    parts = list(path.with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _lazy_project_imports(root: Path) -> dict:
    """(module, imported module, names) -> [line] of the function-level imports outside the CLI, outside
    try blocks (optional dependencies), of neither a heavy library nor a lazy package."""
    import ast

    out = {}
    for path in sorted((root / "svgs_sim").rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[1] == "cli" or rel.as_posix() in LAZY_PACKAGES:
            continue
        tree = ast.parse(path.read_text())
        parents = {c: n for n in ast.walk(tree) for c in ast.iter_child_nodes(n)}
        here = _module_name(rel)
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            chain, q = [], parents.get(node)
            while q is not None:
                chain.append(q)
                q = parents.get(q)
            if not any(isinstance(q, (ast.FunctionDef, ast.AsyncFunctionDef)) for q in chain):
                continue
            if any(isinstance(q, ast.Try) for q in chain):
                continue
            if isinstance(node, ast.ImportFrom) and node.level:
                pkg = here.split(".") if path.name == "__init__.py" else here.split(".")[:-1]
                pkg = pkg[: len(pkg) - (node.level - 1)]
                target = ".".join(pkg + ([node.module] if node.module else []))
            else:
                target = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
            if target.split(".")[0] in HEAVY_LIBRARIES:
                continue
            names = tuple(a.name for a in node.names) if isinstance(node, ast.ImportFrom) else ()
            out.setdefault((here, target, names), []).append(node.lineno)
    return out


_NEW_HEAVY = (
    "import importlib, json, sys\n"
    "H = {heavy!r}\n"
    "importlib.import_module({module!r})\n"
    "out = []\n"
    "for target, names in {targets!r}:\n"
    "    before = {{m.split('.')[0] for m in sys.modules}} & H\n"
    "    mod = importlib.import_module(target)\n"
    "    for n in names:\n"
    "        getattr(mod, n, None) if hasattr(mod, n) else importlib.import_module(target + '.' + n)\n"
    "    out.append(sorted(({{m.split('.')[0] for m in sys.modules}} & H) - before))\n"
    "print(json.dumps(out))\n"
)


@pytest.mark.slow
def test_function_level_imports_are_for_heavy_libraries_the_cli_or_a_cycle():
    """An import inside a function outside the CLI must load a heavy library the module does not
    load itself (measured: each module's lazy imports in a fresh process, one after another; one that
    seems to load nothing heavy there - an earlier one may have loaded its library - again alone in a
    fresh process, unless the same import of that module loaded one in its run), or break a listed
    cycle; anything else belongs at module level. The CLI imports in its handlers (cold start)."""
    from concurrent.futures import ThreadPoolExecutor

    root = Path(__file__).resolve().parents[1]
    lazy = _lazy_project_imports(root)
    assert set(LAZY_FOR_A_CYCLE) <= {p[:2] for p in lazy}, LAZY_FOR_A_CYCLE  # no stale entry

    def new_heavy(module, targets):
        code = _NEW_HEAVY.format(heavy=HEAVY_LIBRARIES, module=module, targets=targets)
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=300)
        assert r.returncode == 0, (module, targets, r.stderr[-2000:])
        return json.loads(r.stdout.splitlines()[-1])

    pairs = [p for p in lazy if p[:2] not in LAZY_FOR_A_CYCLE]
    modules = sorted({p[0] for p in pairs})
    groups = [[p for p in pairs if p[0] == m] for m in modules]
    with ThreadPoolExecutor(2) as ex:
        found = list(ex.map(lambda g: new_heavy(g[0][0], [(p[1], p[2]) for p in g]), groups))
    loads = {p: f for g, fs in zip(groups, found) for p, f in zip(g, fs)}

    def alone(p):
        """What decides a lazy import's load alone: its module, its target and the names that are
        submodules of the target (names of attributes import nothing more)."""
        pkg = root.joinpath(*p[1].split("."))
        subs = tuple(n for n in p[2] if (pkg / f"{n}.py").is_file() or (pkg / n / "__init__.py").is_file())
        return p[0], p[1], subs

    known = {alone(p): loads[p] for p in pairs if loads[p]}  # the same import measured in its module's run
    again = sorted({alone(p) for p in pairs if not loads[p]} - set(known))
    with ThreadPoolExecutor(2) as ex:
        known.update(zip(again, ex.map(lambda k: new_heavy(k[0], [(k[1], k[2])])[0], again)))
    loads.update({p: known[alone(p)] for p in pairs if not loads[p]})
    light = [f"{p[0]} line {lazy[p]}: {p[1]} {p[2]}" for p in pairs if not loads[p]]
    assert not light, f"function-level imports that load nothing heavy (move them to module level): {light}"
    assert len(pairs) > 10  # the scan sees the renderer's and the camera model's lazy imports
