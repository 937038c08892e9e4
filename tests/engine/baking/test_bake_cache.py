# SPDX-License-Identifier: GPL-3.0-or-later
"""Baking morphing grids in worker processes, and their .npz cache (SBC paper VI)."""

import dataclasses
import os
import threading

import numpy as np
import pytest

from curved_reflections.engine.baking import bake, bake_cache
from curved_reflections.engine import look_at_view
from curved_reflections.engine.methods.morphing import morph_grid as G
from curved_reflections.engine.scene import Reflector
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.methods.sbc.sbc_arrays import sbc_from_arrays, sbc_to_arrays
from curved_reflections.engine.geometry.sphere import icosphere

SETTINGS = G.MorphSettings(grid=(3, 3, 2), margin=0.8, face_resolution=32)
CENTRE = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def sphere():
    return icosphere(CENTRE, 1.0, 3, "Mirror Ball")


@pytest.fixture(scope="module")
def baked(sphere, tmp_path_factory):
    """One 3x3x2 bake on two worker processes, and its folder."""
    folder = tmp_path_factory.mktemp("morphing")
    steps = []
    result = bake.bake_grid(sphere, np.eye(4), SETTINGS, folder, processes=2,
                            progress=lambda done, total: steps.append((done, total)))
    return folder, result, steps


def _points(n=400, seed=0):
    points = np.random.default_rng(seed).uniform([-2.5, -2.5, -1.0], [2.5, 2.5, 3.0], (n, 3))
    return points[np.linalg.norm(points - CENTRE, axis=1) > 1.05]


def test_sbc_arrays_round_trip_projects_identically(sphere):
    view = look_at_view([0.5, -3.0, 1.8], CENTRE, width=96, height=72)
    sbc = build_sample_based_camera([sphere], view, ([-3, -3, -2], [3, 3, 4]), downsample=2)
    arrays = sbc_to_arrays(sbc, "x_")
    assert all(isinstance(v, np.ndarray) and v.dtype != object for v in arrays.values())
    again = sbc_from_arrays(arrays, "x_")
    points = _points()
    # The scene's reflectors stay behind (sbc_arrays.TRANSIENT): a loaded camera interpolates only.
    assert again.true_rays is None
    a, b = sbc.project(points, polish=False), again.project(points)
    assert a.valid.sum() > 50
    assert np.array_equal(a.valid, b.valid) and np.array_equal(np.nan_to_num(a.pixels), np.nan_to_num(b.pixels))
    assert again.stats["n_leaves"] == sbc.stats["n_leaves"]


def test_bake_writes_every_node_and_reports_progress(baked):
    folder, result, steps = baked
    assert not result.cancelled and result.n_built == result.n_nodes == 18
    assert steps == [(k, 18) for k in range(1, 19)]
    assert result.processes == 2 and result.peak_rss_mb > 0 and result.nbytes > 0
    files = sorted(p.name for p in result.directory.iterdir())
    assert "grid.npz" in files and len([f for f in files if f.startswith("node_")]) == 18
    assert not [f for f in files if f.endswith(".tmp")]  # every write finished by its rename


def test_loaded_grid_projects_and_is_pickle_free(sphere, baked):
    folder, result, _ = baked
    grid = bake.load_for(sphere, np.eye(4), SETTINGS, folder)
    view = look_at_view([1.5, -2.0, 2.5], CENTRE, width=160, height=120)
    projection = grid.project(_points(), view)
    assert projection.valid.sum() > 50
    for path in result.directory.iterdir():
        with np.load(path, allow_pickle=False) as data:  # raises on any object array
            assert all(data[k].dtype != object for k in data.files)


def test_processes_give_the_same_grid_as_one_process(sphere, baked, tmp_path, monkeypatch):
    folder, parallel, _ = baked
    serial = bake.bake_grid(sphere, np.eye(4), SETTINGS, tmp_path, processes=1)
    assert serial.key == parallel.key and serial.shape == parallel.shape
    for node in range(18):
        a, b = (bake_cache.read_node_arrays(bake_cache.node_file(result.directory, node))
                for result in (parallel, serial))
        assert set(a) == set(b)
        for k in a:
            if k != "seconds" and "stats" not in k:  # timings differ
                assert np.array_equal(a[k], b[k]), (node, k)


def test_nodes_are_built_and_written_in_worker_processes(sphere, tmp_path, monkeypatch):
    pids, writers = tmp_path / "pids", tmp_path / "writers"
    pids.mkdir()
    writers.mkdir()
    kind = bake_cache.GRID_KINDS["tetrahedral"]
    original, original_write = kind.build, bake_cache.write_node

    def recording(*args):
        (pids / str(os.getpid())).touch()
        return original(*args)

    def recording_write(*args):
        (writers / str(os.getpid())).touch()
        return original_write(*args)

    monkeypatch.setitem(bake_cache.GRID_KINDS, "tetrahedral",  # inherited by the forked workers
                        dataclasses.replace(kind, build=recording))
    monkeypatch.setattr(bake_cache, "write_node", recording_write)
    settings = G.MorphSettings(grid=(2, 2, 2), margin=0.8, face_resolution=16)
    result = bake.bake_grid(sphere, np.eye(4), settings, tmp_path / "cache", processes=2)
    workers = {int(p.name) for p in pids.iterdir()}
    assert workers and os.getpid() not in workers
    # The workers compress and write their own nodes; the parent only reports progress.
    assert {int(p.name) for p in writers.iterdir()} <= workers
    assert len(list(result.directory.glob("node_*"))) == result.n_built == 8


def test_stale_missing_and_corrupt_caches_give_clear_errors(sphere, baked, tmp_path):
    folder, result, _ = baked
    with pytest.raises(bake_cache.CacheError, match="no morphing cache yet") as missing:
        bake.load_for(sphere, np.eye(4), SETTINGS, tmp_path)
    assert missing.value.reason == "missing"
    moved = icosphere(CENTRE, 1.1, 3, "Mirror Ball")  # other geometry, same name
    with pytest.raises(bake_cache.CacheError, match="other geometry or settings") as stale:
        bake.load_for(moved, np.eye(4), SETTINGS, folder)
    assert stale.value.reason == "stale"
    other = G.MorphSettings(grid=(3, 3, 3), margin=0.8, face_resolution=32)
    with pytest.raises(bake_cache.CacheError, match="other geometry or settings"):
        bake.load_for(sphere, np.eye(4), other, folder)
    # A rigid motion keeps the cache: the grid lives in the reflector's frame.
    matrix = np.eye(4)
    matrix[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    matrix[:3, 3] = [2.0, 1.0, 0.0]
    world = Reflector(sphere.name, G.from_frame(matrix, sphere.vertices), sphere.triangles,
                        sphere.normals @ matrix[:3, :3].T)
    assert bake.load_for(world, matrix, SETTINGS, folder).grid.shape == (3, 3, 2)
    assert bake_cache.cache_state(folder, sphere, result.key) == "ready"
    assert bake_cache.cache_state(folder, moved, result.key) == "stale"
    assert bake_cache.cache_state(tmp_path, sphere, result.key) == "missing"


def test_a_reshaped_mirror_gets_a_grid_of_its_own_shape(sphere, tmp_path):
    """Issue 46: the vertices moved (same topology, same transform, same settings). The
    bake builds every node for the new shape in a folder of its own, the loaded grid's
    nodes are that shape's (the same arrays as a bake in an empty folder), a node file of
    the old shape is refused, and a cancelled bake of the new shape leaves the old grid
    for the old shape (undo)."""
    import shutil

    settings = G.MorphSettings(grid=(2, 2, 2), margin=0.8, face_resolution=16)
    axes = np.array([1.0, 0.75, 1.3])
    ellipsoid = Reflector(sphere.name, CENTRE + (sphere.vertices - CENTRE) * axes, sphere.triangles,
                          sphere.normals / axes)
    assert bake_cache.cache_key(ellipsoid, settings) == bake_cache.cache_key(sphere, settings)
    first = bake.bake_grid(sphere, np.eye(4), settings, tmp_path / "cache", processes=1)
    shutil.copytree(tmp_path / "cache", tmp_path / "before")
    cancel = threading.Event()
    cancelled = bake.bake_grid(ellipsoid, np.eye(4), settings, tmp_path / "before", processes=1, cancel=cancel,
                               progress=lambda done, total: cancel.set())
    assert cancelled.cancelled and cancelled.n_skipped == 0 and cancelled.replaced
    assert bake.load_for(sphere, np.eye(4), settings, tmp_path / "before").grid.shape == (2, 2, 2)

    second = bake.bake_grid(ellipsoid, np.eye(4), settings, tmp_path / "cache", processes=1)
    assert second.replaced and second.n_skipped == 0 and second.n_built == second.n_nodes == 8
    assert second.key == first.key and second.shape != first.shape
    assert [p.name for p in (tmp_path / "cache").iterdir()] == [second.directory.name]
    fresh = bake.bake_grid(ellipsoid, np.eye(4), settings, tmp_path / "fresh", processes=1)
    assert not fresh.replaced and fresh.shape == second.shape
    with pytest.raises(bake_cache.CacheError, match="other geometry or settings"):
        bake.load_for(sphere, np.eye(4), settings, tmp_path / "cache")
    loaded = bake.load_for(ellipsoid, np.eye(4), settings, tmp_path / "cache")
    ok = np.flatnonzero(loaded.node_status == G.NODE_OK)
    assert len(ok) >= 4
    for node in ok:
        a, b = (bake_cache.read_node_arrays(bake_cache.node_file(result.directory, node)) for result in (second, fresh))
        assert str(a["key"]) == bake_cache.node_key(second.key, second.shape)
        assert all(np.array_equal(a[k], b[k]) for k in a if k != "seconds" and "stats" not in k), node
        loaded.nodes[node]  # reads
    old_node = bake_cache.grid_directory(tmp_path / "before", sphere.name, first.key, first.shape)
    shutil.copy(bake_cache.node_file(old_node, ok[0]), bake_cache.node_file(second.directory, ok[0]))
    with pytest.raises(bake_cache.CacheError, match="belongs to another grid"):
        bake.load_for(ellipsoid, np.eye(4), settings, tmp_path / "cache").nodes[ok[0]]


def test_a_renamed_mirror_takes_its_grid_along(sphere, baked, tmp_path):
    """A grid baked under a name no object has now, of the same key and shape, is moved to
    the mirror's new name (no bake); not while an object still has the old name, nor for
    another shape."""
    import shutil

    folder, result, _ = baked
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    kettle = Reflector("Kettle", sphere.vertices, sphere.triangles, sphere.normals)
    with pytest.raises(bake_cache.CacheError) as missing:
        bake.load_for(kettle, np.eye(4), SETTINGS, copy)
    assert missing.value.reason == "missing"
    assert bake.adopt_renamed(kettle, np.eye(4), SETTINGS, copy, {"Kettle", sphere.name}) is None  # a copy kept it
    other_shape = Reflector("Kettle", sphere.vertices * 1.1, sphere.triangles, sphere.normals)
    assert bake.adopt_renamed(other_shape, np.eye(4), SETTINGS, copy, {"Kettle"}) is None
    adopted = bake.adopt_renamed(kettle, np.eye(4), SETTINGS, copy, {"Kettle"})
    assert adopted == bake_cache.grid_directory(copy, "Kettle", result.key, result.shape)
    assert [p.name for p in copy.iterdir()] == [adopted.name]
    assert bake.load_for(kettle, np.eye(4), SETTINGS, copy).grid.shape == (3, 3, 2)
    again = bake.bake_grid(kettle, np.eye(4), SETTINGS, copy, processes=1)
    assert again.n_built == 0 and again.n_skipped == 18 and not again.replaced
    assert bake.adopt_renamed(kettle, np.eye(4), SETTINGS, copy, {"Kettle"}) is None  # it has its grid


def test_corrupt_files_raise_cache_errors_not_tracebacks(sphere, baked, tmp_path):
    import shutil

    folder, result, _ = baked
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    directory = bake_cache.grid_directory(copy, sphere.name, result.key, result.shape)
    node = int(np.flatnonzero(bake.load_for(sphere, np.eye(4), SETTINGS, copy).node_status == G.NODE_OK)[0])
    bake_cache.node_file(directory, node).write_bytes(b"not a zip file")
    grid = bake.load_for(sphere, np.eye(4), SETTINGS, copy)
    with pytest.raises(bake_cache.CacheError, match=f"node_{node:05d}.npz is unreadable") as error:
        grid.nodes[node]
    assert error.value.reason == "corrupt"
    # An object array needs pickle: refused, reported as corrupt.
    manifest = dict(np.load(directory / "grid.npz"))
    manifest["key"] = np.array([{"evil": 1}], dtype=object)
    np.savez(directory / "grid.npz", **manifest)
    with pytest.raises(bake_cache.CacheError, match="grid.npz is unreadable"):
        bake.load_for(sphere, np.eye(4), SETTINGS, copy)
    (directory / "grid.npz").write_bytes(b"\x00" * 10)
    with pytest.raises(bake_cache.CacheError, match="unreadable"):
        bake.load_for(sphere, np.eye(4), SETTINGS, copy)


def test_cancel_half_way_keeps_the_previous_cache_and_the_next_bake_resumes(sphere, baked, tmp_path):
    import shutil

    folder, result, _ = baked
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    old_folder = bake_cache.grid_directory(copy, sphere.name, result.key, result.shape)
    before = sorted((p.name, p.stat().st_size) for p in old_folder.iterdir())
    cancel = threading.Event()
    seen = []

    def progress(done, total):
        seen.append(done)
        if done >= total // 2:
            cancel.set()

    # Other settings: a finished bake would replace (and remove) the old grid.
    other = G.MorphSettings(grid=(3, 3, 3), margin=0.8, face_resolution=32)
    outcome = bake.bake_grid(sphere, np.eye(4), other, copy, processes=2, progress=progress, cancel=cancel)
    assert outcome.cancelled and outcome.directory is None and outcome.n_built < outcome.n_nodes
    assert max(seen) < 27
    after = sorted((p.name, p.stat().st_size) for p in old_folder.iterdir())
    assert after == before
    assert bake.load_for(sphere, np.eye(4), SETTINGS, copy).grid.shape == (3, 3, 2)
    with pytest.raises(bake_cache.CacheError, match=r"has \d+ of 27 nodes") as error:
        bake.load_for(sphere, np.eye(4), other, copy)
    assert error.value.reason == "incomplete"
    # The next bake builds only the nodes still missing, then retires the old grid.
    built = bake_cache.baked_nodes(bake_cache.grid_directory(copy, sphere.name, outcome.key, outcome.shape), 27)[0].sum()
    assert built >= outcome.n_built
    finished = bake.bake_grid(sphere, np.eye(4), other, copy, processes=2)
    assert finished.n_skipped == built and finished.n_built == 27 - built and finished.directory is not None
    assert [p.name for p in copy.iterdir()] == [finished.directory.name]
    assert bake.load_for(sphere, np.eye(4), other, copy).grid.shape == (3, 3, 3)


def test_damaged_or_foreign_node_files_are_refused_and_baked_again(sphere, baked, tmp_path):
    import shutil

    folder, result, _ = baked
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    directory = bake_cache.grid_directory(copy, sphere.name, result.key, result.shape)
    ok = np.flatnonzero(bake.load_for(sphere, np.eye(4), SETTINGS, copy).node_status == G.NODE_OK)
    damaged, foreign = int(ok[0]), int(ok[1])
    path = bake_cache.node_file(directory, damaged)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])  # truncated
    other = dict(np.load(bake_cache.node_file(directory, foreign)))
    other["key"] = np.array("0" * 64)
    np.savez_compressed(bake_cache.node_file(directory, foreign), **other)
    grid = bake.load_for(sphere, np.eye(4), SETTINGS, copy)
    with pytest.raises(bake_cache.CacheError, match=f"node_{damaged:05d}.npz is unreadable") as error:
        grid.nodes[damaged]
    assert "Bake Morphing Grid builds the node again" in str(error.value)
    with pytest.raises(bake_cache.CacheError, match=f"node_{foreign:05d}.npz belongs to another grid"):
        grid.nodes[foreign]
    assert sorted(p.name for p in directory.glob("*.damaged")) == [f"node_{n:05d}.npz.damaged"
                                                                  for n in sorted((damaged, foreign))]
    with pytest.raises(bake_cache.CacheError) as incomplete:
        bake.load_for(sphere, np.eye(4), SETTINGS, copy)
    assert incomplete.value.reason == "incomplete"
    repaired = bake.bake_grid(sphere, np.eye(4), SETTINGS, copy, processes=1)
    assert repaired.n_built == 2 and repaired.n_skipped == 16 and repaired.directory == directory
    repaired_grid = bake.load_for(sphere, np.eye(4), SETTINGS, copy)
    assert repaired_grid.nodes[damaged].status == G.NODE_OK and repaired_grid.nodes[foreign].status == G.NODE_OK


_RANGE_BAKE = """
import sys
import numpy as np
sys.path.insert(0, {scripts!r})
import package_link
package_link.import_as_package({root!r})
from curved_reflections.engine.baking import bake
from curved_reflections.engine.methods.morphing import morph_grid as G
from curved_reflections.engine.geometry.sphere import icosphere
settings = G.MorphSettings(grid=(3, 3, 2), margin=0.8, face_resolution=32)
sphere = icosphere(np.array([0.0, 0.0, 1.0]), 1.0, 3, "Mirror Ball")
nodes = bake.parse_node_range(sys.argv[2], 18)
result = bake.bake_grid(sphere, np.eye(4), settings, sys.argv[1], processes=1, nodes=nodes)
print("built", result.n_built, "complete", result.directory is not None)
"""


def test_two_processes_baking_ranges_side_by_side_give_the_single_process_grid(baked, tmp_path, repo_root):
    """What a render farm does: two processes, started together, each bake a range of one
    grid's nodes into the same folder; the grid is whole and equals the one-process bake."""
    import subprocess
    import sys

    folder, result, _ = baked
    script = tmp_path / "range_bake.py"
    script.write_text(_RANGE_BAKE.format(scripts=str(repo_root / "scripts"), root=str(repo_root)))
    shared = tmp_path / "shared"
    runs = [subprocess.Popen([sys.executable, str(script), str(shared), nodes], stdout=subprocess.PIPE, text=True)
            for nodes in ("0-8", "9-")]
    outputs = [run.communicate(timeout=300)[0] for run in runs]
    assert all(run.returncode == 0 for run in runs), outputs
    assert sorted(int(o.split()[1]) for o in outputs) == [9, 9]
    directory = bake_cache.grid_directory(shared, "Mirror Ball", result.key, result.shape)
    assert bake_cache.baked_nodes(directory, 18)[0].all()
    for node in range(18):
        ours, theirs = bake_cache.node_file(directory, node), bake_cache.node_file(result.directory, node)
        assert ours.is_file() == theirs.is_file()
        if ours.is_file():
            a, b = bake_cache.read_node_arrays(ours), bake_cache.read_node_arrays(theirs)
            assert set(a) == set(b)
            for k in a:
                if k != "seconds" and "stats" not in k:
                    assert np.array_equal(a[k], b[k]), (node, k)
    again = subprocess.run([sys.executable, str(script), str(shared), "0-17"], capture_output=True, text=True,
                           timeout=300)
    assert again.stdout.split()[:4] == ["built", "0", "complete", "True"]  # a finished range is not redone


def test_node_ranges_parse_or_say_what_is_wrong():
    assert bake.parse_node_range("", 18) == range(18)
    assert bake.parse_node_range("3-7", 18) == range(3, 8)
    assert bake.parse_node_range("9-", 18) == range(9, 18)
    assert bake.parse_node_range(" 4 ", 18) == range(4, 5)
    for text, problem in (("7-3", "nodes 0 to 17"), ("0-18", "nodes 0 to 17"), ("a-b", "write first-last")):
        with pytest.raises(ValueError, match=problem):
            bake.parse_node_range(text, 18)


def test_clear_removes_only_that_reflectors_grids(sphere, baked, tmp_path):
    import shutil

    folder, _, _ = baked
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    (copy / "Other-0123456789abcdef").mkdir()
    assert bake_cache.clear_cache(copy, sphere.name) == 1
    assert [p.name for p in copy.iterdir()] == ["Other-0123456789abcdef"]
    with pytest.raises(bake_cache.CacheError, match="no morphing cache yet"):
        bake.load_for(sphere, np.eye(4), SETTINGS, copy)
