"""Surface values that vary over a surface: image textures (bilinear, three wrap modes) and
vertex colours, looked up at a hit's texture coordinates by the compiled path loop.

Written by hand rather than through OpenImageIO's TextureSystem: the lookup runs inside the
compiled loop, once per hit, where a Python library cannot be called. Images
are read and converted to linear RGB by the loaders (ptrace.io.materials); here they are flat
arrays (ptrace.scene.Textures).
"""
import math

from numba import njit

from .scene import CLAMP, MIRROR_REPEAT


@njit(cache=True, inline="always")
def _wrap(i, n, mode):
    """Texel index i (any integer) of a row or column of n texels, by wrap mode."""
    if mode == CLAMP:
        return min(max(i, 0), n - 1)
    if mode == MIRROR_REPEAT:
        period = i % (2 * n)          # Python's modulo: non-negative
        return period if period < n else 2 * n - 1 - period
    return i % n                      # REPEAT


@njit(cache=True, _nrt=False, forceinline=True)
def texture_lookup(texels, offset, width, height, wrap, t, s, tv):
    """Texture t's linear RGB at texture coordinates (s, tv), tv up (OBJ's convention; row 0 of the
    image is its top, v = 1): bilinear between the four nearest texel centres, which sit at
    ((i + 0.5) / W, 1 - (j + 0.5) / H)."""
    w, h = width[t], height[t]
    x = s * w - 0.5
    y = (1.0 - tv) * h - 0.5
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0, 0.0
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    ix0, iy0 = int(x0), int(y0)
    i0 = _wrap(ix0, w, wrap[t, 0])
    i1 = _wrap(ix0 + 1, w, wrap[t, 0])
    j0 = _wrap(iy0, h, wrap[t, 1])
    j1 = _wrap(iy0 + 1, h, wrap[t, 1])
    base = offset[t]
    a, b = base + j0 * w + i0, base + j0 * w + i1
    c, d = base + j1 * w + i0, base + j1 * w + i1
    w00, w10 = (1.0 - fx) * (1.0 - fy), fx * (1.0 - fy)
    w01, w11 = (1.0 - fx) * fy, fx * fy
    r = w00 * texels[a, 0] + w10 * texels[b, 0] + w01 * texels[c, 0] + w11 * texels[d, 0]
    g = w00 * texels[a, 1] + w10 * texels[b, 1] + w01 * texels[c, 1] + w11 * texels[d, 1]
    bl = w00 * texels[a, 2] + w10 * texels[b, 2] + w01 * texels[c, 2] + w11 * texels[d, 2]
    return r, g, bl


@njit(cache=True, _nrt=False, forceinline=True)
def _uv(uv, prim, u, v):
    w = 1.0 - u - v
    return (w * uv[prim, 0, 0] + u * uv[prim, 1, 0] + v * uv[prim, 2, 0],
            w * uv[prim, 0, 1] + u * uv[prim, 1, 1] + v * uv[prim, 2, 1])


@njit(cache=True, _nrt=False, forceinline=True)
def surface_albedo(shapes, materials, m, prim, u, v):
    """(albedo r, g, b, alpha, metallic) of material m at barycentrics (u, v) of primitive
    prim: the material's values times its albedo texture and the vertex colours (triangles
    only), its alpha times the roughness texture's green channel squared and its metallic times
    that texture's blue channel (glTF's metallicRoughness texture)."""
    ar, ag, ab = materials.albedo[m, 0], materials.albedo[m, 1], materials.albedo[m, 2]
    alpha = materials.alpha[m]
    metallic = materials.metallic[m]
    n_tri = shapes.faces.shape[0]
    if prim < 0 or prim >= n_tri:
        return ar, ag, ab, alpha, metallic
    colours = shapes.vertex_colours
    if colours.shape[0] > 0:
        a, b, c = shapes.faces[prim, 0], shapes.faces[prim, 1], shapes.faces[prim, 2]
        w = 1.0 - u - v
        ar *= w * colours[a, 0] + u * colours[b, 0] + v * colours[c, 0]
        ag *= w * colours[a, 1] + u * colours[b, 1] + v * colours[c, 1]
        ab *= w * colours[a, 2] + u * colours[b, 2] + v * colours[c, 2]
    t_albedo, t_rough = materials.albedo_texture[m], materials.roughness_texture[m]
    if (t_albedo >= 0 or t_rough >= 0) and shapes.uv.shape[0] > 0:
        s, tv = _uv(shapes.uv, prim, u, v)
        if t_albedo >= 0:
            tr, tg, tb = texture_lookup(materials.texels, materials.tex_offset,
                                        materials.tex_width, materials.tex_height,
                                        materials.tex_wrap, t_albedo, s, tv)
            ar, ag, ab = ar * tr, ag * tg, ab * tb
        if t_rough >= 0:
            _, roughness, blue = texture_lookup(materials.texels, materials.tex_offset,
                                                materials.tex_width, materials.tex_height,
                                                materials.tex_wrap, t_rough, s, tv)
            alpha = max(alpha * roughness * roughness, 1e-4)
            metallic *= blue
    return ar, ag, ab, alpha, metallic


@njit(cache=True, _nrt=False, forceinline=True)
def surface_emission(shapes, materials, m, prim, u, v):
    """Emitted radiance of material m at barycentrics (u, v) of primitive prim: its emission
    times its emission texture (triangles with texture coordinates only)."""
    er, eg, eb = materials.emission[m, 0], materials.emission[m, 1], materials.emission[m, 2]
    t = materials.emission_texture[m]
    if t >= 0 and 0 <= prim < shapes.faces.shape[0] and shapes.uv.shape[0] > 0:
        s, tv = _uv(shapes.uv, prim, u, v)
        tr, tg, tb = texture_lookup(materials.texels, materials.tex_offset, materials.tex_width,
                                    materials.tex_height, materials.tex_wrap, t, s, tv)
        er, eg, eb = er * tr, eg * tg, eb * tb
    return er, eg, eb


@njit(cache=True, _nrt=False, forceinline=True)
def surface_opacity(shapes, materials, m, prim, u, v):
    """Material m's alpha (glTF's: its base colour factor's alpha times its base colour
    texture's alpha) at barycentrics (u, v) of primitive prim; the texture applies to triangles
    with texture coordinates only."""
    a = materials.opacity[m]
    t = materials.alpha_texture[m]
    if t >= 0 and 0 <= prim < shapes.faces.shape[0] and shapes.uv.shape[0] > 0:
        s, tv = _uv(shapes.uv, prim, u, v)
        a *= texture_lookup(materials.texels, materials.tex_offset, materials.tex_width,
                            materials.tex_height, materials.tex_wrap, t, s, tv)[0]
    return a


@njit(cache=True, _nrt=False, forceinline=True)
def mapped_normal(shapes, materials, m, prim, u, v, nx, ny, nz):
    """The shading normal (nx, ny, nz) (unit, on either side of the surface) bent by material
    m's tangent-space normal texture at barycentrics (u, v) of triangle prim, as glTF defines
    it: the texel's (2 c - 1) scaled by the material's normal scale in x and y, in the frame of
    the tangent (along +u), the bitangent (along +v, ptrace's v up, which is the texture's up)
    and the normal. The tangent frame comes from the triangle's texture coordinates, made
    orthogonal to the interpolated normal (a file's own tangents are not read). The bent
    normal is on the side the given one was on. Without a normal texture, texture coordinates
    or a well-defined tangent, the normal is returned as given."""
    t = materials.normal_texture[m]
    faces, vertices, normals, uv = shapes.faces, shapes.vertices, shapes.vertex_normals, shapes.uv
    if t < 0 or not 0 <= prim < faces.shape[0] or uv.shape[0] == 0:
        return nx, ny, nz
    a, b, c = faces[prim, 0], faces[prim, 1], faces[prim, 2]
    w = 1.0 - u - v
    # the interpolated normal, outward (as the file gives it), which the texture bends
    ox = w * normals[a, 0] + u * normals[b, 0] + v * normals[c, 0]
    oy = w * normals[a, 1] + u * normals[b, 1] + v * normals[c, 1]
    oz = w * normals[a, 2] + u * normals[b, 2] + v * normals[c, 2]
    length = math.sqrt(ox * ox + oy * oy + oz * oz)
    if not length > 0.0:
        return nx, ny, nz
    ox, oy, oz = ox / length, oy / length, oz / length
    e1x, e1y, e1z = (vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1],
                     vertices[b, 2] - vertices[a, 2])
    e2x, e2y, e2z = (vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1],
                     vertices[c, 2] - vertices[a, 2])
    du1, dv1 = uv[prim, 1, 0] - uv[prim, 0, 0], uv[prim, 1, 1] - uv[prim, 0, 1]
    du2, dv2 = uv[prim, 2, 0] - uv[prim, 0, 0], uv[prim, 2, 1] - uv[prim, 0, 1]
    det = du1 * dv2 - du2 * dv1
    if det == 0.0 or not math.isfinite(det):
        return nx, ny, nz
    # dP/du and dP/dv of the triangle (their common factor 1 / det only sets their lengths)
    tx, ty, tz = dv2 * e1x - dv1 * e2x, dv2 * e1y - dv1 * e2y, dv2 * e1z - dv1 * e2z
    bx, by, bz = du1 * e2x - du2 * e1x, du1 * e2y - du2 * e1y, du1 * e2z - du2 * e1z
    if det < 0.0:
        tx, ty, tz, bx, by, bz = -tx, -ty, -tz, -bx, -by, -bz
    d = tx * ox + ty * oy + tz * oz
    tx, ty, tz = tx - d * ox, ty - d * oy, tz - d * oz
    length = math.sqrt(tx * tx + ty * ty + tz * tz)
    if not length > 0.0:
        return nx, ny, nz
    tx, ty, tz = tx / length, ty / length, tz / length
    # the bitangent: o x t, turned to dP/dv's side (mirrored texture coordinates flip it)
    cx, cy, cz = oy * tz - oz * ty, oz * tx - ox * tz, ox * ty - oy * tx
    if cx * bx + cy * by + cz * bz < 0.0:
        cx, cy, cz = -cx, -cy, -cz
    s, tv = _uv(uv, prim, u, v)
    mr, mg, mb = texture_lookup(materials.texels, materials.tex_offset, materials.tex_width,
                                materials.tex_height, materials.tex_wrap, t, s, tv)
    scale = materials.normal_scale[m]
    mx, my, mz = (2.0 * mr - 1.0) * scale, (2.0 * mg - 1.0) * scale, 2.0 * mb - 1.0
    rx = mx * tx + my * cx + mz * ox
    ry = mx * ty + my * cy + mz * oy
    rz = mx * tz + my * cz + mz * oz
    length = math.sqrt(rx * rx + ry * ry + rz * rz)
    if not length > 0.0:
        return nx, ny, nz
    if nx * ox + ny * oy + nz * oz < 0.0:    # the given normal faces the surface's back
        length = -length
    return rx / length, ry / length, rz / length
