# SPDX-License-Identifier: GPL-3.0-or-later
"""The layout rules of the extension's code (``../shared/DESIGN.md``): no import circle
between its modules (imports inside functions count: they hide a circle, they do not
remove it), imports at the top of their modules, no module over 600 lines but those
listed with their reason, the engine (``engine/``) free of Blender, what the live view's
worker threads import free of ``gpu``, and the shipped packages free of the development
helpers (``tools/``, not in the zip). Read from the source with ``ast``
(``tools/import_graph.py``); nothing of the extension is imported."""

import ast
import io
import tokenize
from pathlib import Path

from curved_reflections.tools.import_graph import module_names, relative_imports

REPO_ROOT = Path(__file__).resolve().parents[1]
#: What the zip ships, and the development helpers beside it (same rules, never imported
#: by the shipped ones).
SHIPPED_PACKAGES = ("engine", "drawing", "blender")
PACKAGES = SHIPPED_PACKAGES + ("tools",)
#: No module over this many lines but those in :data:`OVER_THE_CEILING`.
MAX_LINES = 600
#: {module: why it is longer than :data:`MAX_LINES`}. An entry goes once its module is
#: split (a test fails while a module listed here is no longer over the ceiling).
OVER_THE_CEILING: dict = {}
#: Imports inside functions other than a module's ``register()`` / ``unregister()``
#: allowed in all (issue 45), each with its reason in a comment on its line or the line
#: above: an import circle no better split removes, an optional dependency.
MAX_LOCAL_IMPORTS = 10
#: Modules the live view's worker threads import (``blender/live_workers.py``): numpy
#: work that must import without Blender's ``gpu``, nor reach a module that imports it.
WORKER_IMPORTS = ("drawing.methods.camera_source",)
#: Modules of Blender's own that exist only inside Blender (or the ``bpy`` module).
BLENDER_MODULES = {"bpy", "gpu", "mathutils", "bmesh"}


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
    assert "drawing.methods.sbc_triangles" in graph["drawing.reflection_draw"]
    assert "engine.methods.sbc.sbc" in graph["engine.methods.sbc.sbc_build"]
    assert "blender.live" in graph["blender.live_handlers"]
    assert "engine.methods.morphing.morph_grid" in graph["engine.methods.morphing.morphing"]
    assert "engine.geometry.raytrace" in graph["engine.reference.exact"]


def test_no_import_circle():
    assert _cycles(_graph()) == []


def test_a_circle_is_found():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def _lengths() -> dict:
    return {name or "__init__": len(path.read_text(encoding="utf-8").splitlines())
            for name, path in _modules().items()}


def test_no_module_over_600_lines_but_those_listed_with_their_reason():
    over = {name: n for name, n in _lengths().items() if n > MAX_LINES and name not in OVER_THE_CEILING}
    assert over == {}, f"over {MAX_LINES} lines (split by concept, or list with the reason): {over}"
    assert all(reason.strip() for reason in OVER_THE_CEILING.values())


def test_every_module_listed_over_the_ceiling_still_is():
    lengths = _lengths()
    stale = {name: lengths.get(name, "no such module") for name in OVER_THE_CEILING
             if not (name in lengths and lengths[name] > MAX_LINES)}
    assert stale == {}, f"listed in OVER_THE_CEILING but not over {MAX_LINES} lines: {stale}"


def _local_imports(source: str) -> list:
    """(line, whether a comment gives its reason) of each import inside a function
    other than a module-level ``register()`` / ``unregister()``: the comment on one of
    the import's lines, or alone on the line above."""
    alone = {}  # {line: whether its comment stands alone on it}
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            alone[token.start[0]] = not token.line[:token.start[1]].strip()
    tree = ast.parse(source)
    found = []

    def visit(node, in_function: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if not (node is tree and child.name in ("register", "unregister")):
                    visit(child, True)
            elif isinstance(child, (ast.Import, ast.ImportFrom)) and in_function:
                reason = (any(line in alone for line in range(child.lineno, child.end_lineno + 1))
                          or alone.get(child.lineno - 1, False))
                found.append((child.lineno, reason))
            else:
                visit(child, in_function)

    visit(tree, False)
    return found


def test_a_local_import_is_found_with_its_reason():
    source = (
        "import os\n"
        "def register():\n    from . import blender\n"
        "def f():\n    import gpu\n"
        "    x = 1  # unrelated\n    import bpy\n"
        "    # the package imports this module\n    from . import b\n"
        "class C:\n    def g(self):\n        from .a import (x,  # optional\n            y)\n"
        "        def inner():\n            import numpy\n"
        "    def register(self):\n        import bmesh\n"
    )
    assert _local_imports(source) == [(5, False), (7, False), (9, True), (12, True), (15, False), (17, False)]


def test_imports_sit_at_the_top_of_their_modules():
    found = [(f"{path.relative_to(REPO_ROOT).as_posix()}:{line}", reason) for path in _modules().values()
             for line, reason in _local_imports(path.read_text(encoding="utf-8"))]
    unexplained = [where for where, reason in found if not reason]
    problems = ([f"{len(found)} imports inside functions, at most {MAX_LOCAL_IMPORTS}"]
                if len(found) > MAX_LOCAL_IMPORTS else []) + (
        [f"{len(unexplained)} without a comment giving the reason"] if unexplained else [])
    assert not problems, "; ".join(problems) + ":\n" + "\n".join(
        where + ("" if reason else "  (no reason given)") for where, reason in found)


def _blender_imports(path: Path) -> set:
    """The modules of :data:`BLENDER_MODULES` that a module imports, anywhere in its source."""
    roots = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            roots |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots & BLENDER_MODULES


def test_what_the_worker_threads_import_never_touches_the_gpu():
    modules, graph = _modules(), _graph()
    for start in WORKER_IMPORTS:
        reached, waiting = set(), [start]
        while waiting:
            name = waiting.pop()
            if name not in reached:
                reached.add(name)
                waiting += graph[name]
        touching = {name: found for name in sorted(reached) if (found := _blender_imports(modules[name]))}
        assert touching == {}, (start, touching)


def test_the_engine_never_imports_blender():
    for name, path in _modules().items():
        if not name.startswith("engine"):
            continue
        assert _blender_imports(path) == set(), name


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


#: The types the renderer and the frame pipeline hand around without asking which one
#: they hold: the per-frame passes, the projection sources, the sample-based camera.
PASS_AND_SOURCE_TYPES = {"FramePass", "IterativePass", "MorphPass", "PerturbationPass", "SBCTextures",
                         "CameraSource", "MorphSource", "SampleBasedCamera"}
#: What a pass or a source answers by its protocol (``frame_pass.FramePass``, the
#: projection source of ``drawing/methods/sbc_triangles.py``): never sniffed by name.
PROTOCOL_ATTRIBUTES = {"ray_map", "view", "downsample", "groups", "on_gpu", "sheet_subdivisions", "project",
                       "cones", "true_rays", "methods", "grids", "answers", "reflector_indices"}


def _type_sniffs(source: str) -> list:
    """(line, call) of each ``isinstance`` naming a pass or source type and each
    ``hasattr`` / ``getattr`` naming a protocol attribute in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Name) or len(node.args) < 2:
            continue
        if node.func.id == "isinstance":
            names = {n.id if isinstance(n, ast.Name) else n.attr for n in ast.walk(node.args[1])
                     if isinstance(n, (ast.Name, ast.Attribute))}
            if names & PASS_AND_SOURCE_TYPES:
                found.append((node.lineno, ast.unparse(node)))
        elif node.func.id in ("hasattr", "getattr") and isinstance(node.args[1], ast.Constant) \
                and node.args[1].value in PROTOCOL_ATTRIBUTES:
            found.append((node.lineno, ast.unparse(node)))
    return found


def test_no_pass_or_source_is_told_apart_by_its_type_or_its_attributes():
    """In the layers that hand passes and sources around (the drawing and Blender layers;
    the engine checks what it reads back from a cache file, which is no protocol)."""
    layers = {name: path for name, path in _modules().items() if name.split(".")[0] in ("drawing", "blender")}
    sniffs = {name: found for name, path in layers.items() if (found := _type_sniffs(path.read_text(encoding="utf-8")))}
    assert sniffs == {}


def test_a_type_sniff_is_found():
    assert [line for line, _ in _type_sniffs("isinstance(x, projection.SBCTextures)\nhasattr(x, 'ray_map')\n"
                                             "getattr(x, 'cones', None)\nisinstance(x, int)\n")] == [1, 2, 3]
