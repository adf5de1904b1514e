"""The architecture as a test: imports point one way (render → scene → theory), renderers import only the base."""

from __future__ import annotations

import ast
from pathlib import Path

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
