"""The architecture as a test: imports point one way (render → scene → theory), renderers import only the base."""

from __future__ import annotations

import ast
from pathlib import Path

import warp as wp

import grisx

ROOT = Path(grisx.__file__).parent
NEUTRAL = ("grisx.errors", "grisx.device", "grisx.params", "grisx.imageio")  # utilities below every layer


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("grisx"):
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names if a.name.startswith("grisx"))
    return names


def _allowed(module: str, prefixes: tuple[str, ...]) -> bool:
    return module.startswith(NEUTRAL) or any(module == p or module.startswith(p + ".") for p in prefixes)


def test_renderers_import_only_the_base_scene_and_theory():
    renderers = ["pt", "restir_di", "restir_gi", "restir_pt", "views"]
    for name in renderers:
        bad = [m for m in _imports(ROOT / "render" / f"{name}.py") if not _allowed(m, ("grisx.render.base", "grisx.scene", "grisx.theory", "grisx.poisson"))]
        assert not bad, f"grisx/render/{name}.py imports {bad}"


def test_layers_point_one_way():
    for layer, allowed in (("theory", ("grisx.theory",)), ("scene", ("grisx.scene", "grisx.theory")),
                           ("render/base", ("grisx.render.base", "grisx.scene", "grisx.theory"))):
        for path in (ROOT / layer).rglob("*.py"):
            bad = [m for m in _imports(path) if not _allowed(m, allowed)]
            assert not bad, f"{path.relative_to(ROOT)} imports {bad}"


def _warp_constant_attributes(source: str) -> list[str]:
    """``name.attr`` inside a ``wp.func``/``wp.kernel`` where ``name`` is also one of Warp's constants (``wp.e``, ``wp.tau``, ...)."""
    constants = {n for n in dir(wp) if not n.startswith("_") and isinstance(getattr(wp, n), (int, float))}
    found = []
    for fn in ast.walk(ast.parse(source)):
        if not isinstance(fn, ast.FunctionDef) or not any("wp." in ast.unparse(d) for d in fn.decorator_list):
            continue
        for node in ast.walk(fn):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in constants:
                found.append(f"{fn.name}:{node.lineno}: {node.value.id}.{node.attr}")
    return found


def test_warp_code_names_no_variable_after_a_warp_constant():
    # Warp 1.19 hashes a module before code generation by resolving ``e.dist`` to its constant ``wp.e``, and after it
    # (once another module that shares the function was built in the process) as the local variable: the same
    # kernels got two hashes and CI compiled ReSTIR PT's and area ReSTIR's modules twice (about 10 s each)
    bad = [f"{path.relative_to(ROOT)}:{hit}" for path in ROOT.rglob("*.py") for hit in _warp_constant_attributes(path.read_text())]
    assert not bad, bad


def test_a_local_named_after_a_warp_constant_is_caught():
    source = "import warp as wp\n@wp.func\ndef f(x: float) -> float:\n    e = Rec()\n    e.dist = x\n    return e.dist\n"
    assert _warp_constant_attributes(source) == ["f:5: e.dist", "f:6: e.dist"]


def _direct_launches(source: str) -> list[int]:
    """Lines that call ``wp.launch`` itself (not :func:`grisx.device.launch`)."""
    return [n.lineno for n in ast.walk(ast.parse(source))
            if isinstance(n, ast.Call) and ast.unparse(n.func) == "wp.launch"]


def test_render_passes_launch_in_the_projects_blocks():
    # a pass launched with wp.launch runs in Warp's 256-thread blocks, 4-14% slower on an H200
    # (grisx.device.LAUNCH_BLOCK_DIM); one-off table builds at scene load (lights, microfacet) may
    bad = [f"{path.relative_to(ROOT)}:{line}" for layer in ("render", "scene")
           for path in (ROOT / layer).rglob("*.py") if path.name not in ("lights.py", "microfacet.py")
           for line in _direct_launches(path.read_text())]
    assert not bad, bad


def test_a_direct_launch_is_caught():
    source = "import warp as wp\nfrom grisx.device import launch\nlaunch(k, dim=4)\nwp.launch(k, dim=4)\n"
    assert _direct_launches(source) == [4]
