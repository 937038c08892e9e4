# SPDX-License-Identifier: GPL-3.0-or-later
"""The layout rules of the extension's code (issue 20; ``../shared/DESIGN.md``): no
import circle between its modules (imports inside functions count: they hide a circle,
they do not remove it), no module much over 600 lines, the engine (``addon/``) free
of Blender, and the shipped packages free of the development helpers (``tools/``, not
in the zip). Read from the source with ``ast`` (``tools/import_graph.py``); nothing of
the extension is imported."""

import ast
from pathlib import Path

from curved_reflections.tools.import_graph import module_names, relative_imports

REPO_ROOT = Path(__file__).resolve().parents[1]
#: What the zip ships, and the development helpers beside it (same rules, never imported
#: by the shipped ones).
SHIPPED_PACKAGES = ("addon", "gpu_shaders", "operators")
PACKAGES = SHIPPED_PACKAGES + ("tools",)
#: "No module over about 600 lines" (issue 20): this much over is still "about".
MAX_LINES = 650


def _modules() -> dict:
    """{dotted name relative to the repository root: path} of the extension's modules."""
    paths = ["__init__.py"] + [path.relative_to(REPO_ROOT).as_posix()
                               for package in PACKAGES for path in (REPO_ROOT / package).rglob("*.py")]
    return {name: REPO_ROOT / path for name, path in module_names(paths).items()}


def _imports(name: str, path: Path, modules: dict) -> set:
    """The extension's modules that ``name`` imports, anywhere in its source."""
    return relative_imports(name, path.read_text(encoding="utf-8"), path.name == "__init__.py", modules)[0]


def _cycles(graph: dict) -> list:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph[node]:
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    return components


def _graph() -> dict:
    modules = _modules()
    # A package's __init__ importing its own modules (to register them) is not a circle
    # with a module that imports a sibling through the package.
    return {name: {target for target in _imports(name, path, modules) if not name.startswith(target + ".")}
            for name, path in modules.items()}


def test_the_graph_sees_the_known_imports():
    graph = _graph()
    assert "gpu_shaders.methods.sbc_triangles" in graph["gpu_shaders.reflection_draw"]
    assert "addon.methods.sbc.sbc" in graph["addon.methods.sbc.sbc_build"]
    assert "operators.live" in graph["operators.live_handlers"]
    assert "addon.methods.morphing.morph_grid" in graph["addon.methods.morphing.morphing"]
    assert "addon.geometry.raytrace" in graph["addon.reference.exact"]


def test_no_import_circle():
    assert _cycles(_graph()) == []


def test_a_circle_is_found():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_over_about_600_lines():
    lengths = {name or "__init__": len(path.read_text(encoding="utf-8").splitlines())
               for name, path in _modules().items()}
    assert {name: n for name, n in lengths.items() if n > MAX_LINES} == {}


def test_the_engine_never_imports_blender():
    for name, path in _modules().items():
        if not name.startswith("addon"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                roots = [a.name.split(".")[0] for a in node.names] if isinstance(node, ast.Import) else (
                    [node.module.split(".")[0]] if node.level == 0 and node.module else [])
                assert not set(roots) & {"bpy", "gpu", "mathutils", "bmesh"}, (name, roots)


def test_shipped_modules_never_import_the_development_helpers():
    """``tools/`` is not in the zip: a shipped module importing it would fail installed."""
    leaks = {name: sorted(t for t in targets if t.split(".")[0] == "tools")
             for name, targets in _graph().items() if name == "" or name.split(".")[0] in SHIPPED_PACKAGES}
    assert {name: found for name, found in leaks.items() if found} == {}


def test_every_relative_import_names_a_module():
    """One that names none fails only when it runs, perhaps inside a function on a rare path."""
    modules = _modules()
    unresolved = {name: found for name, path in modules.items()
                  if (found := relative_imports(name, path.read_text(encoding="utf-8"), path.name == "__init__.py",
                                                modules)[1])}
    assert unresolved == {}
