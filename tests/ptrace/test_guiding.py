"""Path guiding: the quadtree's samples follow its pdf, the pdf integrates to one over the sphere,
a guide trained on light from one small direction concentrates there, a leaf learns the guide's
share the second moments call for, training is the same whatever order blocks hand their
records in, guided renders keep the unguided mean and the same image whatever the threads, the
bounces' headroom is what the records' second moments say, and --guiding auto trains on the
ceiling-lamp box and turns the guide off on a course box (the unguided image)."""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import ptrace
from ptrace import guiding as guiding_module
from ptrace.guiding import (
    RESOLUTION,
    SHARES,
    Trainer,
    accumulate,
    auto_schedule,
    build_quadtrees,
    learn_share,
    schedule,
)
from ptrace.kernel.guide import (
    R_NX,
    RECORD_ROWS,
    GuideArrays,
    guide_leaf,
    guide_node,
    guide_pdf,
    guide_sample,
    guide_turn,
    normal_bucket,
    quadtree_pdf,
    quadtree_sample,
    sphere_to_square,
    square_to_sphere,
)

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def peaked_grid(seed=1, leaves=1):
    """Grids of directional energy: a bright blob, a dimmer one, a floor of noise and empty
    cells, so the quadtree divides unevenly and has quadrants of zero energy."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:RESOLUTION, 0:RESOLUTION] / RESOLUTION
    grids = []
    for _ in range(leaves):
        cx, cy = rng.uniform(0.2, 0.8, 2)
        g = 50 * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / 0.002)
        g += 5 * np.exp(-((x - 0.1) ** 2 + (y - 0.9) ** 2) / 0.01)
        g = (g + rng.uniform(0, 0.05, g.shape)) * (x < 0.75)
        grids.append(g.reshape(-1))
    return np.array(grids)


def square_pdf_grid(q_child, q_energy, node):
    """The quadtree's density at every grid cell's centre (it is constant on each cell)."""
    centres = (np.arange(RESOLUTION) + 0.5) / RESOLUTION
    return np.array([[quadtree_pdf(q_child, q_energy, node, x, y) for x in centres]
                     for y in centres])


def test_the_quadtree_divides_where_the_energy_is_and_its_pdf_integrates_to_one():
    q_child, q_energy, roots = build_quadtrees(peaked_grid(), 0.01)
    assert q_child.shape[0] > 20     # divided, down to cells near the blob
    pdf = square_pdf_grid(q_child, q_energy, roots[0])
    assert np.isclose(pdf.sum() / RESOLUTION ** 2, 1.0, rtol=1e-12)
    assert (pdf == 0).any() and pdf.max() > 100      # empty quadrants, a sharp peak


def test_samples_follow_the_pdf_chi_square():
    q_child, q_energy, roots = build_quadtrees(peaked_grid(seed=3), 0.01)
    rng = np.random.default_rng(7)
    n = 40000
    xs, ys = np.empty(n), np.empty(n)
    for k, (u1, u2) in enumerate(rng.random((n, 2))):
        x, y, pdf = quadtree_sample(q_child, q_energy, roots[0], u1, u2)
        xs[k], ys[k] = x, y
        if k < 2000:   # the density the warp returns is the pdf's at the point
            assert pdf == pytest.approx(quadtree_pdf(q_child, q_energy, roots[0], x, y),
                                        rel=1e-9)
    bins = 16
    observed = np.histogram2d(ys, xs, bins=bins, range=[[0, 1], [0, 1]])[0].reshape(-1)
    cells = square_pdf_grid(q_child, q_energy, roots[0]) / RESOLUTION ** 2
    step = RESOLUTION // bins
    expected = cells.reshape(bins, step, bins, step).sum(axis=(1, 3)).reshape(-1) * n
    assert not observed[expected == 0].any()
    keep = expected >= 5
    rest = ~keep
    obs = np.append(observed[keep], observed[rest].sum())
    exp = np.append(expected[keep], expected[rest].sum())
    statistic, p = stats.chisquare(obs, exp * obs.sum() / exp.sum())
    assert p > 1e-4, (statistic, p)


def one_leaf_guide(grid):
    q_child, q_energy, roots = build_quadtrees(grid, 0.01)
    return GuideArrays(np.full(1, -1, dtype=np.int64), np.zeros(1), np.zeros(1, dtype=np.int64),
                       roots[:1].copy(), q_child, q_energy, np.ones(q_child.shape[0]), 0.5,
                       0, np.zeros((1, 7)))


def test_the_solid_angle_pdf_integrates_to_one_over_the_sphere_and_matches_its_samples():
    guide = one_leaf_guide(peaked_grid(seed=5))
    rng = np.random.default_rng(2)
    z = rng.uniform(-1, 1, 200000)
    phi = rng.uniform(0, 2 * np.pi, z.size)
    r = np.sqrt(1 - z * z)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    values = np.array([guide_pdf(guide, 0, *d) for d in dirs])
    estimate = values.mean() * 4 * np.pi   # E[pdf / uniform pdf]
    error = values.std() * 4 * np.pi / math.sqrt(values.size)
    assert abs(estimate - 1.0) < 4 * error + 1e-3, (estimate, error)
    for u1, u2 in rng.random((500, 2)):
        dx, dy, dz, pdf = guide_sample(guide, 0, u1, u2)
        assert dx * dx + dy * dy + dz * dz == pytest.approx(1.0, abs=1e-12)
        assert pdf == pytest.approx(guide_pdf(guide, 0, dx, dy, dz), rel=1e-9)


def test_the_guide_s_pdf_finds_each_direction_s_cell_without_an_arctangent():
    """guide_pdf tells a direction's half of each node's phi interval by a sign, not atan2: it
    agrees with the quadtree's density at the point numpy's arctan2 and the equal-area map
    give, on random directions, on the axes, and on directions a hair on either side of cell
    edges in phi (where a wrong half would show); and square_to_sphere's one-cosine direction
    maps back to its point."""
    guide = one_leaf_guide(peaked_grid(seed=8))
    rng = np.random.default_rng(12)
    d = rng.normal(size=(20000, 3))
    edges = 2 * np.pi * (np.arange(RESOLUTION) / RESOLUTION)
    z = rng.uniform(-0.99, 0.99, 2 * edges.size)
    phi = np.concatenate([edges + 1e-9, edges - 1e-9])
    r = np.sqrt(1 - z * z)
    axes = np.vstack([np.eye(3), -np.eye(3)]) + 0.0   # (zeros of one sign: atan2 of -0 differs)
    d = np.vstack([d / np.linalg.norm(d, axis=1)[:, None], axes,
                   np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)])
    x = np.clip(0.5 * (d[:, 2] + 1), 0, 1 - 1e-16)
    y = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi) / (2 * np.pi)
    y = np.clip(y, 0, 1 - 1e-16)
    expected = np.array([quadtree_pdf(guide.q_child, guide.q_density, 0, a, b)
                         for a, b in zip(x, y)]) / (4 * np.pi)
    got = np.array([guide_pdf(guide, 0, *v) for v in d])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=0)   # (same cells)
    assert len(set(np.round(got, 9).tolist())) > 20     # a divided tree: many different cells
    for u1, u2 in rng.random((2000, 2)):
        v = np.array(square_to_sphere(u1, u2))
        assert np.linalg.norm(v) == pytest.approx(1.0, abs=1e-12)
        back = np.mod(np.arctan2(v[1], v[0]), 2 * np.pi) / (2 * np.pi)
        assert (0.5 * (v[2] + 1), back) == pytest.approx((u1, u2), abs=1e-9)


def light_records(rng, n, light, cone):
    """Records (ptrace.kernel.guide's RECORD_ROWS) at points of the unit box over uniform
    directions, each with the radiance divided by the uniform pdf: 1 within `cone` radians of
    `light`, else 0; F / p the same, the BSDF's pdf uniform, normals +z, rays that leave the
    scene (no focus point)."""
    p = rng.uniform(-1, 1, (n, 3))
    z = rng.uniform(-1, 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    lit = d @ light > math.cos(cone)
    ones = np.ones(n)
    return np.vstack([p.T, d.T, lit * 4 * np.pi, lit * 4 * np.pi, ones / (4 * np.pi),
                      ones / (4 * np.pi), 0 * ones, 0 * ones, ones, np.full(n, np.inf)])


def test_a_guide_trained_on_one_small_distant_light_concentrates_toward_it():
    rng = np.random.default_rng(4)
    light = np.array([0.3, 0.8, -0.52])
    light /= np.linalg.norm(light)
    trainer = Trainer(-np.ones(3), np.ones(3), split_samples=2000)
    for block in range(8):
        trainer.add((0, block), light_records(rng, 5000, light, math.radians(3)))
    guide = trainer.finish(1)
    assert len(trainer.tree.leaves()) > 1       # the tree split for the next iteration
    # the guide's mass within 15 degrees of the light, from its own samples at a few points
    for point in ([0.5, 0.5, 0.5], [-0.7, 0.1, -0.4]):
        leaf = guide_leaf(guide.axis, guide.split, guide.child, guide.root, *point,
                          normal_bucket(0.0, 0.0, 1.0))   # (the records' normal, +z)
        near = 0
        for u1, u2 in rng.random((2000, 2)):
            d = np.array(guide_sample(guide, leaf, u1, u2)[:3])
            near += d @ light > math.cos(math.radians(15))
        assert near / 2000 > 0.9     # uniform directions: 0.017
        assert guide_pdf(guide, leaf, *light) > 50 / (4 * math.pi)


def focus_records(rng, n, focus):
    """Records at points of the box [-1, 1]^3 whose rays all reach the point `focus` (a bright
    spot near the box), each with the same energy."""
    p = rng.uniform(-1, 1, (n, 3))
    to = focus - p
    t = np.linalg.norm(to, axis=1)
    ones = np.ones(n)
    return np.vstack([p.T, (to / t[:, None]).T, ones, ones, ones / (4 * np.pi),
                      ones / (4 * np.pi), 0 * ones, 0 * ones, ones, t])


def test_a_leaf_s_parallax_frame_aims_its_guide_at_the_focus_from_any_point():
    """One spatial leaf, the box [-1, 1]^3, whose light all comes from the point (3, 0.3, -0.2):
    seen from the box's points the spot lies up to about 30 degrees from where it lies from the
    centre (near the equator of the guide's sphere map, where its cells are small). The first
    iteration's records give the leaf its focus point; the second's are splatted turned into
    the frame, so the guide, turned at a corner, sends most of its samples within 8 degrees of
    the spot as the corner sees it (its cells are about 6 degrees wide). Without the frame
    (PARALLAX off) the learnt lobe is the spot smeared over the box's views of it, and fewer
    than half do."""
    focus = np.array([3.0, 0.3, -0.2])
    corner = np.array([-0.8, 0.8, 0.8])
    aim = (focus - corner) / np.linalg.norm(focus - corner)
    near = {}
    for parallax in (True, False):
        rng = np.random.default_rng(14)
        guiding_module.PARALLAX = parallax
        try:
            trainer = Trainer(-np.ones(3), np.ones(3), split_samples=10 ** 9, normals=False)
            trainer.add((0, 0), focus_records(rng, 20000, focus))
            first = trainer.finish(1)
            assert first.frame[0, 6] == 0.0     # (no focus known while the first was splatted)
            assert trainer.frames[0, 6] == float(parallax)
            if parallax:
                np.testing.assert_allclose(trainer.frames[0, 3:6], focus, atol=1e-9)
                np.testing.assert_allclose(trainer.frames[0, 0:3], 0.0, atol=1e-6)
            trainer.add((0, 0), focus_records(rng, 200000, focus))
            guide = trainer.finish(2, first)
        finally:
            guiding_module.PARALLAX = True
        node = guide_node(guide.axis, guide.split, guide.child, *corner,
                          normal_bucket(0.0, 0.0, 1.0))
        turned = guide_turn(guide, node, *corner)
        hits = 0
        for u1, u2 in rng.random((2000, 2)):
            d = np.array(guide_sample(guide, guide.root[node], u1, u2, *turned)[:3])
            hits += d @ aim > math.cos(math.radians(8))
        near[parallax] = hits / 2000
    assert near[True] > 0.85 and near[False] < 0.5, near


def test_surfaces_facing_other_ways_learn_guides_of_their_own():
    """The same points of the box [-1, 1]^3 as a floor (normal +z), lit from above, and as a
    wall (normal +x), lit from +x: each normal's leaves learn their own light, so the guide at
    a floor point sends its samples toward the floor's light and at a wall point toward the
    wall's (one tree for both, NORMALS off, learns the two lobes at once and splits its
    samples between them)."""
    rng = np.random.default_rng(3)
    up, side = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    lamp = np.array([0.4, 0.3, 0.866]) / np.linalg.norm([0.4, 0.3, 0.866])
    floor = light_records(rng, 20000, lamp, math.radians(5))
    wall = light_records(rng, 20000, side, math.radians(5))
    wall[R_NX:R_NX + 3] = side[:, None]
    assert [normal_bucket(*up), normal_bucket(*side), normal_bucket(0.2, -0.9, 0.3)] == [4, 0, 3]
    share = {}
    for normals in (True, False):
        trainer = Trainer(-np.ones(3), np.ones(3), split_samples=10 ** 9, normals=normals)
        trainer.add((0, 0), floor)
        trainer.add((0, 1), wall)
        guide = trainer.finish(1)
        for name, normal, light in (("floor", up, lamp), ("wall", side, side)):
            leaf = guide_leaf(guide.axis, guide.split, guide.child, guide.root, 0.1, 0.2, 0.3,
                              normal_bucket(*normal))
            near = sum(np.array(guide_sample(guide, leaf, u1, u2)[:3]) @ light
                       > math.cos(math.radians(10)) for u1, u2 in rng.random((1000, 2)))
            share[name, normals] = near / 1000
    assert share["floor", True] > 0.9 and share["wall", True] > 0.9, share
    assert share["floor", False] < 0.6 and share["wall", False] < 0.6, share


def test_the_turned_guide_s_samples_follow_its_pdf_which_integrates_to_one():
    """At a point where the leaf's frame turns the guide by about 37 degrees, guide_sample's
    density is guide_pdf's at the direction it returns, the turned pdf integrates to one over
    the sphere, and samples binned over the sphere follow it (chi-square against the pdf's
    integral over each bin)."""
    guide = one_leaf_guide(peaked_grid(seed=6))
    guide = guide._replace(frame=np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 1.0]]))
    point = np.array([1.5, 0.0, 0.0])
    vx, vy, vz, c = guide_turn(guide, 0, *point)
    assert math.degrees(math.acos(c)) == pytest.approx(36.87, abs=0.01)
    rng = np.random.default_rng(8)
    n = 20000
    drawn = np.empty((n, 3))
    for k, (u1, u2) in enumerate(rng.random((n, 2))):
        dx, dy, dz, pdf = guide_sample(guide, 0, u1, u2, vx, vy, vz, c)
        drawn[k] = dx, dy, dz
        if k < 500:
            assert dx * dx + dy * dy + dz * dz == pytest.approx(1.0, abs=1e-12)
            assert pdf == pytest.approx(guide_pdf(guide, 0, dx, dy, dz, vx, vy, vz, c),
                                        rel=1e-9)
    z = rng.uniform(-1, 1, 200000)
    phi = rng.uniform(0, 2 * np.pi, z.size)
    r = np.sqrt(1 - z * z)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    values = np.array([guide_pdf(guide, 0, *d, vx, vy, vz, c) for d in dirs])
    estimate = values.mean() * 4 * np.pi
    error = values.std() * 4 * np.pi / math.sqrt(values.size)
    assert abs(estimate - 1.0) < 4 * error + 1e-3, (estimate, error)
    # the turn moves the density: unturned, the same directions have another pdf
    unturned = np.array([guide_pdf(guide, 0, *d) for d in dirs[:2000]])
    assert np.abs(unturned - values[:2000]).max() > 1.0

    def bins(d):   # 8 x 8 equal-area bins of the sphere
        return (np.minimum((d[:, 2] + 1) * 4, 7).astype(int) * 8
                + np.minimum(np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi) / (2 * np.pi) * 8,
                             7).astype(int))

    expected = np.bincount(bins(dirs), weights=values, minlength=64) * 4 * np.pi / dirs.shape[0]
    observed = np.bincount(bins(drawn), minlength=64)
    keep = expected * n >= 20
    assert keep.sum() > 10 and not observed[expected == 0].any()
    obs = np.append(observed[keep], observed[~keep].sum())
    exp = np.append(expected[keep], expected[~keep].sum()) * n
    statistic, p = stats.chisquare(obs, exp * obs.sum() / exp.sum())
    assert p > 1e-4, (statistic, p)


def test_the_box_filter_splats_a_record_into_the_leaves_its_box_overlaps():
    """Two leaves of the box [-1, 1]^3 split at x = 0: a record at x = -0.25 has a box the
    size of its leaf (1 x 2 x 2) from x = -0.75 to 0.25, three quarters in its leaf and one in
    the other; one at the middle of its leaf stays there; one at x = -0.9 has a box partly
    outside the tree, [-1, -0.4] of it inside and all of that in its leaf (shares of the whole
    box would lose 0.4 of its energy). Without the filter each stays in its leaf, and the
    grid's total is the records' energy either way."""
    axis, split = np.array([0, -1, -1]), np.array([0.0, 0.0, 0.0])
    child, root = np.array([1, 0, 0]), np.array([0, 0, 1])
    lower, upper = -np.ones(3), np.ones(3)
    d = np.array([0.3, -0.4, math.sqrt(0.75)])
    records = np.zeros((RECORD_ROWS, 3))
    records[0] = [-0.25, -0.5, -0.9]
    records[3:6] = d[:, None]
    records[6] = [8.0, 4.0, 2.0]
    records[12] = 1.0
    x, y = sphere_to_square(*d)
    cell = int(y * RESOLUTION) * RESOLUTION + int(x * RESOLUTION)
    for box, expected in ((True, [6.0 + 4.0 + 2.0, 2.0]), (False, [14.0, 0.0])):
        grid = np.zeros((2, RESOLUTION * RESOLUTION))
        counts, leaves = np.zeros(2, dtype=np.int64), np.zeros(3, dtype=np.int64)
        accumulate(axis, split, child, root, lower, upper, records, counts, grid, leaves,
                   False, box, np.zeros((2, 7)), np.zeros((2, 5)))
        assert list(leaves) == [0, 0, 0] and list(counts) == [3, 0]
        assert grid[:, cell] == pytest.approx(expected, rel=1e-12)
        assert grid.sum() == pytest.approx(14.0, rel=1e-12)
    # with the cosine, each record's energy times |d . n| (n = +z here)
    grid = np.zeros((2, RESOLUTION * RESOLUTION))
    accumulate(axis, split, child, root, lower, upper, records, np.zeros(2, dtype=np.int64),
               grid, np.zeros(3, dtype=np.int64), True, False, np.zeros((2, 7)),
               np.zeros((2, 5)))
    assert grid[0, cell] == pytest.approx(14.0 * math.sqrt(0.75), rel=1e-12)


def test_training_is_the_same_whatever_order_or_cut_blocks_hand_their_records_in():
    """Between two merges (a chunk of training passes), blocks may come in any order and cut
    the records anywhere (threads, tiles): the guide must not change. Each merge splats runs of
    its records on threads of their own (PARTS), cut by record count, so a cut by block would
    show here as different sums."""
    rng = np.random.default_rng(9)
    light = np.array([0.0, 1.0, 0.0])
    chunks = [np.hstack([light_records(rng, 3000, light, 0.3) for _ in range(4)])
              for _ in range(3)]
    again = [np.hstack([light_records(rng, 3000, light, 0.3) for _ in range(4)])
             for _ in range(2)]
    guides = []
    for cut, order in ((4, None), (7, [5, 0, 3, 6, 1, 4, 2]), (1, None)):
        trainer = Trainer(-np.ones(3), np.ones(3), split_samples=500)
        for c, records in enumerate(chunks):   # a merge after each chunk, as train() does
            blocks = np.array_split(records, cut, axis=1)
            for k in (order or range(cut)):
                trainer.add((c, k), blocks[k])
            trainer.merge()
        first = trainer.finish(1)
        for c, records in enumerate(again):  # a second iteration on the refined tree (shares)
            blocks = np.array_split(records, cut, axis=1)
            for k in reversed(order or range(cut)):
                trainer.add((c, k), blocks[k])
            trainer.merge()
        guides.append(trainer.finish(2, first))
    assert guides[0].share.min() < 1.0   # (shares were learnt)
    for other in guides[1:]:
        for a, b in zip(guides[0], other):
            assert np.array_equal(a, b)


def test_splatting_on_threads_sums_what_one_thread_does(monkeypatch):
    """The runs a merge splats on threads of their own (PARTS) hold every record once: the
    counts equal one thread's, and the grids within rounding of its (a run dropped, cut twice
    or splatted into the wrong grid shows as a difference of a whole record's energy)."""
    rng = np.random.default_rng(21)
    light = np.array([0.6, 0.0, 0.8])
    blocks = [light_records(rng, 7001, light, 0.4) for _ in range(5)]
    trainers = []
    for parts in (1, 2, 3):
        monkeypatch.setattr(guiding_module, "PARTS", parts)
        trainer = Trainer(-np.ones(3), np.ones(3), split_samples=500)
        for k, block in enumerate(blocks[:2]):
            trainer.add((0, k), block)
        trainer.finish(1)                       # a refined tree: the box filter shares records
        for k, block in enumerate(blocks[2:]):
            trainer.add((1, k), block)
        trainer.merge()
        trainers.append(trainer)
    one = trainers[0]
    assert one.grid.shape[0] > 1 and one.counts.sum() == 3 * 7001
    for other in trainers[1:]:
        assert np.array_equal(other.counts, one.counts)
        assert np.allclose(other.grid, one.grid, rtol=1e-12, atol=0)


def test_the_training_schedule_doubles_within_a_quarter_of_the_samples_and_32_passes():
    assert schedule(64) == [1, 2, 4, 8]
    assert schedule(256) == schedule(4096) == [1, 2, 4, 8, 16]    # at most TRAIN_MOST passes
    assert schedule(16) == [1, 2]
    assert schedule(3) == []
    assert schedule(64, first=2) == [2, 4, 8]
    assert auto_schedule(64) == [2, 2, 4, 8]     # the unguided probe, then guided iterations
    assert auto_schedule(128) == auto_schedule(1024) == [2, 2, 4, 8, 16]
    assert auto_schedule(32) == [2, 2, 4]
    assert auto_schedule(16) == []               # too few samples to train a guide: off


def hemisphere_records(rng, n, integrand):
    """learn_share's rows for n bounces drawn uniformly over the hemisphere of normal +z (the
    BSDF's pdf 1 / 2 pi, no guide), all in leaf 0: F / p = integrand(d) 2 pi."""
    z = rng.uniform(0, 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z])
    b = np.full(n, 1 / (2 * np.pi))
    return np.ascontiguousarray(np.vstack([np.zeros(n), integrand(d) / b, b, b, d,
                                           np.zeros((2, n)), np.ones(n), np.zeros((3, n))]))


def test_a_leaf_learns_the_guide_s_share_from_the_second_moments():
    """A guide trained toward a small light: where the reflected light comes from that
    direction alone, the mixture's second moment falls as the guide's share grows (the largest,
    0.9, is learnt); where it is uniform over the hemisphere, the BSDF's uniform pdf is
    proportional to it (zero variance), and any share of the guide adds variance (0 learnt)."""
    rng = np.random.default_rng(11)
    light = np.array([0.3, 0.52, 0.8])
    light /= np.linalg.norm(light)
    trainer = Trainer(-np.ones(3), np.ones(3), split_samples=10 ** 9)
    for block in range(4):
        trainer.add((0, block), light_records(rng, 20000, light, math.radians(10)))
    guide = trainer.finish(1)
    assert guide.alpha == guiding_module.ALPHA    # the first guide: nothing drew records from it
    cone = math.cos(math.radians(4))    # well within the guide's support
    small = hemisphere_records(rng, 40000, lambda d: (light @ d > cone) * 1.0)
    wide = hemisphere_records(rng, 40000, lambda d: np.ones(d.shape[1]))
    assert learn_share(guide, 1, small, SHARES, 10)[0] == SHARES[-1] == 0.9
    assert learn_share(guide, 1, wide, SHARES, 10)[0] == 0.0
    # a leaf of fewer records than `least` takes the choice over all records
    two = np.hstack([small, wide[:, :5]])
    together = learn_share(guide, 1, two, SHARES, 10)[0]
    two[0, -5:] = 1
    assert together < 0.9 and list(learn_share(guide, 2, two, SHARES, 10)) == [0.9, together]


@pytest.fixture(scope="module")
def ceiling():
    return ptrace.load(str(SCENES / "guiding_ceiling.xml"), defines={"res": "32"})   # whole view


def render(scene, seed, guiding, **keywords):
    options = dict(spp=32, max_depth=4, resolution=(32, 32), seed=seed, guiding=guiding)
    options.update(keywords)
    stats_ = {}
    image = ptrace.render(scene, stats=stats_, **options)
    return image, stats_


def test_guided_and_unguided_means_agree_on_the_ceiling_lamp_box(ceiling, monkeypatch):
    """Per seed, the image's mean over each quadrant: guided and unguided estimates of the same
    four numbers, compared by Welch's t over eight seeds each. The guide's share is fixed at
    ALPHA (LEARN off): at this size the learnt shares are small (about 0.05), and so would be
    the bias of a wrong mixture. (Leaving the guide's pdf out of a BSDF-sampled bounce's
    mixture gave t = -5.2 and -7.3 on the upper quadrants; this code gave |t| <= 1.5.)"""
    monkeypatch.setattr(guiding_module, "LEARN", False)
    means = {"off": [], "on": []}
    for guiding in means:
        for seed in range(8):
            image, figures = render(ceiling, seed, guiding, spp=64)
            quadrants = image.mean(axis=2).reshape(2, 16, 2, 16).mean(axis=(1, 3)).reshape(-1)
            means[guiding].append(quadrants)
            if guiding == "on":
                assert figures["guiding"]["guided"] and figures["guiding"]["records"] > 0
    off, on = np.array(means["off"]), np.array(means["on"])
    t, p = stats.ttest_ind(on, off, equal_var=False)
    assert (np.abs(t) < 4.5).all(), (t, on.mean(0), off.mean(0))
    assert off.mean() > 0.05      # the box is lit (indirectly)


def test_a_guided_render_is_the_same_whatever_the_threads(ceiling):
    one = render(ceiling, 3, "on", threads=1)[0]
    two = render(ceiling, 3, "on", threads=2)[0]
    assert np.array_equal(one, two)


def test_guiding_refuses_what_it_does_not_support(ceiling):
    with pytest.raises(ptrace.PtraceError, match="guiding"):
        ptrace.render(ceiling, spp=4, guiding="on", adaptive=(4, 0.1))
    with pytest.raises(ptrace.PtraceError, match="guiding mode"):
        ptrace.render(ceiling, spp=4, guiding="sometimes")


def test_the_headroom_is_the_records_second_moment_over_their_mean_squared_by_leaf():
    """Records lit within a cone of 10 degrees (F / p = 4 pi there, 0 elsewhere): a perfect
    guide would lower the bounce's second moment by the share of directions the cone misses,
    E[x^2] / E[x]^2 = n / lit = 1 / q for q the cone's share of the sphere; records of one
    light value everywhere leave nothing to gain (1). Two leaves (normals up and down: two
    buckets) are averaged by their light. An unlit iteration: 1."""
    rng = np.random.default_rng(5)
    light = np.array([0.2, -0.4, 0.9])
    light /= np.linalg.norm(light)
    trainer = Trainer(-np.ones(3), np.ones(3), split_samples=10 ** 9)
    assert trainer.pending_headroom() == 1.0           # nothing handed in
    cone = light_records(rng, 40000, light, math.radians(10))
    lit = int(np.count_nonzero(cone[7]))
    trainer.add((0, 0), cone)
    share = (1 - math.cos(math.radians(10))) / 2
    assert trainer.pending_headroom() == pytest.approx(40000 / lit, rel=1e-9)
    assert trainer.pending_headroom() == pytest.approx(1 / share, rel=0.15)
    trainer.merge()
    assert trainer.pending_headroom() == 1.0           # merged: no longer pending
    flat = light_records(rng, 10000, light, math.pi)   # lit everywhere: x = 4 pi
    flat[R_NX + 2] = -1.0                               # normals down: the other bucket
    trainer.add((1, 0), cone)
    trainer.add((1, 1), flat)
    weight = lit / (lit + 10000)                        # each leaf's share of the light
    assert trainer.pending_headroom() == pytest.approx(weight * 40000 / lit + (1 - weight) * 1.0)


def test_auto_trains_on_the_ceiling_lamp_box_and_is_the_same_whatever_the_threads(ceiling):
    """Every pixel of the box is lit by bounces toward the lit ceiling, a few directions of the
    hemisphere: the probe's headroom is far above HEADROOM (about 60-80 at 32x32), so training
    goes on; the final passes are guided where the last iteration's variance per sample is
    below the probe's."""
    image, figures = render(ceiling, 2, "auto", spp=64)
    g = figures["guiding"]
    decision = g["decision"]
    assert decision["headroom"] > 1.5 * guiding_module.HEADROOM, decision
    assert decision["probe_variance"] == g["variance"][0] and math.isfinite(g["variance"][0])
    assert g["iterations"] == [2, 2, 4, 8] and g["training_samples"] == 16
    assert g["guided"] == (g["variance"][-1] < g["variance"][0])
    assert sum(g["weights"]) == pytest.approx(1.0)   # the iterations' and the final image's
    assert np.isfinite(image).all() and image.mean() > 0.05
    assert np.array_equal(image, render(ceiling, 2, "auto", spp=64, threads=1)[0])


def test_auto_turns_the_guide_off_on_a_course_box_and_renders_the_unguided_image(course_scene):
    """CBspheres_lambertian, where next-event estimation does the work: the bounces' light
    comes from the whole hemisphere (walls, ceiling), the headroom is about 2, so auto keeps
    the unguided render: its image is the unguided one, the probe's samples in it."""
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    options = dict(spp=64, max_depth=5, resolution=(64, 48), seed=3)
    figures = {}
    auto = ptrace.render(scene, guiding="auto", stats=figures, **options)
    off = ptrace.render(scene, **options)
    g = figures["guiding"]
    assert not g["guided"] and g["iterations"] == [2]
    assert g["decision"]["headroom"] < guiding_module.HEADROOM / 4, g["decision"]
    np.testing.assert_allclose(auto, off, rtol=1e-5, atol=1e-6)


def test_the_commands_refuse_guiding_where_it_does_not_work_in_one_line(tmp_path, capsys):
    from ptrace.app import cli, options
    scene = str(SCENES / "guiding_ceiling.xml")
    out = str(tmp_path / "x.png")
    for argv in ([scene, "--guiding", "on", "-a", "4", "0.1", "-f", out],
                 [scene, "--guiding", "on", "-H", "-f", out],
                 [scene, "--guiding", "maybe", "-f", out],
                 ["view", scene, "--no-browser", "--guiding", "auto"]):
        assert cli.main(argv) == options.EXIT_USAGE == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("ptrace: error: "), err
        assert "guiding" in err
    assert list(tmp_path.iterdir()) == []
