"""Structural invariants of the BVH, on course meshes and on inputs that defeat the mean split."""
import numpy as np
import pytest

import accel
import ptrace
from accel import raygen
from accel.bvh import MEAN_SPLIT_DEPTH, STACK_SIZE, WIDTH, _wide_rows


def ranges(starts, counts):
    """The ranges [start, start + count) laid end to end, and which range each index came from."""
    counts = np.asarray(counts, dtype=np.int64)
    which = np.repeat(np.arange(len(counts)), counts)
    offsets = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(np.asarray(starts, dtype=np.int64), counts) + offsets, which


def depths(parent, limit):
    """Each node's depth below the root (parent -1) from its parent's index, in at most `limit`
    rounds; fails on a cycle or a chain deeper than that."""
    depth = np.zeros(len(parent), dtype=int)
    for _ in range(limit + 1):
        deeper = np.where(parent >= 0, depth[np.maximum(parent, 0)] + 1, 0)
        if (deeper == depth).all():
            return depth
        depth = deeper
    pytest.fail(f"a chain of parents deeper than {limit} (or a cycle)")


def check_invariants(bvh):
    geometry = bvh.geometry
    n = geometry.primitive_count
    nodes = bvh.lower.shape[0]
    assert nodes <= max(2 * n - 1, 0)
    prim_lower, prim_upper = geometry.primitive_bounds()
    child, count = bvh.child_or_first, bvh.count
    assert (bvh.lower <= bvh.upper).all()
    leaf = np.flatnonzero(count > 0)
    assert (count[leaf] <= bvh.max_leaf_size).all()
    index, which = ranges(child[leaf], count[leaf])
    prims, owner = bvh.order[index], leaf[which]
    np.testing.assert_array_equal(np.bincount(prims, minlength=n), 1)  # each in exactly one leaf
    assert (bvh.lower[owner] <= prim_lower[prims]).all()
    assert (prim_upper[prims] <= bvh.upper[owner]).all()
    inner = np.flatnonzero(count <= 0)
    left = child[inner]
    assert (inner < left).all() and (left + 1 < nodes).all()   # children after their parent
    parent = np.full(nodes, -1)
    for kid in (left, left + 1):
        assert (bvh.lower[inner] <= bvh.lower[kid]).all()
        assert (bvh.upper[kid] <= bvh.upper[inner]).all()
        parent[kid] = inner
    depth = depths(parent, STACK_SIZE)
    assert depth.max(initial=0) == bvh.max_depth
    assert bvh.max_depth < STACK_SIZE - 1
    stats = bvh.stats()
    assert stats["nodes"] == nodes and stats["leaves"] == int((bvh.count > 0).sum())
    assert stats["bytes"] > 0 or n == 0
    check_wide_invariants(bvh)


def check_wide_invariants(bvh):
    """The 8-wide tree the traversal walks: from row 0 it reaches every wide row once and every
    binary leaf once (the same primitives, triangles stored lane by lane with the mesh's own
    coordinates, NaN in unused lanes, spheres after them), each slot's float32 box is its
    binary node's box rounded outward by less than a float32 ulp, each interior slot's box
    holds its row's boxes, and unused slots are empty boxes after the used ones; and which
    binary nodes became rows is the least-cost choice (check_least_cost)."""
    lower, upper, payloads = bvh.wide_tree()
    rows = lower.shape[0]
    assert bvh.stats()["wide_nodes"] == rows
    if bvh.lower.shape[0] == 0:
        assert rows == 0
        return
    geometry, blocks, prims = bvh.geometry, bvh._blocks, bvh._prims
    used = np.isfinite(lower[:, 0])                            # (rows, WIDTH)
    n_used = used.sum(axis=1)
    assert (n_used >= 1).all()
    np.testing.assert_array_equal(used, np.arange(WIDTH) < n_used[:, None])   # used ones first
    assert (np.where(used[:, None], True, lower == np.inf)).all()
    assert (np.where(used[:, None], True, upper == -np.inf)).all()
    payloads = payloads.astype(np.int64)
    # interior slots: every row but row 0 is the child of exactly one slot, row 0 of none, and
    # the chain of parents ends at row 0 (so the walk from row 0 reaches each row once)
    row, slot = np.nonzero(used & (payloads >> 32 == 0))
    kids = payloads[row, slot]
    references = np.bincount(kids, minlength=rows)
    assert references[0] == 0 and (references[1:] == 1).all()
    parent = np.full(rows, -1)
    parent[kids] = row
    assert depths(parent, bvh.max_depth).max() <= bvh.max_depth
    kid_lower = np.where(used[kids][:, None], lower[kids], np.inf).min(axis=2)
    kid_upper = np.where(used[kids][:, None], upper[kids], -np.inf).max(axis=2)
    assert (lower[row, :, slot] <= kid_lower).all() and (kid_upper <= upper[row, :, slot]).all()
    # leaf slots: payload = first block | triangles << 32 | spheres << 48
    row, slot = np.nonzero(used & (payloads >> 32 != 0))
    payload = payloads[row, slot]
    first, n_tri, n_sph = payload & 0xffffffff, (payload >> 32) & 0xffff, payload >> 48
    tri_blocks = -(-n_tri // 4)
    lane_index, lane_slot = ranges(4 * first, n_tri)
    lanes = prims[lane_index]
    assert (lanes < geometry.triangle_count).all()
    assert (prims[ranges(4 * first + n_tri, 4 * tri_blocks - n_tri)[0]] == -1).all()
    sphere_index, sphere_slot = ranges(4 * (first + tri_blocks), n_sph)
    spheres = prims[sphere_index]
    assert (spheres >= geometry.triangle_count).all()
    # each slot holds exactly one binary leaf's primitives, and each binary leaf is one slot's
    leaf = np.flatnonzero(bvh.count > 0)
    index, which = ranges(bvh.child_or_first[leaf], bvh.count[leaf])
    leaf_of = np.full(geometry.primitive_count, -1)
    leaf_of[bvh.order[index]] = leaf[which]
    slot_prims = np.concatenate([lanes, spheres])
    of_slot = np.concatenate([lane_slot, sphere_slot])
    binary = np.full(len(payload), -1)
    binary[of_slot] = leaf_of[slot_prims]
    np.testing.assert_array_equal(leaf_of[slot_prims], binary[of_slot])
    np.testing.assert_array_equal(np.bincount(slot_prims, minlength=geometry.primitive_count), 1)
    np.testing.assert_array_equal(n_tri + n_sph, bvh.count[binary])
    np.testing.assert_array_equal(np.sort(binary), leaf)
    # triangle j of a slot is lane j % 4 of its block first + j // 4; the lanes past the last
    # triangle of a slot's last block are NaN
    lane_block = blocks.reshape(-1, 3, 3, 4)
    j = lane_index - 4 * first[lane_slot]
    coordinates = lane_block[first[lane_slot] + j // 4, :, :, j % 4]
    np.testing.assert_array_equal(coordinates, geometry.vertices[geometry.faces[lanes]])
    pad, pad_slot = ranges(4 * first + n_tri, 4 * tri_blocks - n_tri)
    assert np.isnan(lane_block[pad // 4, :, :, pad % 4]).all()
    # float32 planes: outward, by less than an ulp
    low, high = lower[row, :, slot], upper[row, :, slot]
    assert (low <= bvh.lower[binary]).all() and (bvh.upper[binary] <= high).all()
    assert (np.nextafter(low.astype(np.float32), np.float32(np.inf)) > bvh.lower[binary]).all()
    assert (np.nextafter(high.astype(np.float32), -np.float32(np.inf)) < bvh.upper[binary]).all()
    check_least_cost(bvh)


def half_area(lower, upper):
    e = upper - lower
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def least_wide_cost(bvh):
    """The least sum of half areas of the wide nodes over every way of folding the binary tree
    into WIDTH-wide nodes (the leaves kept), by a recursion of its own: best[b][k] is the least
    cost of a frontier of exactly k nodes of b's subtree (a leaf in it costs nothing, an interior
    node the cost of a wide node of its own: its half area plus its best frontier of 2.. WIDTH
    nodes)."""
    child, count = bvh.child_or_first, bvh.count
    area = half_area(bvh.lower, bvh.upper)
    best = [None] * len(count)
    for b in range(len(count) - 1, -1, -1):   # children after their parent
        if count[b] > 0:
            best[b] = {1: 0.0}
            continue
        left, right = best[child[b]], best[child[b] + 1]
        frontier = {}
        for i, a in left.items():
            for j, c in right.items():
                if i + j <= WIDTH:
                    frontier[i + j] = min(frontier.get(i + j, np.inf), a + c)
        best[b] = dict(frontier)
        best[b][1] = area[b] + min(frontier.values())
    return best[0][1] if count[0] == 0 else 0.0


def check_least_cost(bvh):
    """The rows' cost (each row's box, the union of its slots' binary boxes, is the box of the
    binary node it came from) is the least any folding of this binary tree can have."""
    if bvh.lower.shape[0] == 0:
        return
    rows = _wide_rows(bvh.lower, bvh.upper, bvh.child_or_first, bvh.count)
    lower = rows[:, :3 * WIDTH].reshape(-1, 3, WIDTH).min(axis=2)
    upper = rows[:, 3 * WIDTH:6 * WIDTH].reshape(-1, 3, WIDTH).max(axis=2)
    cost = half_area(lower, upper).sum() if bvh.count[0] == 0 else 0.0
    least = least_wide_cost(bvh)
    assert cost == pytest.approx(least, rel=1e-12, abs=0.0)
    return cost


def greedy_wide_cost(bvh):
    """The cost of the earlier collapse: each wide node takes its binary node's two children,
    then opens the interior child of largest half area until it has WIDTH."""
    child, count = bvh.child_or_first, bvh.count
    area = half_area(bvh.lower, bvh.upper)
    cost, todo = 0.0, [0] if count[0] == 0 else []
    while todo:
        b = todo.pop()
        cost += area[b]
        kids = [child[b], child[b] + 1]
        while len(kids) < WIDTH:
            interior = [k for k in kids if count[k] == 0]
            if not interior:
                break
            widest = max(interior, key=lambda k: area[k])
            kids.remove(widest)
            kids += [child[widest], child[widest] + 1]
        todo += [k for k in kids if count[k] == 0]
    return cost


@pytest.mark.parametrize("split", ["mean", "sah"])
def test_collapse_is_the_least_cost_folding(scenes_dir, split):
    """On random triangle soups (deep trees with one triangle per leaf) and a course mesh, the
    collapse reaches the least cost of least_wide_cost, never more than the greedy collapse it
    replaced, and less than it somewhere."""
    rng = np.random.default_rng(11)
    for n in (1, 2, 9, 40, 300):
        vertices = rng.normal(size=(3 * n, 3)) * rng.uniform(0.01, 1.0, size=(3 * n, 1))
        geometry = accel.Geometry(vertices, np.arange(3 * n).reshape(n, 3))
        for leaf_size in (1, 4):
            bvh = accel.build("bvh", geometry, max_leaf_size=leaf_size, split=split)
            cost = check_least_cost(bvh)
            assert cost <= greedy_wide_cost(bvh) * (1 + 1e-12)
    bvh = accel.build("bvh", ptrace.load(scenes_dir / "meshedit/cow.dae").geometry, split=split)
    cost = check_least_cost(bvh)
    assert cost < greedy_wide_cost(bvh)


@pytest.mark.parametrize("split", ["mean", "sah"])
@pytest.mark.parametrize("relpath", ["meshedit/cow.dae", "sky/CBspheres.dae",
                                     "meshedit/maxplanck.dae"])
def test_invariants_on_course_meshes(scenes_dir, relpath, split):
    geometry = ptrace.load(scenes_dir / relpath).geometry
    for leaf_size in (1, 4, 8):
        check_invariants(accel.build("bvh", geometry, max_leaf_size=leaf_size, split=split))


@pytest.mark.parametrize("relpath", ["meshedit/cow.dae", "sky/CBspheres.dae", "sky/CBbunny.dae"])
def test_sah_split_answers_exactly_like_naive(scenes_dir, relpath):
    geometry = ptrace.load(scenes_dir / relpath).geometry
    rays = raygen.sphere_rays(geometry, 5000, seed=4)
    reference = accel.build("naive", geometry).intersect(rays)
    hits = accel.build("bvh", geometry, split="sah").intersect(rays)
    np.testing.assert_array_equal(hits.prim, reference.prim)
    np.testing.assert_array_equal(hits.t, reference.t)


def geometric_series_geometry(count=1000):
    """Triangles in the planes x = 2^-k: each mean split peels only a few off the top."""
    x = 2.0 ** -np.arange(count)
    base = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    points = base[None, :, :] + np.stack([x, np.zeros(count), np.zeros(count)], 1)[:, None, :]
    return accel.Geometry(points.reshape(-1, 3), np.arange(3 * count).reshape(count, 3))


def test_depth_stays_bounded_when_mean_splits_peel_a_few_at_a_time():
    geometry = geometric_series_geometry()
    check_invariants(accel.build("bvh", geometry, split="sah"))
    bvh = accel.build("bvh", geometry)
    check_invariants(bvh)
    assert bvh.max_depth >= MEAN_SPLIT_DEPTH   # the mean split really did go deep here...
    assert bvh.max_depth <= MEAN_SPLIT_DEPTH + 10   # ...and the count split then bounded it
    rays = raygen.sphere_rays(geometry, 2000)
    reference = accel.build("naive", geometry).intersect(rays)
    np.testing.assert_array_equal(bvh.intersect(rays).prim, reference.prim)


@pytest.mark.parametrize("split", ["mean", "sah"])
def test_invariants_with_coincident_centroids(split):
    one = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    geometry = accel.Geometry(np.tile(one, (1000, 1)), np.arange(3000).reshape(1000, 3))
    bvh = accel.build("bvh", geometry, split=split)
    check_invariants(bvh)
    assert bvh.stats()["largest_leaf"] <= bvh.max_leaf_size
    assert bvh.max_depth <= 10   # count splits halve: at most ceil(log2(1000 / 4)) + 1


def test_bad_options_are_refused():
    with pytest.raises(ValueError):
        accel.build("bvh", geometric_series_geometry(4), max_leaf_size=0)
    with pytest.raises(ValueError):
        accel.build("bvh", geometric_series_geometry(4), split="median-of-nothing")


def test_axis_aligned_rays_on_box_planes_match_naive():
    """The slab test orders planes by the direction's sign and maps a zero component to an
    infinite inverse (a plane difference of 0 then gives NaN, which culls nothing): rays along
    the axes (two zero components) whose origin lies exactly on node box planes in those two
    components, with tmin > 0, must give naive's answers bit for bit, closest hit and any
    hit."""
    rng = np.random.default_rng(11)
    # 400 axis-aligned unit squares (two triangles each) at integer coordinates
    corners = rng.integers(0, 8, size=(400, 3)).astype(np.float64)
    axis = rng.integers(0, 3, size=400)
    u, v = (axis + 1) % 3, (axis + 2) % 3
    quad = np.zeros((400, 4, 3))
    quad[:] = corners[:, None, :]
    rows = np.arange(400)
    quad[rows, 1, u] += 1
    quad[rows, 2, u] += 1
    quad[rows, 2, v] += 1
    quad[rows, 3, v] += 1
    vertices = quad.reshape(-1, 3)
    base = 4 * rows[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    geometry = accel.Geometry(vertices, faces)
    naive = accel.build("naive", geometry)
    n = 4000
    for split in ("mean", "sah"):
        bvh = accel.build("bvh", geometry, split=split)
        planes = np.concatenate([bvh.lower, bvh.upper])          # (2 * nodes, 3)
        starts = planes[rng.integers(0, len(planes), n)]          # on a box plane, per axis
        along = rng.integers(0, 3, n)
        starts[np.arange(n), along] = rng.uniform(-1.0, 9.0, n)
        directions = np.zeros((n, 3))
        directions[np.arange(n), along] = rng.choice([-1.0, 1.0], n)
        rays = accel.Rays(starts, directions, 1e-3, rng.choice([np.inf, 3.0], n))
        expected = naive.intersect(rays)
        assert 0.05 < (expected.prim >= 0).mean() < 0.95
        hits = bvh.intersect(rays)
        np.testing.assert_array_equal(hits.prim, expected.prim)
        np.testing.assert_array_equal(hits.t, expected.t)
        np.testing.assert_array_equal(bvh.occluded(rays), naive.occluded(rays))


def test_directions_float32_cannot_invert_match_naive(scenes_dir):
    """Direction components whose inverse is beyond the float32 slab test's range (tiny or huge,
    some axes or all three, which then test every primitive), with tmin 0 and 1e-3: bvh answers
    as naive does, bit for bit, closest hit and any hit."""
    geometry = ptrace.load(scenes_dir / "meshedit/cow.dae").geometry
    base = raygen.sphere_rays(geometry, 600, seed=9)
    naive, bvh = accel.build("naive", geometry), accel.build("bvh", geometry)
    scales = np.ones((6, 600, 3))
    scales[0] = 1e-40                    # every axis: no box can cull
    scales[1] = 1e39
    scales[2, :, 0] = 1e-40              # one axis
    scales[3, :, 1] = 1e39
    scales[4, :, :2] = 1e-35             # two axes
    scales[5] = [1e-33, 1.0, 1e33]
    hit = []
    for scale in scales:
        for tmin in (0.0, 1e-3):
            rays = accel.Rays(base.origins, base.directions * scale, tmin)
            expected = naive.intersect(rays)
            hits = bvh.intersect(rays)
            np.testing.assert_array_equal(hits.prim, expected.prim)
            np.testing.assert_array_equal(hits.t, expected.t)
            np.testing.assert_array_equal(bvh.occluded(rays), naive.occluded(rays))
            hit.append((expected.prim >= 0).mean())
    assert min(hit[:3]) > 0.2   # every axis scaled alike (t in range): hitting as often


@pytest.mark.parametrize("split", ["mean", "sah"])
def test_traversal_stops_at_the_nearest_hit(split):
    """A hit shrinks the ray's interval: boxes that start beyond the nearest hit found are never
    opened. Rays straight down hit a near pair of triangles at z = 0 above 200 triangles at
    z = -10 that they would also hit: only the near pair's leaf is tested (at most a leaf's worth
    of triangle tests per ray), and the far cluster is as if absent."""
    rng = np.random.default_rng(3)
    near = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    far = rng.random((600, 3)) * [2, 2, 0.5] + [-1, -1, -10.25]
    vertices = np.vstack([near, far])
    faces = np.vstack([[[0, 1, 2], [0, 2, 3]], 4 + np.arange(600).reshape(200, 3)])
    n = 2000
    origins = np.column_stack([rng.random((n, 2)) * 1.6 - 0.8, np.full(n, 5.0)])
    directions = np.tile([0.0, 0.0, -1.0], (n, 1))
    backend = accel.build("bvh", accel.Geometry(vertices, faces), split=split)
    rays = accel.Rays(origins, directions)
    hits = backend.intersect(rays)
    assert np.isin(hits.prim, [0, 1]).all()
    visits, tests = backend.traversal_work(rays)
    print(f"{split}: {tests:.2f} triangle tests and {visits:.2f} nodes per ray")
    assert tests <= backend.max_leaf_size


def _random_scene(seed, triangles, spheres, exact):
    """Random triangles (float32-exact coordinates or not) and spheres."""
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(-1.0, 1.0, (3 * triangles, 3))
    if exact:
        vertices = vertices.astype(np.float32).astype(np.float64)
    return accel.Geometry(vertices, np.arange(3 * triangles).reshape(triangles, 3),
                          rng.uniform(-1.0, 1.0, (spheres, 3)), rng.uniform(0.01, 0.2, spheres))


@pytest.mark.parametrize("split", ["mean", "sah"])
def test_a_small_scene_is_built_as_python_into_the_compiled_build_s_tree(split, monkeypatch):
    """A scene of at most accel.interpreted.SMALL primitives is built by the build's functions
    run as Python (accel.interpreted), which compiles nothing; the tree, the rows the traversal
    reads and the leaves' blocks are the compiled build's, bit for bit: with spheres, with
    coordinates float32 holds exactly (float32 blocks) and not, with coincident centroids
    (count splits) and with a tree deep enough for the depth limit."""
    import accel.bvh as bvh_module
    import accel.interpreted
    one = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    scenes = [_random_scene(1, 300, 20, exact=False), _random_scene(2, 200, 0, exact=True),
              accel.Geometry(np.tile(one, (60, 1)), np.arange(180).reshape(60, 3)),
              geometric_series_geometry(150)]
    for geometry in scenes:
        built = {}
        for limit in (geometry.primitive_count, geometry.primitive_count - 1):
            monkeypatch.setattr(accel.interpreted, "SMALL", limit)
            interpreted = limit >= geometry.primitive_count
            bvh = accel.build("bvh", geometry, split=split)
            build = bvh_module.BUILDS[split]
            assert (bvh._run(build) is build) is not interpreted
            built[interpreted] = bvh
        python, compiled = built[True], built[False]
        assert python.max_depth == compiled.max_depth
        for name in ("lower", "upper", "child_or_first", "count", "order"):
            a, b = getattr(python, name), getattr(compiled, name)
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        for a, b in zip(python.compiled, compiled.compiled):
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
            else:
                assert a == b
