# SPDX-License-Identifier: GPL-3.0-or-later
"""The documentation describes the code as it is.

- Every file or folder path written in the docs (``docs/*.md``, ``docs/benchmarks/*.md``,
  ``README.md``) and in the extension's source (docstrings and comments of ``engine/``,
  ``drawing/``, ``blender/``, its GLSL) exists: ``engine/methods/sbc/sbc.py``,
  ``drawing/glsl/morph_blend.glsl``, ``tests/.../test_x.py``, ``scripts/demo.py``, a
  ``path/module.attribute``, a markdown link. Paths in the source may be relative to the
  file's own folder or one above it (``glsl/x.glsl`` in ``drawing/methods/``); the
  docs write them from the repository root, or relative to the doc for links. A bare
  file name (``sbc_pack.py``) must name a file somewhere in the repository.
- Every Sphinx-style reference in the source to one of the extension's modules
  (``:mod:`.capture```, ``:func:`..bsp.ray_cones```, ``:class:`engine.view.View```)
  resolves: relative ones against the module's package, as a relative import does, and
  the first name after the module is defined in it.
- Every ```python example of the docs runs as written, in a fresh Python in which the
  repository is the package ``curved_reflections`` (``scripts/package_link.py``, as
  ``tests/conftest.py`` does). The user guide's examples for the installed extension
  (``bl_ext.user_default.curved_reflections``, .blend files) run against the built zip in
  ``tests/blender/test_packaging.py``.

Nothing here imports ``bpy``.
"""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("engine", "drawing", "blender")

#: Extensions of the files a path may name; a path without one must start with one of
#: ROOTS (a folder, or ``path/module.attribute``).
EXTENSIONS = ("py", "glsl", "md", "json", "toml", "png", "txt")
ROOTS = ("engine", "drawing", "blender", "tests", "scripts", "docs")
_PATH = re.compile(
    r"(?<![\w./\-~:])"  # not inside a longer path, a URL or an absolute path
    r"((?:\.\./|\./)*(?:[\w\-*]+/)+[\w\-*.]*\w\.(?:" + "|".join(EXTENSIONS) + r")"
    r"|(?:" + "|".join(ROOTS) + r")/[\w\-*./]*)"
    r"(?![\w/])")
_BARE = re.compile(r"(?<![\w./\-~:`*])`{0,2}([A-Za-z_][\w\-]*\.(?:py|glsl|md))\b")
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_REFERENCE = re.compile(r":(mod|func|class|meth|data|attr|exc):`~?([\w.]+)`")
#: A dotted name written as code, from the top of one of the extension's packages.
_DOTTED = re.compile(r"``((?:" + "|".join(PACKAGES) + r")\.[\w.]+)``")
_EXAMPLE = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def _doc_files() -> list:
    docs = REPO_ROOT / "docs"
    return sorted(docs.glob("*.md")) + sorted((docs / "benchmarks").glob("*.md")) + [REPO_ROOT / "README.md"]


def _source_files() -> list:
    files = [REPO_ROOT / "__init__.py"]
    for package in PACKAGES:
        files += sorted(p for p in (REPO_ROOT / package).rglob("*") if p.suffix in (".py", ".glsl"))
    return files


def _name(path: Path) -> str:
    return path.relative_to(REPO_ROOT).as_posix()


def _all_file_names() -> set:
    return {p.name for p in REPO_ROOT.rglob("*")
            if not {".git", ".venv", "__pycache__"} & set(p.relative_to(REPO_ROOT).parts)}


def _exists(path: str, bases: list) -> bool:
    """Whether ``path`` names a file or folder below one of ``bases`` (globs: any match;
    ``module.attribute``: the module)."""
    path = path.rstrip("/")
    candidates = [path]
    head, _, last = path.rpartition("/")
    if "." in last and last.rsplit(".", 1)[1] not in EXTENSIONS:  # path/module.attribute
        candidates.append(f"{head}/{last.split('.')[0]}.py")
    for base in bases:
        for candidate in candidates:
            target = (base / candidate).resolve()
            if REPO_ROOT != target and REPO_ROOT not in target.parents:
                continue
            if "*" in candidate:
                if any(base.glob(candidate)):
                    return True
            elif target.exists():
                return True
    return False


def _missing_paths(path: Path, names: set) -> list:
    """(file, reference) of every path written in ``path`` that names nothing."""
    text = path.read_text(encoding="utf-8")
    is_doc = path.suffix == ".md"
    # Docs: from the repository root, or (links) from the doc's folder; sources: from their
    # own folder or any folder above it.
    bases = [REPO_ROOT, path.parent] if is_doc else [path.parent, *[p for p in path.parents if
                                                                    p == REPO_ROOT or REPO_ROOT in p.parents]]
    missing = []
    for match in _PATH.finditer(text):
        if not _exists(match.group(1), bases):
            missing.append((_name(path), match.group(1)))
    for match in _BARE.finditer(text):
        if match.group(1) not in names:
            missing.append((_name(path), match.group(1)))
    if is_doc:
        for match in _LINK.finditer(text):
            target = match.group(1).split("#")[0]
            outside = "://" in target or target.startswith("mailto:")
            if target and not outside and not (path.parent / target).exists():
                missing.append((_name(path), match.group(1)))
    return missing


def _module_file(parts: list) -> Path | None:
    base = REPO_ROOT.joinpath(*parts)
    for candidate in (base.with_suffix(".py") if parts else None, base / "__init__.py"):
        if candidate is not None and candidate.is_file():
            return candidate
    return None


def _defined_names(module: Path) -> set:
    names = set()
    for node in ast.parse(module.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names |= {n.id for t in node.targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return names


def _unresolved_references(path: Path, text: str | None = None) -> list:
    """(file, reference) of every reference to one of the extension's modules in the
    Python source ``path`` (or ``text``, as if written there) that does not resolve."""
    parts = list(path.relative_to(REPO_ROOT).with_suffix("").parts)
    package = parts[:-1]  # a package's own __init__: the package itself
    unresolved = []
    text = path.read_text(encoding="utf-8") if text is None else text
    written = [(m.group(0), *m.groups()) for m in _REFERENCE.finditer(text)]
    written += [(m.group(0), "obj", m.group(1)) for m in _DOTTED.finditer(text)]
    for reference, role, target in written:
        if target.startswith("."):
            level = len(target) - len(target.lstrip("."))
            if level - 1 > len(package):
                unresolved.append((_name(path), reference))
                continue
            names = package[:len(package) - (level - 1)] + [n for n in target.lstrip(".").split(".") if n]
        elif target.split(".")[0] in PACKAGES:
            names = target.split(".")
        elif target.startswith("curved_reflections."):
            names = target.split(".")[1:]
        else:
            continue  # another library's, or a name Sphinx searches for
        if role == "mod" or _module_file(names) is not None:  # a module, or a name for one
            if _module_file(names) is None:
                unresolved.append((_name(path), reference))
            continue
        for cut in range(len(names) - 1, -1, -1):  # the longest module prefix
            module = _module_file(names[:cut])
            if module is not None:
                break
        if module is None or names[cut] not in _defined_names(module):
            unresolved.append((_name(path), reference))
    return unresolved


def test_every_path_in_the_docs_exists():
    names = _all_file_names()
    missing = [m for path in _doc_files() for m in _missing_paths(path, names)]
    assert missing == [], "paths in the docs that name nothing:\n" + "\n".join(map(str, missing))


def test_every_path_in_the_extensions_docstrings_and_comments_exists():
    names = _all_file_names()
    missing = [m for path in _source_files() for m in _missing_paths(path, names)]
    assert missing == [], "paths in the source that name nothing:\n" + "\n".join(map(str, missing))


def test_every_module_reference_in_the_docstrings_resolves():
    unresolved = [m for path in _source_files() if path.suffix == ".py" for m in _unresolved_references(path)]
    assert unresolved == [], "references that do not resolve:\n" + "\n".join(map(str, unresolved))


def test_the_overview_is_a_design_overview_not_a_notebook():
    assert len((REPO_ROOT / "docs" / "overview.md").read_text(encoding="utf-8").splitlines()) <= 600


def test_the_docs_describe_the_code_not_its_history():
    """No dated entries in the overview, the user guide or the README, and no benchmark
    page with a section about an earlier run (git history keeps those)."""
    dated = re.compile(r"\b20\d\d-\d\d-\d\d\b")
    for name in ("docs/overview.md", "docs/user_guide.md", "README.md"):
        assert not dated.findall((REPO_ROOT / name).read_text(encoding="utf-8")), name
    history = re.compile(r"^#+ .*(run before|since the|earlier run|what changed|\b20\d\d-\d\d-\d\d\b)",
                         re.IGNORECASE | re.MULTILINE)
    pages = sorted((REPO_ROOT / "docs" / "benchmarks").glob("*.md"))
    assert {p.name: history.findall(p.read_text(encoding="utf-8")) for p in pages if
            history.search(p.read_text(encoding="utf-8"))} == {}


def test_the_checks_find_what_they_should():
    """The checks themselves: a stale path, a stale relative reference, a bad link."""
    assert _exists("engine/methods/sbc/sbc.py", [REPO_ROOT]) and not _exists("engine/sbc.py", [REPO_ROOT])
    assert _exists("blender/morph_bake.cache_directory", [REPO_ROOT])
    assert _exists("glsl/morph_blend.glsl", [REPO_ROOT / "drawing" / "methods", REPO_ROOT / "drawing"])
    assert _exists("docs/benchmarks/*.md", [REPO_ROOT]) and not _exists("docs/benchmarks/*.txt", [REPO_ROOT])
    assert [m.group(1) for m in _PATH.finditer("see `engine/band_trace.py`, //frames/a_####.png, "
                                               "/tmp/x.png and https://x.org/a/b.py")] == ["engine/band_trace.py"]
    assert _module_file(["engine", "methods", "sbc"]) is not None and _module_file(["engine", "sbc"]) is None
    sbc = REPO_ROOT / "engine" / "methods" / "sbc" / "sbc.py"
    good = (":mod:`.bsp` :func:`.bsp.ray_cones` :mod:`...projection` :class:`..octree.OctreeGrid` "
            "``engine.methods.sbc.sbc.SampleBasedCamera.project`` ``engine.methods.perturbation``")
    assert _unresolved_references(sbc, good) == []
    bad = ":mod:`..bsp` :func:`.bsp.no_such_name` :mod:`....x` ``engine.sbc.SampleBasedCamera`` :mod:`.sbc.nothing`"
    assert sorted(r for _, r in _unresolved_references(sbc, bad)) == sorted(bad.split(" "))


def _examples() -> list:
    found = []
    for path in _doc_files():
        for k, code in enumerate(_EXAMPLE.findall(path.read_text(encoding="utf-8"))):
            found.append(pytest.param(code, id=f"{_name(path)}-{k}"))
    return found


def _for_the_installed_extension(code: str) -> bool:
    return "bl_ext." in code or "addon_utils" in code


def test_examples_for_the_installed_extension_are_the_user_guides():
    """Those run against the built zip (tests/blender/test_packaging.py), not here."""
    others = [p.id for p in _examples() if _for_the_installed_extension(p.values[0])
              and not p.id.startswith("docs/user_guide.md-")]
    assert others == []
    packaging = (REPO_ROOT / "tests" / "blender" / "test_packaging.py").read_text(encoding="utf-8")
    assert '"docs" / "user_guide.md"' in packaging


#: Runs an example with the repository importable as ``curved_reflections`` and an
#: isolated Blender user folder.
_PRELUDE = f"""
import importlib.util
_spec = importlib.util.spec_from_file_location("_package_link", {str(REPO_ROOT / "scripts" / "package_link.py")!r})
_link = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_link)
_link.isolate_blender_user_folder()
_link.import_as_package({str(REPO_ROOT)!r})
del importlib, _spec, _link
"""


@pytest.mark.parametrize("code", [p for p in _examples() if not _for_the_installed_extension(p.values[0])])
def test_the_docs_python_examples_run_as_written(code, tmp_path):
    script = tmp_path / "example.py"
    script.write_text(_PRELUDE + code, encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    output = done.stdout + done.stderr
    assert done.returncode == 0 and "Traceback" not in output, f"{code}\n{output[-3000:]}"
