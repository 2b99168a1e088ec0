"""Whether a mesh file that has no light of its own gets the default light.

A file without lights is lit either by its own emissive surfaces or by ptrace's default
ambient light (radiance AMBIENT_RADIANCE from the upper hemisphere about +Y). A closed room lit
by its own lamp (an OBJ Cornell box) must be lit by that lamp and nothing else; a model whose
only emitters are small or face away from it (a helmet's lamps, the labels beside a row of
spheres) must still be seen.

The rule (emitter_share): the power the emitters send onto the scene's other surfaces, against
the power the default light would send onto the scene's bounding box. The emitters' power is
the integral over their surface of the emitted luminance (the material's emission times its
emission texture) times pi, on each of their two faces (ptrace's emission is two-sided). The
share of it that lands is measured by tracing RAYS rays from the emitters, cosine-distributed
about either face's normal: a ray lands if it hits a triangle whose material does not emit, at
least NEAR times the box's largest side away. (Light that lands nearer lights the surface just
behind its emitter, which the emitter hides: a lamp under a ceiling, a label on a board; light
that lands on emitters lights the inside of an emissive object, which nothing sees; glTF's
emitters reflect too, but what lands on them is still mostly their own insides.) The
default light's power onto the box is pi x AMBIENT_RADIANCE x the box's surface area. Emitters
whose landed power is at least EMITTER_SHARE of that light the file alone; weaker ones get the
default light beside them. The share does not depend on the file's units or tessellation.

The rays are traced by Embree through embreex's own Python interface (a dependency of ptrace
already), not through accel: accel's faces are numba code, whose first compilation would cost
far more than the rest of a loader's work.
"""
import dataclasses
import math

import numpy as np

from ..scene import AMBIENT, CLAMP, LUMINANCE, MIRROR_REPEAT

AMBIENT_RADIANCE = 1.0
# emitters whose power landing on the scene is at least this share of the default light's
# onto the bounding box light the file alone (chosen from real files: see docs/usage.md)
EMITTER_SHARE = 0.01
# texture samples per emissive triangle (fewer on big meshes: at most MAX_LOOKUPS in all)
SAMPLES, MAX_LOOKUPS = 16, 1 << 20
# rays traced from the emitters (the landed share's standard error: at most 1/256)
RAYS = 1 << 14
NEAR = 0.01             # light lands this far (times the box's largest side) or more, or not


def emitter_share(vertices, faces, material_index, materials, uv, textures):
    """The emitters' power that lands on the scene over the default light's power onto the
    scene's bounding box: 0 without emitters, inf for a box of no area that has emitters."""
    triangles, luminance, area = emitter_triangles(vertices, faces, material_index, materials,
                                                   uv, textures)
    # the weights (luminance x area) over their largest factors, each in [0, 1]: their sum
    # cannot overflow, nor can the probabilities the rays are picked by; the power is finite
    # for a file's numbers (within ptrace.io.limits.LIMIT), and inf at worst, never NaN
    scales = [float(np.max(x)) if len(x) else 0.0 for x in (luminance, area)]
    if not (scales[0] > 0.0 and scales[1] > 0.0 and np.isfinite(scales).all()):
        return math.inf if scales[0] > 0.0 and scales[1] > 0.0 else 0.0
    weight = (luminance / scales[0]) * (area / scales[1])
    if not weight.sum() > 0.0:
        return 0.0
    power = 2.0 * math.pi * scales[0] * scales[1] * float(weight.sum())      # both faces
    used = vertices[faces.reshape(-1)]
    lower, upper = used.min(axis=0), used.max(axis=0)
    reference = ambient_power(lower, upper)
    if not reference > 0.0:
        return math.inf
    reflecting = np.ones(len(faces), bool)
    reflecting[triangles] = False
    landed = landed_fraction(vertices, faces, triangles, weight, reflecting, lower, upper)
    return power * landed / reference if landed > 0.0 else 0.0


def ambient_power(lower, upper):
    """pi x AMBIENT_RADIANCE x the surface area of the box [lower, upper]."""
    x, y, z = np.maximum(np.asarray(upper, float) - np.asarray(lower, float), 0.0)
    return math.pi * AMBIENT_RADIANCE * 2.0 * (x * y + y * z + z * x)


def emitter_triangles(vertices, faces, material_index, materials, uv, textures):
    """(indices, mean emitted luminance, area) of the triangles whose material emits: the
    luminance is the material's emission times its emission texture, averaged over up to
    SAMPLES points of the triangle (nearest texel), 0 where the texture is black."""
    emission = np.asarray(materials.emission, dtype=np.float64) @ LUMINANCE
    tri_material = np.asarray(material_index[:len(faces)])
    chosen = np.flatnonzero(np.isin(tri_material, np.flatnonzero(emission > 0)))
    corners = vertices[faces[chosen]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1)
    luminance = emission[tri_material[chosen]]
    texture = np.asarray(materials.emission_texture)[tri_material[chosen]]
    textured = np.flatnonzero(texture >= 0) if len(uv) == len(faces) else np.zeros(0, int)
    samples = max(1, min(SAMPLES, MAX_LOOKUPS // max(len(textured), 1)))
    for start in range(0, len(textured), 1 << 16):
        part = textured[start:start + (1 << 16)]
        luminance[part] = _textured_luminance(materials, chosen[part], texture[part],
                                              tri_material[chosen[part]], uv, textures,
                                              samples)
    return chosen, luminance, area


def landed_fraction(vertices, faces, triangles, weight, reflecting, lower, upper, rays=RAYS):
    """The share of the power of `triangles` (each weighted by luminance x area) that lands
    on a surface that does not emit (reflecting: a flag per triangle), at least NEAR times the
    bounding box's largest side from where it left (see the module's docstring for why):
    rays from points spread over the triangles in proportion to weight, either face alike,
    cosine-distributed about its normal."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    rng = np.random.default_rng(0)
    centre = 0.5 * (lower + upper)
    scale = float(np.abs(upper - lower).max()) or 1.0
    corners = (vertices[faces] - centre) / scale     # float32 keeps the shape: near 0, size 1
    pick = triangles[rng.choice(len(triangles), size=rays, p=weight / weight.sum())]
    a, b, c = corners[pick, 0], corners[pick, 1], corners[pick, 2]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    normal *= rng.choice([-1.0, 1.0], size=(rays, 1))   # either face
    root, v = np.sqrt(rng.random(rays))[:, None], rng.random(rays)[:, None]
    origin = (1.0 - root) * a + root * (1.0 - v) * b + root * v * c + 1e-5 * normal
    direction = _cosine_directions(normal, rng)
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, corners.astype(np.float32))
    hits = scene.run(origin.astype(np.float32), direction.astype(np.float32), output=1)
    prim = np.asarray(hits["primID"])
    hit = prim >= 0
    landed = hit & (np.asarray(hits["tfar"]) >= NEAR)
    landed[hit] &= reflecting[prim[hit]]
    return float(np.mean(landed))


def _cosine_directions(normal, rng):
    """Unit directions cosine-distributed about each unit normal."""
    n = len(normal)
    phi = 2.0 * math.pi * rng.random(n)
    r = np.sqrt(rng.random(n))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=1)
    helper = np.where(np.abs(normal[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    x = np.cross(helper, normal)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(normal, x)
    return local[:, :1] * x + local[:, 1:2] * y + local[:, 2:] * normal


def _textured_luminance(materials, triangles, texture, material, uv, textures, samples):
    """Mean emitted luminance over each triangle (emission x texture at `samples` points)."""
    points = _barycentric_points(samples)                      # (S, 3)
    st = np.einsum("sk,tkc->tsc", points, uv[triangles])        # (T, S, 2)
    width = textures.width[texture][:, None]
    height = textures.height[texture][:, None]
    with np.errstate(invalid="ignore"):
        st = np.nan_to_num(st, nan=0.0, posinf=0.0, neginf=0.0)
    # within 2^30, where float64 still resolves 2^-22 of a repeat, so that st x a side of at
    # most 2^31 texels (PNG's largest) stays below int64's 2^63 (a file's vt may be anything
    # finite: 1e308 x the width overflowed)
    st = np.clip(st, -2.0 ** 30, 2.0 ** 30)
    column = _wrap(np.floor(st[..., 0] * width).astype(np.int64), width,
                   textures.wrap[texture, 0][:, None])
    row = _wrap(np.floor((1.0 - st[..., 1]) * height).astype(np.int64), height,
                textures.wrap[texture, 1][:, None])
    texels = textures.texels[textures.offset[texture][:, None] + row * width + column]
    colour = texels.mean(axis=1) * np.asarray(materials.emission)[material]
    return colour @ LUMINANCE


def _wrap(i, n, mode):
    """Texel indices i wrapped into [0, n) by each one's wrap mode (as ptrace.textures)."""
    period = i % (2 * n)
    mirrored = np.where(period < n, period, 2 * n - 1 - period)
    return np.where(mode == CLAMP, np.clip(i, 0, n - 1),
                    np.where(mode == MIRROR_REPEAT, mirrored, i % n))


def _barycentric_points(samples):
    """(samples, 3) barycentric weights spread over a triangle (the centroid for one)."""
    if samples == 1:
        return np.full((1, 3), 1.0 / 3.0)
    k = np.arange(samples) + 0.5
    u = k / samples
    v = (k * 0.6180339887498949) % 1.0           # a Fibonacci lattice over the unit square
    root = np.sqrt(u)
    return np.stack([1.0 - root, root * (1.0 - v), root * v], axis=1)


NOTE = "mesh file: default light: "     # how every note of this rule starts
OFF = "--no-default-light, or load(..., default_light=False)"


def default_lights(vertices, faces, material_index, materials, uv, textures, on=True):
    """(light records, note) for a mesh file that has no lights of its own: the default
    ambient light unless its emitters light it (emitter_share at least EMITTER_SHARE) or `on`
    is False; the note says which rule applied and with what share."""
    ambient = [{"kind": AMBIENT, "radiance": (AMBIENT_RADIANCE,) * 3}]
    emits = (np.asarray(materials.emission) > 0).any(axis=1)
    if not emits[np.asarray(material_index[:len(faces)])].any():
        if not on:
            return [], NOTE + f"off ({OFF}), and the file has no light and no emissive surface"
        return ambient, (NOTE + f"the file has no light and no emissive surface: one ambient "
                                f"light of radiance {AMBIENT_RADIANCE:g} (the upper hemisphere "
                                f"about +Y; --no-default-light: none)")
    if not on:
        return [], NOTE + f"off ({OFF}): the file's emissive surfaces are its only light"
    share = emitter_share(vertices, faces, material_index, materials, uv, textures)
    said = "all" if share == math.inf else f"{100 * share:.2g} %"
    if share >= EMITTER_SHARE:
        return [], (NOTE + f"none: the file has no light, and its emissive surfaces light it "
                           f"(the power they send onto its surfaces is {said} of the default "
                           f"light's onto its bounds, at least {100 * EMITTER_SHARE:g} %; -e "
                           f"adds an environment)")
    return ambient, (NOTE + f"the file has no light, and its emissive surfaces send onto its "
                            f"surfaces {said} of the default light's power onto its bounds "
                            f"(under {100 * EMITTER_SHARE:g} %): one ambient light of radiance "
                            f"{AMBIENT_RADIANCE:g} beside them (--no-default-light: none)")


def without_default_light(scene, why):
    """Drop a mesh file's default ambient light (the only ambient light a mesh file has),
    its note saying `why`; the scene as it is if it has none."""
    keep = scene.lights.kind != AMBIENT
    if keep.all():
        return scene
    fields = {f.name: getattr(scene.lights, f.name)[keep]
              for f in dataclasses.fields(scene.lights)}
    scene.lights = type(scene.lights)(**fields)
    scene.notes[:] = [n for n in scene.notes if not n.startswith(NOTE)]
    scene.notes.append(NOTE + f"off ({why})")
    return scene
