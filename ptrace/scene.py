"""The loaded scene: flat numpy arrays only. No scene graph survives loading."""
from dataclasses import dataclass, field

import numpy as np

import accel

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])   # of linear RGB (Rec. 709 / sRGB primaries)

# BSDF kinds (Materials.kind). The codes index BSDF_NAMES.
(DIFFUSE, EMISSION, MIRROR, GLASS, REFRACTION, MICROFACET, GLOSSY, GLTF_PBR, PLASTIC,
 ROUGH_PLASTIC) = range(10)
BSDF_NAMES = ("diffuse", "emission", "mirror", "glass", "refraction", "microfacet", "glossy",
              "gltf_pbr", "plastic", "roughplastic")

# Materials.cutoff of a glTF BLEND material (ptrace.cutouts): rays pass with probability 1 - alpha
BLEND_CUT = -1.0

# Light kinds (Lights.kind). The codes index KIND_NAMES; LIGHT_NAMES are those a scene file
# may name. ENVIRONMENT is added by Scene.with_environment (the course's -e), never by a file.
AMBIENT, DIRECTIONAL, POINT, AREA, SPOT, ENVIRONMENT = range(6)
LIGHT_NAMES = ("ambient", "directional", "point", "area", "spot")
KIND_NAMES = LIGHT_NAMES + ("environment",)
# What a point or spot light's radiance means (Lights.model).
COURSE, PHYSICAL = range(2)
MODEL_NAMES = ("course", "physical")
# the Fresnel reflectance of glass (Materials.fresnel): SCHLICK, the course's approximation;
# EXACT, a smooth dielectric's (Mitsuba's dielectric)
SCHLICK, EXACT = 0.0, 1.0
# how a PHYSICAL spot falls off between its cones (Lights.falloff): SMOOTH, glTF's (the square
# of a ramp linear in the cosine); ANGULAR, Mitsuba's (linear in the angle)
SMOOTH, ANGULAR = range(2)


@dataclass(eq=False)
class Materials:
    """M materials as parallel arrays. Which fields matter depends on kind:

    diffuse: albedo; emission: emission; mirror: albedo (reflectance);
    glass: albedo (reflectance), transmittance, ior; refraction: transmittance, ior;
    microfacet: alpha, eta, k, and specular, a factor on its Fresnel reflectance (Mitsuba's
    specular_reflectance beside eta and k; (1, 1, 1) where a record or the arrays leave it
    out); glossy (not the course's: a diffuse base under a glossy
    dielectric coat, for mesh files' plastics): albedo (the base), specular (the coat's
    reflectance at normal incidence), alpha; gltf_pbr (glTF's metallic-roughness BRDF,
    ptrace.gltf_brdf, for glTF files): albedo (the base colour), metallic, alpha (roughness^2),
    and emission, which it adds to what it reflects (a gltf_pbr of non-zero emission is an
    emitter too: emits()); plastic (Mitsuba's smooth plastic, ptrace.plastic: a smooth
    dielectric coat over a diffuse base): albedo (the base's diffuse_reflectance), specular
    (the coat's specular_reflectance), ior (the coat's index over the outside's, eta), and in
    eta the three numbers its functions read without ior: (eta, the coat's diffuse Fresnel
    reflectance from inside fdr_int, the probability weight of its specular lobe), in k[:, 0]
    1 for Mitsuba's `nonlinear` (else 0); roughplastic (Mitsuba's roughplastic: a microfacet
    dielectric coat over a diffuse base): as plastic, but with eta's second number the coat's
    internal reflectance, alpha the coat's roughness, k[:, 1] its distribution (0 Beckmann,
    1 GGX), and the coat's transmittance from outside at cos theta = j / (n - 1), j = 0 .. n-1,
    in specular's columns 3 .. 3 + n - 1 (a record's `table`; Materials.from_records widens
    every material's specular row when one has a table, to n = ptrace.bsdf.TABLE).

    albedo_texture, emission_texture and roughness_texture index Scene.textures (-1: none):
    a texture multiplies albedo or emission by its colour at the hit's UV, and a roughness
    texture multiplies alpha by its green channel squared and metallic by its blue channel
    (glTF's metallicRoughness texture: roughness is G, alpha = roughness^2, metallic is B).
    File materials (mesh files) use them; the course's scenes have none.

    opacity, alpha_texture and cutoff are glTF's alpha (ptrace.cutouts): the alpha is opacity
    times alpha_texture's value (-1: none), and cutoff says what it does: 0 nothing (opaque),
    c in (0, 1] cuts the surface out where alpha < c (MASK), -1 makes it pass rays with
    probability 1 - alpha (BLEND). normal_texture (-1: none) is a tangent-space normal texture,
    its x and y scaled by normal_scale (ptrace.textures.mapped_normal).

    fresnel says how a glass reflects: SCHLICK (the course's) or EXACT (a smooth dielectric's
    Fresnel reflectance, as Mitsuba's dielectric). A scene's glass reflects one way: its glass
    kernel is made for one (ptrace.kernel.wavefront.exact_glass). An EXACT glass whose k[m, 0]
    is ptrace.bsdf's THIN_GLASS is a thin slab of it (Mitsuba's thindielectric).
    """
    kind: np.ndarray            # (M,) int32
    albedo: np.ndarray          # (M, 3)
    transmittance: np.ndarray   # (M, 3)
    emission: np.ndarray        # (M, 3)
    ior: np.ndarray             # (M,)
    roughness: np.ndarray       # (M,) parsed, unused like the course
    alpha: np.ndarray           # (M,)
    eta: np.ndarray             # (M, 3)
    k: np.ndarray               # (M, 3)
    names: tuple = ()
    specular: np.ndarray = None            # (M, 3) (or (M, 3 + n): roughplastic's table)
    albedo_texture: np.ndarray = None      # (M,) int32, -1 for none
    emission_texture: np.ndarray = None    # (M,) int32
    roughness_texture: np.ndarray = None   # (M,) int32
    metallic: np.ndarray = None            # (M,), gltf_pbr only
    opacity: np.ndarray = None             # (M,), 1 for none
    alpha_texture: np.ndarray = None       # (M,) int32
    cutoff: np.ndarray = None              # (M,), 0 for opaque
    normal_texture: np.ndarray = None      # (M,) int32
    normal_scale: np.ndarray = None        # (M,)
    fresnel: np.ndarray = None             # (M,), glass only: SCHLICK or EXACT

    def __post_init__(self):
        m = len(self.kind)
        if self.specular is None:   # a microfacet's reflectance factor: 1 unless it is given
            self.specular = np.zeros((m, 3))
            self.specular[np.asarray(self.kind) == MICROFACET] = 1.0
        for name, default in OPTIONAL_FIELDS.items():
            if getattr(self, name) is None:
                shape = (m, 3) if name in RGB_FIELDS else m
                setattr(self, name, np.full(shape, default,
                                            dtype=np.int32 if name in TEXTURE_FIELDS else None))
        glass = np.asarray(self.fresnel)[np.asarray(self.kind) == GLASS]
        if glass.size and (glass != glass[0]).any():
            raise ValueError("a scene's glass materials must all reflect one way (SCHLICK or "
                             "EXACT)")

    def __len__(self):
        return self.kind.shape[0]

    def emits(self):
        """(M,) bool: the materials that emit light: every emission material, and a gltf_pbr
        one whose emission is not zero (it reflects as well)."""
        glowing = np.asarray(self.emission).reshape(-1, 3).max(axis=1, initial=0.0) > 0.0
        return (self.kind == EMISSION) | ((self.kind == GLTF_PBR) & glowing)

    @classmethod
    def from_records(cls, records):
        """Build from a list of dicts with a 'kind' and any of the fields above (a field a
        record leaves out takes its default in RGB_FIELDS, NUMBER_FIELDS or TEXTURE_FIELDS)."""
        m = len(records)
        records = [dict(r, specular=MICROFACET_SPECULAR)
                   if r["kind"] == MICROFACET and "specular" not in r else r for r in records]
        column = lambda key, default, dtype, shape: np.array(
            [r.get(key, default) for r in records], dtype=dtype).reshape(shape)
        tables = [r["table"] for r in records if "table" in r]
        if tables:      # roughplastic's tables, after the specular colour
            width = len(tables[0])
            rows = [np.concatenate([r.get("specular", RGB_FIELDS["specular"]),
                                    r.get("table", np.zeros(width))]) for r in records]
            return cls(
                kind=np.array([r["kind"] for r in records], dtype=np.int32).reshape(m),
                names=tuple(r.get("name", "") for r in records),
                **{key: column(key, value, np.float64, (m, 3))
                   for key, value in RGB_FIELDS.items() if key != "specular"},
                specular=np.array(rows, dtype=np.float64).reshape(m, 3 + width),
                **{key: column(key, value, np.float64, m) for key, value in NUMBER_FIELDS.items()},
                **{key: column(key, -1, np.int32, m) for key in TEXTURE_FIELDS},
            )
        return cls(
            kind=np.array([r["kind"] for r in records], dtype=np.int32).reshape(m),
            names=tuple(r.get("name", "") for r in records),
            **{key: column(key, value, np.float64, (m, 3)) for key, value in RGB_FIELDS.items()},
            **{key: column(key, value, np.float64, m) for key, value in NUMBER_FIELDS.items()},
            **{key: column(key, -1, np.int32, m) for key in TEXTURE_FIELDS},
        )


# Materials' fields and their defaults: per channel, numbers, and texture indices (-1: none)
RGB_FIELDS = {"albedo": (0.5, 0.5, 0.5), "transmittance": (0.0, 0.0, 0.0),
              "emission": (0.0, 0.0, 0.0), "eta": (0.0, 0.0, 0.0), "k": (0.0, 0.0, 0.0),
              "specular": (0.0, 0.0, 0.0)}
NUMBER_FIELDS = {"ior": 1.0, "roughness": 0.0, "alpha": 0.0, "metallic": 0.0, "opacity": 1.0,
                 "cutoff": 0.0, "normal_scale": 1.0, "fresnel": SCHLICK}
TEXTURE_FIELDS = ("albedo_texture", "emission_texture", "roughness_texture", "alpha_texture",
                  "normal_texture")
MICROFACET_SPECULAR = (1.0, 1.0, 1.0)   # a microfacet's specular where its record has none
# the fields Materials may be built without, and what they then hold (per material)
OPTIONAL_FIELDS = {"specular": 0.0, "metallic": 0.0, "opacity": 1.0, "cutoff": 0.0,
                   "normal_scale": 1.0, "fresnel": SCHLICK, **{key: -1 for key in TEXTURE_FIELDS}}


# Texture wrap modes (Textures.wrap), glTF's three: repeat, clamp to edge, mirrored repeat.
REPEAT, CLAMP, MIRROR_REPEAT = range(3)
WRAP_NAMES = ("repeat", "clamp", "mirror")


@dataclass(eq=False)
class Textures:
    """T image textures packed into one array of linear RGB texels: texture i is the rows
    offset[i] .. offset[i] + width[i] * height[i] of texels, row by row from the image's top
    row. wrap is (T, 2): the mode along u and along v."""
    texels: np.ndarray      # (N, 3) float32, linear
    offset: np.ndarray      # (T,) int64
    width: np.ndarray       # (T,) int64
    height: np.ndarray      # (T,) int64
    wrap: np.ndarray        # (T, 2) int64
    names: tuple = ()

    def __len__(self):
        return self.offset.shape[0]

    @classmethod
    def empty(cls):
        return cls(np.zeros((0, 3), np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64),
                   np.zeros(0, np.int64), np.zeros((0, 2), np.int64))

    @classmethod
    def from_images(cls, images, wraps=None, names=()):
        """From a list of (H, W, 3) linear float arrays (top row first). A single float32
        texture is not copied: the texels share its memory."""
        if not images:
            return cls.empty()
        heights = np.array([image.shape[0] for image in images], dtype=np.int64)
        widths = np.array([image.shape[1] for image in images], dtype=np.int64)
        sizes = heights * widths
        offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        if len(images) == 1:      # its texels as they are (a view when float32 already)
            texels = np.ascontiguousarray(np.asarray(images[0], np.float32).reshape(-1, 3))
        else:
            texels = np.concatenate([np.asarray(image, np.float32).reshape(-1, 3)
                                     for image in images])
        wrap = np.zeros((len(images), 2), np.int64) if wraps is None \
            else np.array(wraps, dtype=np.int64).reshape(-1, 2)
        return cls(texels, offset, widths, heights, wrap, tuple(names))


@dataclass(eq=False)
class Lights:
    """L lights as parallel arrays (docs/course.md#lights has the placement rules).

    point/spot: position; directional: direction (unit, toward the light);
    area: position (centre), direction (unit facing normal), edge_x, edge_y (unnormalised), area;
    ambient: radiance only (the upper hemisphere about world +Y).

    model says what a point or spot light means (MODEL_NAMES): COURSE, the course's (a point
    light's radiance arrives undimmed at any distance; a spot light gives nothing, as in the
    course's stub), or PHYSICAL, what glTF means (radiance is the intensity, divided by the
    squared distance; a spot's direction is its axis, pointing away from the light, and it
    falls off from 1 inside cos_inner to 0 outside cos_outer, smoothly, as glTF's
    KHR_lights_punctual suggests, or, where its falloff is ANGULAR, linearly in the angle from
    the axis, as Mitsuba's spot does). A scene's spots all fall off one way: the shading kernels
    are made for one (ptrace.kernel.wavefront.angular_spots).
    """
    kind: np.ndarray        # (L,) int32
    radiance: np.ndarray    # (L, 3)
    position: np.ndarray    # (L, 3)
    direction: np.ndarray   # (L, 3)
    edge_x: np.ndarray      # (L, 3)
    edge_y: np.ndarray      # (L, 3)
    area: np.ndarray        # (L,)
    model: np.ndarray = None       # (L,) int32: COURSE or PHYSICAL
    cos_inner: np.ndarray = None   # (L,) spot cone, PHYSICAL model
    cos_outer: np.ndarray = None   # (L,)
    falloff: np.ndarray = None     # (L,) int32: SMOOTH or ANGULAR, a spot's between its cones

    def __post_init__(self):
        n = len(self.kind)
        if self.model is None:
            self.model = np.full(n, COURSE, dtype=np.int32)
        if self.cos_inner is None:
            self.cos_inner = np.ones(n)
        if self.cos_outer is None:
            self.cos_outer = np.ones(n)
        if self.falloff is None:
            self.falloff = np.full(n, SMOOTH, dtype=np.int32)
        spots = np.asarray(self.falloff)[np.asarray(self.kind) == SPOT]
        if spots.size and (spots != spots[0]).any():
            raise ValueError("a scene's spot lights must all fall off one way (SMOOTH or "
                             "ANGULAR)")

    def __len__(self):
        return self.kind.shape[0]

    @classmethod
    def from_records(cls, records):
        n = len(records)
        vec = lambda key: np.array([r.get(key, (0.0, 0.0, 0.0)) for r in records],
                                   dtype=np.float64).reshape(n, 3)
        return cls(
            kind=np.array([r["kind"] for r in records], dtype=np.int32).reshape(n),
            radiance=vec("radiance"), position=vec("position"), direction=vec("direction"),
            edge_x=vec("edge_x"), edge_y=vec("edge_y"),
            area=np.array([r.get("area", 0.0) for r in records], dtype=np.float64).reshape(n),
            model=np.array([r.get("model", COURSE) for r in records], dtype=np.int32).reshape(n),
            cos_inner=np.array([r.get("cos_inner", 1.0) for r in records],
                               dtype=np.float64).reshape(n),
            cos_outer=np.array([r.get("cos_outer", 1.0) for r in records],
                               dtype=np.float64).reshape(n),
            falloff=np.array([r.get("falloff", SMOOTH) for r in records],
                             dtype=np.int32).reshape(n),
        )

    def counts(self):
        """{"area": 1, ...}: how many lights of each kind."""
        out = {}
        for code in self.kind:
            name = KIND_NAMES[code]
            out[name] = out.get(name, 0) + 1
        return out


@dataclass(eq=False)
class CameraSpec:
    """What the scene file says about its camera (the course's orbit rule uses view_point only).

    view_point: the camera node's world matrix applied to (0, 0, -1, 1), one unit in front of the
    camera; position: the node's world position (kept for reference, the course ignores it);
    hfov, vfov: degrees as the file gives them (vfov derived from the aspect ratio if absent);
    znear, zfar: the camera rays' t interval.
    """
    view_point: np.ndarray
    position: np.ndarray
    hfov: float = 50.0
    vfov: float = 35.0
    znear: float = 0.001
    zfar: float = 1000.0


@dataclass(frozen=True, eq=False)
class FileCamera:
    """A camera a mesh file carries (a glTF camera on a node of the file's scene), as the file
    gives it: kind "perspective" or "orthographic"; position and camera_to_world (columns
    right, up, backward: unit and at right angles) from the node's world matrix; yfov (the
    vertical field of view, degrees) and aspect (width / height, None when not given) of a
    perspective camera; xmag, ymag (half the view's width and height) of an orthographic one;
    znear, zfar (zfar None: no far plane)."""
    name: str
    node: int
    kind: str
    position: np.ndarray
    camera_to_world: np.ndarray
    znear: float
    zfar: float = None
    yfov: float = None
    aspect: float = None
    xmag: float = None
    ymag: float = None


@dataclass(eq=False)
class Scene:
    path: str
    geometry: accel.Geometry
    # (V, 3) unit, area-weighted (docs/course.md#meshes); 0 where undefined
    vertex_normals: np.ndarray
    material_index: np.ndarray      # (F + S,) int32 into materials
    materials: Materials
    lights: Lights
    camera: CameraSpec = None
    notes: list = field(default_factory=list)   # what the loader decided (e.g. defaults given)
    environment: object = None      # a ptrace.environment.Environment, with an ENVIRONMENT light
    # file materials (mesh files): texture coordinates of each triangle's corners, (F, 3, 2)
    # with v up (OBJ's convention), or (0, 3, 2) when no material uses a texture; vertex
    # colours (V, 3) that multiply the albedo, or (0, 3); the textures materials index
    uv: np.ndarray = None
    vertex_colours: np.ndarray = None
    textures: Textures = None
    file_cameras: tuple = ()        # FileCamera records of the file's own cameras (glTF)
    # what the file asks of a render where the caller does not say (a Mitsuba scene's film,
    # sampler and integrator): any of resolution (W, H), spp, max_depth, rr_depth, hide_emitters
    render_defaults: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.uv is None:
            self.uv = np.zeros((0, 3, 2))
        if self.vertex_colours is None:
            self.vertex_colours = np.zeros((0, 3))
        if self.textures is None:
            self.textures = Textures.empty()

    def with_environment(self, environment):
        """This scene lit also by an environment (the course's -e): one more light, of kind
        ENVIRONMENT, sampled by the image's luminance and seen by every ray that escapes. It
        replaces an environment the scene had."""
        import dataclasses
        keep = self.lights.kind != ENVIRONMENT
        lights = Lights(**{f.name: getattr(self.lights, f.name)[keep]
                           for f in dataclasses.fields(Lights)})
        one = Lights.from_records([{"kind": ENVIRONMENT, "radiance": (1.0, 1.0, 1.0)}])
        joined = Lights(**{f.name: np.concatenate([getattr(lights, f.name), getattr(one, f.name)])
                           for f in dataclasses.fields(Lights)})
        return dataclasses.replace(self, lights=joined, environment=environment)

    @property
    def triangle_count(self):
        return self.geometry.triangle_count

    @property
    def sphere_count(self):
        return self.geometry.sphere_count

    def bsdf_kinds(self):
        """Sorted names of the BSDF kinds used by at least one primitive."""
        used = np.unique(self.materials.kind[np.unique(self.material_index)]) \
            if len(self.material_index) else []
        return sorted(BSDF_NAMES[k] for k in used)

    def bounds(self):
        """(lower, upper) over meshes and spheres (lights excluded), or None if empty."""
        return self.geometry.bounds()


def area_weighted_normals(vertices, faces):
    """Per-vertex sum of cross(p_j - p_i, p_k - p_i) over incident faces, normalised.

    docs/course.md#meshes: file normals are ignored and these are recomputed. A vertex whose sum
    is zero (unused, or only in zero-area faces) gets a zero normal.
    """
    normals = np.zeros_like(vertices)
    if len(faces):
        # twice the area, same for every corner; a chunk of faces at a time
        face_normals = np.empty((len(faces), 3), dtype=np.result_type(vertices, np.float64))
        for first in range(0, len(faces), 1 << 16):
            p0, p1, p2 = (vertices[faces[first:first + (1 << 16), i]] for i in range(3))
            face_normals[first:first + len(p0)] = np.cross(p1 - p0, p2 - p0)
        for corner in range(3):
            np.add.at(normals, faces[:, corner], face_normals)
    length = np.linalg.norm(normals, axis=1)
    nonzero = length > 0
    normals[nonzero] /= length[nonzero, None]
    return normals
