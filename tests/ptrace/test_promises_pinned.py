"""Promises checked against answers computed here, independently of the code under test: the
memory budget's running account (hand arithmetic), the default light's emitter share (a closed
form for the light a small square sends onto a parallel floor), and the light tree's importance
(a plain numpy reimplementation of pbrt-v4's LightBounds::Importance with the departures
ptrace.light_tree's docstring states)."""
import math

import numpy as np
import pytest
from files_by_hand import QUAD, QUAD_FACES, QUAD_UV_GLTF, gltf

import ptrace
from ptrace.budget import TEXEL_BYTES, TEXTURE_PEAK_BYTES, Budget, BudgetError

# -- the memory budget: items that fit alone but not together ---------------------------------


def test_budget_items_that_fit_alone_are_refused_together():
    """A budget charges what each item keeps (resident) and refuses an item when the total so
    far, plus that item's resident and transient bytes, passes the limit: three items of 40
    resident bytes each fit a 100-byte budget alone, the first two together (80), not the
    third (120). An item's transient bytes count while it is charged and are then returned:
    30 kept + 50 meanwhile fits alone (80), but not after another such item (30 + 80)."""
    for _ in range(3):
        Budget(100, "test").charge("f", "an item", 40)          # each alone
    together = Budget(100, "test")
    together.charge("f", "the first", 40)
    together.charge("f", "the second", 40)
    assert together.spent == 80
    with pytest.raises(BudgetError, match="the third"):
        together.charge("f", "the third", 40)
    with_transient = Budget(100, "test")
    with_transient.charge("f", "one", 30, transient=50)
    assert with_transient.spent == 30
    with pytest.raises(BudgetError, match="two"):
        with_transient.charge("f", "two", 30, transient=50)


def _textured_quads(path, count, side):
    """A glTF file of `count` quads side by side, each with its own side x side texture."""
    import io

    import PIL.Image
    images = []
    for k in range(count):
        stream = io.BytesIO()
        PIL.Image.new("RGB", (side, side), (40 * k + 50, 90, 200)).save(stream, "PNG")
        images.append(stream.getvalue())
    primitives = [dict(positions=QUAD + [3.0 * k, 0.0, 0.0], indices=QUAD_FACES.reshape(-1),
                       uv=QUAD_UV_GLTF, material=k) for k in range(count)]
    materials = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": k}}}
                 for k in range(count)]
    gltf(path, primitives, materials=materials, images=images)
    return path


def test_a_files_textures_that_fit_the_budget_alone_are_refused_together(tmp_path):
    """Two 512 x 512 textures of N texels each: a texture keeps K = TEXEL_BYTES a texel and
    peaks at P = TEXTURE_PEAK_BYTES while it is decoded, so one texture needs P N, the second
    after the first K N + P N. A budget of (P + K / 2) N (plus room for the quads' few
    triangles) loads either file of one texture, and refuses the file that holds both."""
    side = 512
    texels = side * side
    kept, peak = TEXEL_BYTES, TEXTURE_PEAK_BYTES
    limit = (peak + kept // 2) * texels + 20_000
    ptrace.load(_textured_quads(tmp_path / "one.gltf", 1, side), max_memory=limit)
    (tmp_path / "other").mkdir()
    ptrace.load(_textured_quads(tmp_path / "other" / "one.gltf", 1, side), max_memory=limit)
    with pytest.raises(BudgetError, match="512x512 texture"):
        ptrace.load(_textured_quads(tmp_path / "two.gltf", 2, side), max_memory=limit)
    # and room for both
    ptrace.load(tmp_path / "two.gltf", max_memory=(peak + kept + 2) * texels + 20_000)


# -- the default light's emitter share ---------------------------------------------------------


def _corner_form_factor(a, b, c):
    """The share of a cosine-distributed hemisphere of directions, from a point at height c,
    that meets a parallel a x b rectangle with a corner straight below the point (the
    differential-area-to-rectangle form factor)."""
    A, B = a / c, b / c
    sa, sb = np.sqrt(1.0 + A * A), np.sqrt(1.0 + B * B)
    return (A / sa * np.arctan(B / sa) + B / sb * np.arctan(A / sb)) / (2.0 * math.pi)


def test_the_default_lights_emitter_share_is_the_closed_form():
    """A square emitter (side s, emission 1 in every channel: luminance 1) at height h over a
    floor of half-width W, nothing else. Its power is 2 pi s^2 (pi s^2 from either face); the
    light leaving the upper face meets nothing, the share of the lower face's that lands on
    the floor is the form factor F from its points to the floor (averaged over the square in
    numpy); the default light's power onto the bounding box (2W x h x 2W) is pi x 1 x its
    area. share = 2 pi s^2 (F / 2) / (pi 2 (4 W^2 + 2 x 2 W h)); the rule traces 2^14 rays,
    so to a few percent."""
    from ptrace.io.default_light import emitter_share
    from ptrace.scene import DIFFUSE, EMISSION, Materials
    s, h, W = 0.4, 1.0, 2.0
    vertices = np.array([[-W, 0, -W], [W, 0, -W], [W, 0, W], [-W, 0, W],
                         [-s / 2, h, -s / 2], [s / 2, h, -s / 2], [s / 2, h, s / 2],
                         [-s / 2, h, s / 2]], float)
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]])
    materials = Materials.from_records([{"kind": DIFFUSE, "albedo": (0.5,) * 3},
                                        {"kind": EMISSION, "emission": (1.0,) * 3}])
    share = emitter_share(vertices, faces, np.array([0, 0, 1, 1]), materials,
                          np.zeros((0, 3, 2)), None)
    k = (np.arange(64) + 0.5) / 64 * s - s / 2
    x, z = np.meshgrid(k, k)
    form = sum(_corner_form_factor(W + sx * x, W + sz * z, h)
               for sx in (-1, 1) for sz in (-1, 1)).mean()
    box = 2 * ((2 * W) * h + h * (2 * W) + (2 * W) * (2 * W))
    expected = 2 * math.pi * s * s * (form / 2) / (math.pi * 1.0 * box)
    assert 0.8 < form < 1.0
    assert share == pytest.approx(expected, rel=0.04), (share, expected)


# -- the light tree's importance against pbrt-v4's formula -------------------------------------


def _cos_sub(sin_a, cos_a, sin_b, cos_b):
    """cos(max(0, a - b)) (pbrt-v4's cosSubClamped)."""
    return 1.0 if cos_a > cos_b else cos_a * cos_b + sin_a * sin_b


def _sin_sub(sin_a, cos_a, sin_b, cos_b):
    """sin(max(0, a - b)) (pbrt-v4's sinSubClamped)."""
    return 0.0 if cos_a > cos_b else sin_a * cos_b - cos_a * sin_b


def pbrt_importance(lo, hi, power, axis, cos_o, cos_e, two, p, n):
    """pbrt-v4's LightBounds::Importance(p, n), in plain Python, with ptrace's departures (its
    module docstring): the distance is clamped by the bounding sphere's squared radius (inside
    it, power / r^2), n is one-sided (cos theta_i = -n . wi, nothing where the light's sphere
    lies wholly behind n), and the importance is zero where the box lies on or below p's
    tangent plane, or p lies on or behind a box of flat one-sided emitters."""
    lo, hi, p, axis = (np.asarray(x, float) for x in (lo, hi, p, axis))
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    if n is not None and (corners @ n).max() <= p @ n:
        return 0.0
    flat = cos_o >= 1.0 and cos_e >= 0.0 and not two
    if flat and p @ axis <= (corners @ axis).min():
        return 0.0
    pc = 0.5 * (lo + hi)
    r2 = 0.25 * float(np.sum((hi - lo) ** 2))
    d2 = float(np.sum((p - pc) ** 2))
    if d2 <= r2:
        return power / r2
    wi = (p - pc) / math.sqrt(d2)
    cos_w = float(axis @ wi)
    if two:
        cos_w = abs(cos_w)
    sin_w = math.sqrt(max(0.0, 1.0 - cos_w * cos_w))
    sin2_b = r2 / d2                       # BoundSubtendedDirections: the bounding sphere
    cos_b, sin_b = math.sqrt(1.0 - sin2_b), math.sqrt(sin2_b)
    sin_o = math.sqrt(max(0.0, 1.0 - cos_o * cos_o))
    cos_x = _cos_sub(sin_w, cos_w, sin_o, cos_o)
    sin_x = _sin_sub(sin_w, cos_w, sin_o, cos_o)
    cos_p = _cos_sub(sin_x, cos_x, sin_b, cos_b)
    if cos_p <= cos_e:
        return 0.0
    importance = power * cos_p / d2
    if n is not None:
        cos_i = -float(n @ wi)
        sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
        cos_pi = _cos_sub(sin_i, cos_i, sin_b, cos_b)
        if cos_pi <= 0.0:
            return 0.0
        importance *= cos_pi
    return max(importance, 0.0)


def _random_lanes(rng):
    """One wide node of LANES random lanes, filled as the build fills them (its centre and
    squared radius: the box's bounding sphere), and each lane's inputs for pbrt_importance."""
    from ptrace.light_tree_build import (
        F_AXIS,
        F_CENTER,
        F_COS_E,
        F_COS_O,
        F_FLAT,
        F_HI,
        F_LO,
        F_POWER,
        F_R2,
        F_SIN_O,
        F_TWO,
        FIELDS,
        LANES,
    )
    lanes = np.zeros((1, FIELDS, LANES))
    inputs = []
    for i in range(LANES):
        lo = rng.uniform(-1.5, 1.5, 3)
        hi = lo + rng.uniform(0.0, 1.2, 3) * (rng.random(3) < 0.85)   # some flat boxes
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        kind = rng.integers(4)
        cos_o = (1.0, -1.0, rng.uniform(-1, 1), rng.uniform(0.5, 1))[kind]
        cos_e = 0.0 if rng.random() < 0.6 else math.cos(rng.uniform(0.05, 1.5))
        two = bool(rng.random() < 0.3)
        power = rng.uniform(0.1, 10.0)
        lanes[0, F_LO:F_LO + 3, i], lanes[0, F_HI:F_HI + 3, i] = lo, hi
        lanes[0, F_CENTER:F_CENTER + 3, i] = 0.5 * (lo + hi)
        lanes[0, F_R2, i] = 0.25 * np.sum((hi - lo) ** 2)
        lanes[0, F_POWER, i], lanes[0, F_AXIS:F_AXIS + 3, i] = power, axis
        lanes[0, F_COS_O, i], lanes[0, F_SIN_O, i] = cos_o, math.sqrt(1 - cos_o * cos_o)
        lanes[0, F_COS_E, i], lanes[0, F_TWO, i] = cos_e, float(two)
        lanes[0, F_FLAT, i] = float(cos_o >= 1.0 and cos_e >= 0.0 and not two)
        inputs.append((lo, hi, power, axis, cos_o, cos_e, two))
    return lanes, inputs


def test_lane_importance_is_pbrt_v4s_importance():
    """On random boxes, cones, powers and points (with a random unit normal, or none), every
    lane's importance is the reimplementation's, to rounding; and the random cases reach every
    branch: zero by the tangent plane, by the emission cone, and inside the bounding sphere."""
    from ptrace.light_tree import lane_importance
    from ptrace.light_tree_build import LANES
    rng = np.random.default_rng(7)
    seen = {"zero": 0, "inside": 0, "positive": 0}
    for trial in range(120):
        lanes, inputs = _random_lanes(rng)
        for _ in range(6):
            p = rng.uniform(-3.0, 3.0, 3) if rng.random() < 0.8 else rng.uniform(-1, 1, 3)
            n = rng.normal(size=3)
            n /= np.linalg.norm(n)
            has_n = rng.random() < 0.8
            for i in range(LANES):
                got = lane_importance(lanes, 0, i, *p, *(n if has_n else np.zeros(3)), has_n)
                want = pbrt_importance(*inputs[i], p, n if has_n else None)
                assert got == pytest.approx(want, rel=1e-9, abs=1e-300), (trial, i, p, n,
                                                                          has_n, inputs[i])
                lo, hi = inputs[i][:2]
                inside = np.sum((p - 0.5 * (lo + hi)) ** 2) <= 0.25 * np.sum((hi - lo) ** 2)
                seen["zero" if want == 0 else "inside" if inside else "positive"] += 1
    assert min(seen.values()) > 50, seen
