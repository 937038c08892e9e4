# SPDX-License-Identifier: GPL-3.0-or-later
"""The extension's import graph, read from source with ``ast`` (nothing is imported).

Modules are named by their dotted path inside the extension, the root ``__init__.py``
being ``""`` and a package its ``__init__.py`` (``"engine.geometry"``). Only relative
imports count, the only kind the extension uses for its own modules (Blender installs it
as ``bl_ext.<repo>.curved_reflections``), and they count wherever they stand: an import
inside a function runs as surely as one at the top, only later.

``tests/test_layout.py`` looks for circles in this graph; ``tests/blender/test_packaging.py``
walks it from the root ``__init__.py`` through the built zip to find shipped modules the
extension never imports.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping


def module_name(path: str) -> str | None:
    """The dotted name of a ``.py`` file at ``path`` ("/"-separated, relative to the
    extension's root), or ``None`` for any other file."""
    if not path.endswith(".py"):
        return None
    parts = path[:-len(".py")].split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_names(paths: Iterable[str]) -> dict[str, str]:
    """{dotted name: path} of the ``.py`` files among ``paths``."""
    return {name: path for path in paths if (name := module_name(path)) is not None}


def relative_imports(name: str, source: str, is_package: bool, modules) -> tuple[set, list]:
    """The modules of ``modules`` that module ``name`` imports relatively, anywhere in
    ``source``, and the relative imports that name none of them (as written, e.g.
    ``"from ..tools import metrics"``): a module missing from ``modules``, or one beyond
    the extension's root. ``from .pkg import name`` counts as importing ``pkg.name`` when
    that is a module, else ``pkg`` (whose ``__init__`` defines ``name``)."""
    parts = name.split(".") if name else []
    package = parts if is_package else parts[:-1]
    found, unresolved = set(), []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom) or node.level == 0:
            continue
        written = f"from {'.' * node.level}{node.module or ''} import {', '.join(a.name for a in node.names)}"
        if node.level - 1 > len(package):
            unresolved.append(written)
            continue
        base = package[:len(package) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
        for alias in node.names:
            submodule = f"{target}.{alias.name}" if target else alias.name
            if submodule in modules:
                found.add(submodule)
            elif target in modules:
                found.add(target)
            else:
                unresolved.append(written)
    found.discard(name)
    return found, unresolved


def reachable(graph: Mapping[str, Iterable[str]], start: str = "") -> set:
    """The modules that importing ``start`` can run: those ``graph`` leads to, each with
    the packages above it (importing ``a.b.c`` runs ``a`` and ``a.b`` first)."""
    seen, pending = set(), [start]
    while pending:
        name = pending.pop()
        if name in seen:
            continue
        seen.add(name)
        parts = name.split(".") if name else []
        pending.extend(".".join(parts[:k]) for k in range(len(parts)))
        pending.extend(graph.get(name, ()))
    return seen
