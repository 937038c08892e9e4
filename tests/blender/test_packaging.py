# SPDX-License-Identifier: GPL-3.0-or-later
"""The extension zip, built and checked by Blender's own CLI, holds the product alone (no
development helper, no module the extension never imports), installs, works and uninstalls.

Installing runs in a separate Python (install_probe.py) with its own Blender user
folder, so the installed add-on (``bl_ext.user_default.curved_reflections``) never
meets the in-process registration of the other tests: both register the same classes.
"""

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import bpy
import pytest

from curved_reflections.tools.import_graph import module_names, reachable, relative_imports

SCRIPTS = Path(bpy.utils.system_resource('SCRIPTS'))
BLENDER_EXT = SCRIPTS / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
VALID_TAGS = SCRIPTS / "modules" / "_bpy_internal" / "extensions" / "tags.py"

#: What the zip may hold at its top level: the extension and nothing of its development.
SHIPPED = {"blender_manifest.toml", "__init__.py", "LICENSE", "engine", "blender", "drawing"}
#: The repository's development folders, none of which may ship.
DEVELOPMENT = {"tools", "tests", "scripts", "docs"}


def blender_ext(*args):
    """Run Blender's extension CLI (what ``blender --command extension`` runs)."""
    done = subprocess.run(
        [sys.executable, str(BLENDER_EXT), *map(str, args)],
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory, repo_root):
    dist = tmp_path_factory.mktemp("dist")
    blender_ext("build", "--source-dir", repo_root, "--output-dir", dist, "--valid-tags", VALID_TAGS)
    zips = list(dist.glob("*.zip"))
    assert [z.name for z in zips] == ["curved_reflections-0.1.0.zip"]
    return zips[0]


def test_manifest_validates(repo_root):
    assert "Success" in blender_ext("validate", "--valid-tags", VALID_TAGS, repo_root)


def test_zip_validates(extension_zip):
    assert "Success" in blender_ext("validate", "--valid-tags", VALID_TAGS, extension_zip)


def test_zip_holds_only_the_extension(extension_zip):
    names = zipfile.ZipFile(extension_zip).namelist()
    assert {"blender_manifest.toml", "__init__.py", "engine/__init__.py", "engine/scene.py",
            "blender/__init__.py", "blender/capture.py"} <= set(names)
    helpers = [n for n in names if n.split("/")[0] in DEVELOPMENT
               or Path(n).name == "conftest.py" or Path(n).name.startswith("test_")]
    assert helpers == [], "development or test helpers in the zip"
    top_level = {name.split("/")[0] for name in names}
    assert top_level <= SHIPPED, top_level - SHIPPED
    assert not [n for n in names if "__pycache__" in n or n.endswith((".pyc", ".blend1"))]


def test_zip_ships_only_modules_the_extension_imports(extension_zip):
    """Every Python module in the zip is one the extension can run: reached from the root
    ``__init__.py`` (whose ``register()`` imports the operators) through relative imports,
    wherever in a module they stand, read with ``ast`` from the zip itself. A module nothing
    reaches is a development helper that belongs in ``tools/`` (or dead code); an import
    naming a module the zip lacks would fail installed."""
    with zipfile.ZipFile(extension_zip) as archive:
        sources = {n: archive.read(n).decode("utf-8") for n in archive.namelist() if n.endswith(".py")}
    modules = module_names(sources)
    assert "" in modules and "blender" in modules
    graph, unresolved = {}, {}
    for name, path in modules.items():
        graph[name], missing = relative_imports(name, sources[path], path.endswith("__init__.py"), modules)
        if missing:
            unresolved[path] = missing
    assert unresolved == {}, "imports of modules the zip lacks"
    never_imported = sorted(modules[name] for name in set(modules) - reachable(graph, ""))
    assert never_imported == [], "shipped modules the extension never imports"


def test_installs_enables_works_and_disables(extension_zip, tmp_path):
    result_path = tmp_path / "result.json"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    done = subprocess.run(
        [sys.executable, str(Path(__file__).with_name("install_probe.py")), str(extension_zip), str(result_path)],
        capture_output=True, text=True, timeout=300, env=env,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads(result_path.read_text())

    assert result["install"] == ["FINISHED"]
    assert all(result["enabled"].values()), result["enabled"]
    zip_files = {n for n in zipfile.ZipFile(extension_zip).namelist() if not n.endswith("/")}
    assert set(result["installed_files"]) == zip_files
    assert result["poll"] is True
    assert result["check_scene"] == ["FINISHED"]
    assert not any(result["disabled"].values()), result["disabled"]


def test_a_farm_bakes_node_ranges_side_by_side_into_one_cache(extension_zip, tmp_path):
    """The user guide's farm task (``bpy`` module form): two processes started together
    each bake half the nodes of one grid into the scene's shared cache folder; the grid
    is whole and equals the one a single process bakes, file by file."""
    import numpy as np

    from curved_reflections.engine.baking import bake_cache

    probe = str(Path(__file__).with_name("farm_probe.py"))
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    blend, shared, single = tmp_path / "scene.blend", tmp_path / "shared", tmp_path / "single"

    def run(*args):
        return subprocess.Popen([sys.executable, probe, *map(str, args)], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)

    installing = run("install", extension_zip, blend, shared, 2, 8.0)  # 8 nodes, 8 ball sizes out: quick
    assert installing.wait(timeout=120) == 0, installing.stdout.read()
    halves = [run("bake", blend, nodes) for nodes in ("0-3", "4-")]
    outputs = [half.communicate(timeout=600)[0] for half in halves]
    assert all(half.returncode == 0 for half in halves), outputs
    assert all("RESULT ['FINISHED']" in out and "Ball: baked 4 nodes" in out for out in outputs), outputs
    alone = run("bake", blend, "", single)
    assert alone.wait(timeout=600) == 0, alone.stdout.read()

    (ours,), (theirs,) = list(shared.glob("scene/Ball-*")), list(single.glob("scene/Ball-*"))
    assert ours.name == theirs.name
    names = sorted(p.name for p in ours.iterdir())
    assert names == sorted(p.name for p in theirs.iterdir()) and len(names) == 9  # manifest and 8 nodes
    for name in names:
        if name.startswith("node_"):
            a, b = bake_cache.read_node_arrays(ours / name), bake_cache.read_node_arrays(theirs / name)
        else:
            a, b = (dict(np.load(folder / name)) for folder in (ours, theirs))
        assert set(a) == set(b)
        for k in a:
            if k != "seconds" and "stats" not in k:  # timings differ
                assert np.array_equal(a[k], b[k]), (name, k)


def _python_examples(guide: Path) -> list:
    """The ```python blocks of a markdown file, in order."""
    import re

    return re.findall(r"^```python\n(.*?)^```", guide.read_text(encoding="utf-8"), flags=re.MULTILINE | re.DOTALL)


def test_the_user_guides_python_examples_run_as_written(extension_zip, tmp_path, repo_root):
    """Every Python example of docs/user_guide.md, run as written in a fresh Python with the
    zip installed, in a folder holding the files they open: kettle.blend (a mirror ball in
    Auto mode, two frames) and scene.blend (a ball in Morphing mode, a 25 x 2 x 2 grid, so
    that its nodes 0-99 exist; reaching 40 ball sizes beyond it, so that the ball is small
    in the nodes' cube faces and the 100 nodes bake in under 2 s)."""
    probe = str(Path(__file__).with_name("farm_probe.py"))
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    for args in (["install", extension_zip, tmp_path / "scene.blend", tmp_path / "cache", "25", "40"],
                 ["kettle", tmp_path / "kettle.blend"]):
        done = subprocess.run([sys.executable, probe, *map(str, args)], env=env, capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    # The examples run side by side (each a fresh Python that mostly starts Blender and
    # opens a file; none writes what another reads): about half the time on two cores.
    examples = _python_examples(repo_root / "docs" / "user_guide.md")
    assert len(examples) >= 4
    running = []
    for k, example in enumerate(examples):
        script = tmp_path / f"example_{k}.py"
        script.write_text(example, encoding="utf-8")
        running.append(subprocess.Popen([sys.executable, str(script)], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True))
    for k, (example, done) in enumerate(zip(examples, running)):
        stdout, stderr = done.communicate(timeout=600)
        output = stdout + stderr
        assert done.returncode == 0 and "Traceback" not in output, f"example {k}:\n{example}\n{output[-3000:]}"
        if "bake_morphing" in example:
            assert "Ball: baked 100 nodes" in output, output[-3000:]
    assert (Path("/tmp") / "kettle_reflections.png").is_file()
    assert sorted(p.name for p in (Path("/tmp") / "kettle").glob("frame_*.png"))[:2] == ["frame_0001.png",
                                                                                        "frame_0002.png"]
