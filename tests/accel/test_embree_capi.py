"""The embree backend's C API face (accel/embree.py): compiled calls, native tnear, the cases with
no Embree scene, the library lookup, the Embree objects' lifetime and numba's on-disk cache."""
import gc
import importlib.machinery
import importlib.util
import os
import pickle
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from numba import njit

import accel
from accel import compiled, embree, raygen

REPO = Path(__file__).resolve().parents[2]


def soup_with_spheres(seed=4):
    rng = np.random.default_rng(seed)
    corners = rng.random((300, 1, 3)) + 0.15 * rng.normal(size=(300, 3, 3))
    return accel.Geometry(corners.reshape(-1, 3), np.arange(900).reshape(300, 3),
                          centers=[[0.3, 0.5, 0.5], [0.8, 0.2, 0.6]], radii=[0.2, 0.15])


@njit
def trace(record, origins, directions, tmin, tmax):
    """A small kernel on the compiled face, the way the path tracer calls it."""
    n = origins.shape[0]
    t = np.empty(n)
    prim = np.empty(n, dtype=np.int64)
    u = np.empty(n)
    v = np.empty(n)
    blocked = np.empty(n, dtype=np.bool_)
    scratch = compiled.new_scratch(record)
    for r in range(n):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        t[r], prim[r], u[r], v[r] = compiled.closest_hit(record, scratch, ox, oy, oz, dx, dy, dz,
                                                         tmin[r], tmax[r])
        blocked[r] = compiled.any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin[r], tmax[r])
    return t, prim, u, v, blocked


def test_compiled_face_agrees_with_batch_face_and_naive():
    geometry = soup_with_spheres()
    backend = accel.build("embree", geometry)
    naive = accel.build("naive", geometry)
    for rays in (raygen.sphere_rays(geometry, 3000, seed=1),
                 raygen.surface_rays(geometry, 3000, seed=2)):
        batch = backend.intersect(rays)
        t, prim, u, v, blocked = trace(backend.compiled, rays.origins, rays.directions,
                                       rays.tmin, rays.tmax)
        for ours, theirs in ((t, batch.t), (prim, batch.prim), (u, batch.u), (v, batch.v)):
            np.testing.assert_array_equal(ours, theirs)
        np.testing.assert_array_equal(blocked, backend.occluded(rays))
        np.testing.assert_array_equal(blocked, batch.prim >= 0)
        # Embree's float32 against naive's float64: the same primitive nearly always, t within
        # float32 noise; grazing hits are computed again in float64 (bit for bit like naive's)
        reference = naive.intersect(rays)
        same = (batch.prim == reference.prim) & (batch.prim >= 0)
        assert same.sum() >= 0.999 * (reference.prim >= 0).sum() > 0.3 * len(rays)
        assert (batch.prim >= geometry.triangle_count).any()
        np.testing.assert_allclose(batch.t[same], reference.t[same], rtol=1e-5, atol=1e-6)
        triangle = same & (batch.prim < geometry.triangle_count)
        cosine = np.abs(np.einsum("ij,ij->i", normals(geometry, batch.prim[triangle]),
                                  rays.directions[triangle]))
        cosine /= np.linalg.norm(rays.directions[triangle], axis=1)
        grazing = cosine < 0.9 * embree.GRAZING_COSINE   # clear of the float32 normal
        assert grazing.sum() >= 3
        np.testing.assert_array_equal(batch.t[triangle][grazing], reference.t[triangle][grazing])


def normals(geometry, prims):
    corners = geometry.vertices[geometry.faces[prims]]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_scratch_holds_an_aligned_rayhit():
    backend = accel.build("embree", soup_with_spheres())
    floats, words, k, address = embree.new_scratch(backend.compiled)
    assert address % 16 == 0 and address == floats.ctypes.data + 4 * k
    assert floats.nbytes - 4 * k >= 96          # RTCRayHit: 48-byte ray, 48-byte hit
    assert words.dtype == np.uint32 and words.ctypes.data == floats.ctypes.data


# two stacked triangles: z = 0 (prim 0) and z = -1 (prim 1), rays straight down from z = 1
STACKED = accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, -1], [1, 0, -1], [0, 1, -1]],
                         [[0, 1, 2], [3, 4, 5]])


@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_tnear_is_native_and_inclusive(offset):
    geometry = accel.Geometry(STACKED.vertices + offset, STACKED.faces)
    backend = accel.build("embree", geometry)
    start = np.array([0.25, 0.5, 1.0]) + offset
    tmin = np.array([0.0, 1.5, 2.0, 2.0 + 1e-5, 0.0, 1.0, -1.0])
    tmax = np.array([np.inf, np.inf, np.inf, np.inf, 1.0, 1.0, np.inf])
    origins = np.tile(start, (len(tmin), 1))
    origins[6, 2] = offset - 0.5                  # between the two: prim 0 is behind, at t = -0.5
    rays = accel.Rays(origins, np.tile([0.0, 0.0, -1.0], (len(tmin), 1)), tmin, tmax)
    hits = backend.intersect(rays)
    # past the first triangle; exactly at the second (inclusive); just past both; tmax exactly
    # at the first; tmin == tmax == the first; a negative tmin reaching the one behind
    np.testing.assert_array_equal(hits.prim, [0, 1, 1, -1, 0, 0, 0])
    np.testing.assert_allclose(hits.t, [1.0, 2.0, 2.0, np.inf, 1.0, 1.0, -0.5], rtol=1e-6)
    hit = hits.prim >= 0
    assert (hits.t[hit] >= tmin[hit]).all() and (hits.t[hit] <= tmax[hit]).all()
    np.testing.assert_array_equal(backend.occluded(rays), hits.prim >= 0)
    np.testing.assert_array_equal(hits.prim, accel.build("naive", geometry).intersect(rays).prim)


def test_spheres_only_has_no_scene_and_matches_naive():
    geometry = accel.Geometry(np.zeros((0, 3)), np.zeros((0, 3), dtype=int),
                              centers=[[0, 0, 0], [2.0, 0, 0]], radii=[1.0, 0.5])
    backend = accel.build("embree", geometry)
    assert backend.compiled.scene == 0 and backend.stats()["spheres"] == 2
    rays = raygen.sphere_rays(geometry, 2000, seed=3)
    hits = backend.intersect(rays)
    reference = accel.build("naive", geometry).intersect(rays)
    assert (hits.prim >= 0).mean() > 0.3
    for ours, theirs in ((hits.t, reference.t), (hits.prim, reference.prim)):
        np.testing.assert_array_equal(ours, theirs)
    np.testing.assert_array_equal(backend.occluded(rays), hits.prim >= 0)


def test_empty_geometry_misses():
    backend = accel.build("embree", accel.Geometry(np.zeros((0, 3)), np.zeros((0, 3), dtype=int)))
    assert backend.compiled.scene == 0
    rays = raygen.sphere_rays(STACKED, 100)
    hits = backend.intersect(rays)
    assert (hits.prim == -1).all() and np.isinf(hits.t).all()
    assert not backend.occluded(rays).any()
    empty = accel.Rays(np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(backend.intersect(empty)) == 0
    assert len(accel.build("embree", STACKED).occluded(empty)) == 0


def test_embree_objects_released_with_the_accelerator_and_rebuilt_by_pickle():
    backend = accel.build("embree", STACKED)
    release = backend._finalizer
    assert release.alive
    copy = pickle.loads(pickle.dumps(backend))
    assert copy.compiled.scene != backend.compiled.scene      # a scene of its own
    rays = raygen.sphere_rays(STACKED, 500, seed=6)
    np.testing.assert_array_equal(copy.intersect(rays).prim, backend.intersect(rays).prim)
    del backend
    gc.collect()
    assert not release.alive


def test_missing_library_is_one_clear_line(monkeypatch, tmp_path):
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ImportError, match="embreex is not installed"):
        embree.find_library()
    (tmp_path / "embreex").mkdir()
    spec = importlib.machinery.ModuleSpec("embreex", None, is_package=True)
    spec.submodule_search_locations = [str(tmp_path / "embreex")]
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: spec)
    with pytest.raises(ImportError, match="no libembree4 found in " + re.escape(str(tmp_path))):
        embree.find_library()


CACHE_PROBE = textwrap.dedent("""
    import numpy as np
    import accel
    from accel import compiled, raygen
    geometry = accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]],
                              centers=[[0, 0, 2.0]], radii=[0.5])
    backend = accel.build("embree", geometry)
    rays = raygen.sphere_rays(geometry, 1000, seed=1)
    backend.intersect(rays)
    backend.occluded(rays)
    for kernel in (compiled.intersect_batch, compiled.occluded_batch):
        print(sum(kernel.stats.cache_hits.values()), sum(kernel.stats.cache_misses.values()))
""")


def test_batch_kernels_load_from_numbas_cache_in_a_fresh_process(tmp_path):
    # a cache folder of its own: a process that imports accel without ptrace keys accel's
    # kernels by numba's own stamp, one that imports ptrace by ptrace.jit's, and a save under
    # either stamp drops the other's index entries, so another worker's save between the two
    # runs could evict the first run's kernels
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def run():
        result = subprocess.run([sys.executable, "-c", CACHE_PROBE], cwd=REPO, env=env,
                                capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr
        return [tuple(map(int, line.split())) for line in result.stdout.split("\n") if line]

    run()                                  # compiles and writes the cache if it is cold
    for hits, misses in run():             # a fresh process: everything from the cache
        assert hits > 0 and misses == 0, (hits, misses)
