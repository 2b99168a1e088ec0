"""Mitsuba BSDFs and bitmap textures as ptrace material records (docs/usage.md's table "Mitsuba
scenes" says what each becomes).

A BSDF ptrace renders as Mitsuba does becomes its kind with Mitsuba's values (plastic its own
kind, PLASTIC); one it renders with a different but close model (the Ashikhmin-Shirley glossy
model for roughplastic, Beckmann for GGX) gets one note per kind; one that would give a wrong
image (blends, bump and normal maps, rough glass of visible roughness, media) is refused in
one line naming the file and the element.
"""
import math

import numpy as np

from ..bsdf import THIN_GLASS
from ..budget import BudgetError
from ..errors import SceneError
from ..scene import (
    BLEND_CUT,
    CLAMP,
    DIFFUSE,
    EXACT,
    GLASS,
    GLTF_PBR,
    MICROFACET,
    MIRROR,
    MIRROR_REPEAT,
    PLASTIC,
    REPEAT,
    ROUGH_PLASTIC,
)
from .materials import MIN_ALPHA, conductor_from_colour, read_image_file
from .mitsuba_spectra import CONDUCTORS, IOR
from .mitsuba_xml import Colour, Plugin

# Mitsuba's luminance weights of linear RGB (its RGB variants' mean of a bitmap)
LUMINANCE = (0.212671, 0.715160, 0.072169)
WRAP = {"repeat": REPEAT, "mirror": MIRROR_REPEAT, "clamp": CLAMP}
# BSDFs that Mitsuba's evaluate as black from behind unless inside a twosided
ONE_SIDED = ("diffuse", "plastic", "roughplastic", "conductor", "roughconductor", "principled")
REFUSED = {"blendbsdf": "a blend of two BSDFs", "bumpmap": "a bump map",
           "normalmap": "a normal map", "hair": "hair", "measured": "measured data",
           "pplastic": "polarised plastic", "polarizer": "a polariser", "retarder": "a retarder",
           "circular": "a polariser", "null": "a null BSDF (for media)"}
CHECKER = 256             # texels a side of a baked checkerboard
# a filter_type nearest bitmap is stored with each texel repeated up to NEAREST_REPEAT times a
# side (nearest_texels), as long as the copy has at most NEAREST_TEXELS texels
NEAREST_REPEAT, NEAREST_TEXELS = 16, 1 << 20
# a roughdielectric up to this alpha is drawn smooth (noted), a rougher one refused: Mitsuba's
# rough glass renders brighter than its smooth glass from some alpha below 0.02
# (benchmarks/results/mitsuba_scenes.md)
ROUGH_GLASS_LIMIT = 0.01
# principled's parameters that ptrace's glTF BRDF lacks, and their Mitsuba defaults
PRINCIPLED_EXTRAS = {"anisotropic": 0.0, "sheen": 0.0, "sheen_tint": 0.0, "clearcoat": 0.0,
                     "clearcoat_gloss": 0.0, "spec_tint": 0.0, "spec_trans": 0.0,
                     "flatness": 0.0}


class Materials:
    """The material records of a scene: record(bsdf Plugin or None) gives an index."""

    def __init__(self, reader, pool, notes):
        self.reader, self.pool, self.notes = reader, pool, notes
        self.records, self._index = [], {}
        self.textured = False
        self.uv_transforms = {}     # material index -> 3 x 3 transform of Mitsuba's (u, v)
        self.sided = False      # reading the BSDF inside a twosided
        self.one_sided = set()  # indices of the materials Mitsuba's are black from behind
        self.rough_glass = []   # the roughdielectric BSDFs drawn smooth
        self._tables = {}       # (alpha, eta, ggx) -> a roughplastic's rough_coat_tables

    def index(self, bsdf):
        key = id(bsdf) if bsdf is not None else None
        if key not in self._index:
            self._uv = []
            record = {"kind": DIFFUSE, "albedo": (0.5, 0.5, 0.5), "name": "default"} \
                if bsdf is None else self.record(bsdf)
            if any(not np.array_equal(m, self._uv[0]) for m in self._uv[1:]):
                bsdf.fail("its textures transform the texture coordinates differently (ptrace "
                          "gives a material one transform)")
            self._index[key] = len(self.records)
            if bsdf is None or bsdf.type in ONE_SIDED:
                self.one_sided.add(self._index[key])
            if self._uv and not np.array_equal(self._uv[0], np.eye(3)):
                self.uv_transforms[self._index[key]] = self._uv[0]
            self.records.append(record)
        return self._index[key]

    def textures(self, index):
        """Whether material `index` uses a texture."""
        return any(self.records[index].get(k, -1) >= 0 for k in ("albedo_texture",
                                                                 "alpha_texture"))

    def untextured(self, index, where):
        """The index of material `index` with its textures replaced by their mean colour, for
        a shape without texture coordinates (noted once per kind); `index` if it has none."""
        record = self.records[index]
        if all(record.get(k, -1) < 0 for k in ("albedo_texture", "alpha_texture")):
            return index
        if ("untextured", index) not in self._index:
            flat = {k: v for k, v in record.items() if k not in ("albedo_texture",
                                                                 "alpha_texture")}
            if record.get("albedo_texture", -1) >= 0:
                flat["albedo"] = tuple(float(c) for c in self.pool.mean(record["albedo_texture"]))
            if record.get("alpha_texture", -1) >= 0:
                flat["opacity"] = float(self.pool.mean(record["alpha_texture"])[0])
            self._index[("untextured", index)] = len(self.records)
            self.records.append(flat)
            self.notes.append(f"{where}: no texture coordinates: its textures drawn as their "
                              f"mean colour")
        return self._index[("untextured", index)]

    def emitter(self, radiance):
        """The index of a new emission material of this radiance."""
        from ..scene import EMISSION
        self.records.append({"kind": EMISSION, "emission": tuple(radiance), "name": "emitter"})
        return len(self.records) - 1

    def black(self):
        """The index of a black diffuse material: the back of a one-sided surface."""
        if "black" not in self._index:
            self._index["black"] = len(self.records)
            self.records.append({"kind": DIFFUSE, "albedo": (0.0, 0.0, 0.0), "name": "back"})
        return self._index["black"]

    def glowing(self, index, radiance):
        """The index of the material an area emitter's front gets: Mitsuba's front emits and
        also reflects with the shape's BSDF. A black diffuse one (the usual lamp) is an
        emission material, exact; another diffuse one (Mitsuba's default BSDF too) becomes
        glTF's BRDF of roughness 1, not metallic, of its albedo and that emission, which
        reflects about as a Lambertian surface does (its 4 % dielectric coat aside); None for
        any other BSDF (its front does not reflect: the caller's note)."""
        record = self.records[index]
        if record["kind"] != DIFFUSE:
            return None
        if record.get("albedo_texture", -1) < 0 and max(record["albedo"]) <= 0:
            return self.emitter(radiance)
        key = ("glowing", index, tuple(radiance))
        if key not in self._index:
            self._index[key] = len(self.records)
            glow = {k: v for k, v in record.items() if k != "kind"}
            glow.update(kind=GLTF_PBR, metallic=0.0, alpha=1.0, emission=tuple(radiance),
                        name="emitter")
            self.records.append(glow)
            if index in self.uv_transforms:
                self.uv_transforms[self._index[key]] = self.uv_transforms[index]
            self.notes.append("an area emitter on a diffuse BSDF: its front emits and "
                              "reflects as glTF's BRDF of roughness 1 (the diffuse albedo "
                              "under a 4 % dielectric coat), close to, not exactly, Mitsuba's "
                              "Lambertian reflection")
        return self._index[key]

    def note(self, plugin, text):
        self.notes.append(f"<bsdf type=\"{plugin.type}\">: {text}")

    def record(self, bsdf):
        """The record of one <bsdf>."""
        kind = bsdf.type
        if kind in REFUSED:
            bsdf.fail(f"{REFUSED[kind]} ({kind}) is not supported by ptrace: the image would be "
                      f"wrong")
        reader = getattr(self, "_" + kind, None)
        if reader is None:
            bsdf.fail(f"unknown or unsupported BSDF type {kind!r}")
        record = reader(bsdf)
        record.setdefault("name", bsdf.id or kind)
        for name in bsdf.unread():
            self.note(bsdf, f"parameter {name!r} ignored")
        return record

    def _nested(self, bsdf):
        inner = [p for p in bsdf.children if p.tag == "bsdf"] + \
            [v for v in bsdf.params.values() if isinstance(v, Plugin) and v.tag == "bsdf"]
        if not inner:
            bsdf.fail("has no nested <bsdf>")
        return inner

    def _twosided(self, bsdf):
        inner = self._nested(bsdf)
        self.sided = True
        if len(inner) > 1 and inner[0] is not inner[1]:
            self.note(bsdf, "two different sides: ptrace's surfaces have one material, the "
                            "front one is used on both")
        bsdf._read.update(bsdf.params)
        try:
            return dict(self.record(inner[0]))
        finally:
            self.sided = False

    def _mask(self, bsdf):
        inner = self._nested(bsdf)
        record = dict(self.record(inner[0]))
        opacity = bsdf.colour("opacity", Colour((0.5,) * 3))
        bsdf._read.update(k for k, v in bsdf.params.items() if isinstance(v, Plugin)
                          and v.tag == "bsdf")
        if isinstance(opacity, Plugin):
            record.update(opacity=1.0, alpha_texture=self.texture(opacity, raw_default=False))
        else:
            record["opacity"] = float(np.mean(opacity))
        record["cutoff"] = BLEND_CUT
        self.note(bsdf, "shadow rays pass through it as other rays do, with probability 1 - "
                        "opacity; Mitsuba's path integrator stops them, so its shadows behind "
                        "a mask are darker")
        return record

    def _diffuse(self, bsdf):
        if not self.sided:
            self.note(bsdf, "outside a twosided: one-sided, as Mitsuba's: an open shape of "
                            "it is black from behind (a black copy of it 0.0001 of its size "
                            "behind); a closed one is seen from outside only")
        record = {"kind": DIFFUSE}
        self._albedo(bsdf, "reflectance", record, (0.5, 0.5, 0.5))
        return record

    def _albedo(self, bsdf, name, record, default):
        value = bsdf.colour(name, Colour(default))
        if isinstance(value, Plugin):
            record.update(albedo=(1.0, 1.0, 1.0), albedo_texture=self.texture(value))
        else:
            record["albedo"] = self._bounded(bsdf, name, value)

    def _bounded(self, bsdf, name, value, high=1.0):
        if isinstance(value, Plugin):
            bsdf.fail(f"a texture for {name!r} is not supported (only a colour)")
        if min(value) < 0 or high is not None and max(value) > high:
            bsdf.fail(f"{name} {' '.join(f'{v:g}' for v in value)} is out of range [0, {high}]")
        return tuple(value)

    def _ior(self, bsdf, name, default):
        value = bsdf.get(name, default)
        if isinstance(value, str):
            if value.lower() not in IOR:
                bsdf.fail(f"{name} {value!r} is not one of Mitsuba's named indices of "
                          f"refraction ({', '.join(IOR)})")
            return IOR[value.lower()]
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not value > 0:
            bsdf.fail(f"{name} must be a positive number or a named index of refraction")
        return float(value)

    def _alpha(self, bsdf):
        distribution = bsdf.string("distribution", "beckmann")
        if distribution not in ("beckmann", "ggx"):
            bsdf.fail(f"distribution {distribution!r} is neither beckmann nor ggx")
        if distribution == "ggx":
            self.note(bsdf, "GGX rendered as Beckmann of the same alpha (ptrace's microfacet "
                            "distribution)")
        bsdf.boolean("sample_visible", True)
        if bsdf.has("alpha_u") or bsdf.has("alpha_v"):
            au, av = bsdf.float("alpha_u", 0.1), bsdf.float("alpha_v", 0.1)
            if au != av:
                self.note(bsdf, "anisotropic roughness rendered isotropic (alpha "
                                "sqrt(alpha_u alpha_v))")
            alpha = math.sqrt(au * av)
        else:
            alpha = bsdf.float("alpha", 0.1)
        if not alpha >= 0:
            bsdf.fail(f"alpha {alpha:g} is negative")
        return max(alpha, MIN_ALPHA)

    def _conductor(self, bsdf, rough=False):
        alpha = self._alpha(bsdf) if rough else MIN_ALPHA
        reflectance = self._bounded(bsdf, "specular_reflectance",
                                    bsdf.colour("specular_reflectance", Colour((1.0,) * 3)))
        if bsdf.has("eta") or bsdf.has("k"):
            eta = self._bounded(bsdf, "eta", bsdf.colour("eta", Colour((0.0,) * 3)), None)
            k = self._bounded(bsdf, "k", bsdf.colour("k", Colour((1.0,) * 3)), None)
        else:
            name = bsdf.string("material", "none")
            if name != "none" and name not in CONDUCTORS:
                bsdf.fail(f"material {name!r} is not one of Mitsuba's named conductors")
            if name == "none":      # Fresnel 1: the reflectance alone
                if not rough:
                    return {"kind": MIRROR, "albedo": reflectance}
                eta, k = conductor_from_colour(reflectance)
                return {"kind": MICROFACET, "alpha": alpha, "eta": tuple(eta), "k": tuple(k)}
            eta, k = CONDUCTORS[name]
        if not rough:
            self.note(bsdf, f"a smooth conductor with Fresnel: Beckmann alpha {MIN_ALPHA} "
                            f"(ptrace's mirror has no Fresnel)")
        return {"kind": MICROFACET, "alpha": alpha, "eta": tuple(eta), "k": tuple(k),
                "specular": tuple(reflectance)}   # (a factor on the Fresnel, as Mitsuba's)

    def _roughconductor(self, bsdf):
        return self._conductor(bsdf, rough=True)

    def _dielectric(self, bsdf, rough=False):
        ior = self._ior(bsdf, "int_ior", "bk7") / self._ior(bsdf, "ext_ior", "air")
        if rough:
            alpha = self._alpha(bsdf)
            if alpha > ROUGH_GLASS_LIMIT:
                bsdf.fail(f"rough glass (alpha {alpha:g}) is not supported by ptrace (its glass "
                          f"is smooth; up to alpha {ROUGH_GLASS_LIMIT} is drawn smooth)")
            self.note(bsdf, f"rough glass of alpha up to {ROUGH_GLASS_LIMIT} drawn smooth")
            self.rough_glass.append(bsdf)
        return {"kind": GLASS, "ior": ior, "fresnel": EXACT,
                "albedo": self._bounded(bsdf, "specular_reflectance", bsdf.colour(
                    "specular_reflectance", Colour((1.0,) * 3))),
                "transmittance": self._bounded(bsdf, "specular_transmittance", bsdf.colour(
                    "specular_transmittance", Colour((1.0,) * 3)))}

    def _roughdielectric(self, bsdf):
        return self._dielectric(bsdf, rough=True)

    def _thindielectric(self, bsdf):
        """A thin slab of glass (ptrace.bsdf's THIN_GLASS): an EXACT glass that reflects with
        the slab's reflectance at the angle met, else passes rays straight through; shadow
        rays stop at it, as in Mitsuba's path integrator."""
        ior = self._ior(bsdf, "int_ior", "bk7") / self._ior(bsdf, "ext_ior", "air")
        return {"kind": GLASS, "ior": ior, "fresnel": EXACT, "k": (THIN_GLASS, 0.0, 0.0),
                "albedo": self._bounded(bsdf, "specular_reflectance", bsdf.colour(
                    "specular_reflectance", Colour((1.0,) * 3))),
                "transmittance": self._bounded(bsdf, "specular_transmittance", bsdf.colour(
                    "specular_transmittance", Colour((1.0,) * 3)))}

    def _plastic(self, bsdf):
        """Mitsuba's smooth plastic as ptrace's PLASTIC (ptrace.bsdf's plastic_*), its
        parameters packed as ptrace.scene.Materials says."""
        eta = self._ior(bsdf, "int_ior", "polypropylene") / self._ior(bsdf, "ext_ior", "air")
        specular = self._bounded(bsdf, "specular_reflectance",
                                 bsdf.colour("specular_reflectance", Colour((1.0,) * 3)))
        nonlinear = bsdf.boolean("nonlinear", False)
        if not self.sided:
            self.note(bsdf, "outside a twosided: one-sided, as Mitsuba's: an open shape of "
                            "it is black from behind (a black copy of it 0.0001 of its size "
                            "behind); a closed one is seen from outside only")
        record = {"kind": PLASTIC, "ior": eta, "specular": specular}
        value = bsdf.colour("diffuse_reflectance", Colour((0.5,) * 3))
        self._albedo(bsdf, "diffuse_reflectance", record, (0.5, 0.5, 0.5))
        if isinstance(value, Plugin):    # Mitsuba's mean of a texture: (see texture_mean)
            diffuse_mean = self.texture_mean(value, record["albedo_texture"])
        else:
            diffuse_mean = float(np.mean(record["albedo"]))
        specular_mean = float(np.mean(specular))
        total = diffuse_mean + specular_mean
        weight = specular_mean / total if total > 0 else 0.5
        record["eta"] = (eta, fresnel_diffuse_reflectance(1.0 / eta), weight)
        record["k"] = (1.0 if nonlinear else 0.0, 0.0, 0.0)
        return record

    def texture_mean(self, texture, index):
        """What Mitsuba's RGB variants take as a texture's mean: a bitmap's mean luminance, a
        checkerboard's mean of its colours' channel means (its baked image's channel mean)."""
        mean = self.pool.mean(index)
        if texture.type == "bitmap":
            return float(np.dot(mean, LUMINANCE))
        return float(np.mean(mean))

    def _roughplastic(self, bsdf):
        """Mitsuba's roughplastic as ptrace's ROUGH_PLASTIC (ptrace.bsdf's rough_plastic_*):
        the plastic's record, the coat's roughness and distribution, and its tables (once per
        distinct alpha, eta and distribution of the scene)."""
        distribution = bsdf.string("distribution", "beckmann")
        if distribution not in ("beckmann", "ggx"):
            bsdf.fail(f"distribution {distribution!r} is neither beckmann nor ggx")
        bsdf.boolean("sample_visible", True)
        if bsdf.has("alpha_u") or bsdf.has("alpha_v"):
            alpha = bsdf.float("alpha_u", 0.1)
            if bsdf.float("alpha_v", 0.1) != alpha:
                bsdf.fail("anisotropic roughness (alpha_u != alpha_v) is not supported on a "
                          "roughplastic (nor by Mitsuba's)")
        else:
            alpha = bsdf.float("alpha", 0.1)
        if not alpha >= 0:
            bsdf.fail(f"alpha {alpha:g} is negative")
        alpha = max(alpha, MIN_ALPHA)
        record = self._plastic(bsdf)
        eta = record["ior"]
        if eta == 1.0:
            bsdf.fail("int_ior and ext_ior must differ (as Mitsuba requires)")
        ggx = distribution == "ggx"
        key = (alpha, eta, ggx)
        if key not in self._tables:
            self._tables[key] = rough_coat_tables(alpha, eta, ggx)
        table, internal = self._tables[key]
        weight = record["eta"][2]
        record.update(kind=ROUGH_PLASTIC, alpha=alpha, eta=(eta, internal, weight),
                      k=(record["k"][0], 1.0 if ggx else 0.0, 0.0), table=tuple(table))
        return record

    def _principled(self, bsdf):
        roughness = bsdf.float("roughness", 0.5)
        metallic = bsdf.float("metallic", 0.0)
        for name, value in (("roughness", roughness), ("metallic", metallic)):
            if not 0 <= value <= 1:
                bsdf.fail(f"{name} {value:g} is out of range [0, 1]")
        record = {"kind": GLTF_PBR, "metallic": metallic,
                  "alpha": max(roughness * roughness, MIN_ALPHA ** 2)}
        self._albedo(bsdf, "base_color", record, (0.5, 0.5, 0.5))
        specular = bsdf.float("specular", 0.5)
        if bsdf.has("eta"):
            bsdf.float("eta")
            self.note(bsdf, "eta ignored: glTF's dielectric reflects as ior 1.5 does")
        if abs(specular - 0.5) > 1e-6:
            self.note(bsdf, "specular other than 0.5 ignored: glTF's dielectric reflects 0.04")
        extras = [name for name, default in PRINCIPLED_EXTRAS.items()
                  if bsdf.float(name, default) != default]
        if "spec_trans" in extras:
            bsdf.fail("spec_trans (transmission) is not supported on a principled BSDF")
        if extras:
            self.note(bsdf, f"{', '.join(extras)} ignored (glTF's metallic-roughness BRDF "
                            f"lacks them)")
        return record

    def texture(self, texture, raw_default=False):
        """The pool index of a <texture type="bitmap"> or "checkerboard"."""
        if texture.type not in ("bitmap", "checkerboard"):
            texture.fail(f"texture type {texture.type!r} is not supported (only bitmap and "
                         f"checkerboard)")
        self._uv.append(uv_transform(texture))
        self.textured = True
        if texture.type == "checkerboard":
            return self._checkerboard(texture)
        name = texture.string("filename")
        if name is None:
            texture.fail("has no filename")
        path = self.reader.resolve(texture, name)
        wrap = texture.string("wrap_mode", "repeat")
        if wrap not in WRAP:
            texture.fail(f"wrap_mode {wrap!r} is none of {', '.join(WRAP)}")
        filtering = texture.string("filter_type", "bilinear")
        if filtering not in ("bilinear", "nearest", "ewa", "trilinear"):      # 0.6: ewa, ...
            texture.fail(f"filter_type {filtering!r} is none of bilinear, nearest, ewa and "
                         f"trilinear")
        if filtering not in ("bilinear", "nearest"):
            self.notes.append(f"<texture type=\"bitmap\">: filter_type {filtering} drawn "
                              f"bilinear")
        raw = texture.boolean("raw", raw_default)
        try:
            pixels, encoded = read_image_file(path, f"the texture {name!r}", texture.path)
            repeat = 1
            if filtering == "nearest":
                pixels, repeat = nearest_texels(pixels)
                self.notes.append(
                    f"<texture type=\"bitmap\">: filter_type nearest drawn as the bilinear "
                    f"lookup of its texels repeated {repeat} times a side" + (
                        " (the same but within 1/%d of a texel of their edges)" % (2 * repeat)
                        if repeat > 1 else " (too large to repeat: bilinear)"))
            index = self.pool.add(pixels, srgb=not raw, wrap=(WRAP[wrap],) * 2, name=name,
                                  key=(path, raw, repeat), encoded=encoded)
        except (BudgetError, SceneError):
            raise
        except Exception as error:      # noqa: BLE001 - OpenImageIO's many failures
            texture.fail(f"cannot read the image {name!r}: {str(error)[:120]}")
        for unread in texture.unread():
            self.notes.append(f"{texture.where}: parameter {unread!r} ignored")
        return index

    def _checkerboard(self, texture):
        """Mitsuba's checkerboard (color0 where u and v are both in the lower or both in the
        upper half of their unit, color1 elsewhere) baked into an image of CHECKER texels a
        side, repeated."""
        colours = []
        for name, default in (("color0", 0.4), ("color1", 0.2)):
            value = texture.colour(name, Colour((default,) * 3))
            if isinstance(value, Plugin):
                texture.fail(f"a texture for {name!r} is not supported (only a colour)")
            colours.append(np.asarray(value, np.float32))
        half = np.arange(CHECKER) >= CHECKER // 2
        same = half[:, None] == half[None, :]           # rows: v (down), columns: u
        image = np.where(same[:, :, None], colours[0], colours[1]).astype(np.float32)
        self.notes.append(f"<texture type=\"checkerboard\">: baked into a {CHECKER}x{CHECKER} "
                          f"image (its edges filtered over a texel)")
        for unread in texture.unread():
            self.notes.append(f"{texture.where}: parameter {unread!r} ignored")
        return self.pool.add(image, srgb=False, wrap=(REPEAT, REPEAT), name="checkerboard",
                             key=("checkerboard",) + tuple(np.concatenate(colours).tolist()))


def fresnel_diffuse_reflectance(eta):
    """The hemispherical mean of a smooth dielectric boundary's Fresnel reflectance under
    uniform (cosine-weighted) light arriving from the side where the relative index is eta,
    by the fits Mitsuba uses: Egan and Hilgeman's (1973) for eta < 1, d'Eon and Irving's
    (2011) quintic in 1 / eta otherwise (within 0.1-0.6% of the integral for eta in [1/2, 2],
    tested). A plastic's fdr_int is its value at 1 / eta, the light inside the coat."""
    if eta < 1.0:
        return 0.0636 / eta + eta * (eta * -1.4399 + 0.7099) + 0.6681
    x = 1.0 / eta
    return 0.919317 + x * (-3.4793 + x * (6.75335 + x * (-7.80989 + x * (4.98554
                                                                        - 1.36881 * x))))


def _smith_g1(ggx, alpha, v, m, exact=False):
    """Smith's G1 of directions v and normals m (tuples of x, y, z arrays), as ptrace.bsdf's
    _rough_g1 (Walter et al.'s rational Beckmann G1), or with `exact` Beckmann's own
    1 / (1 + Lambda)."""
    xy2 = alpha * alpha * (v[0] * v[0] + v[1] * v[1])
    tan2 = xy2 / np.maximum(v[2] * v[2], 1e-300)
    if ggx:
        g = 2.0 / (1.0 + np.sqrt(1.0 + tan2))
    else:
        with np.errstate(divide="ignore"):
            a = 1.0 / np.sqrt(tan2)
        if exact:
            finite = np.minimum(a, 30.0)
            lam = 0.5 * (_erf(finite) - 1.0) + np.exp(-finite * finite) / (2.0 * finite *
                                                                         math.sqrt(math.pi))
            g = 1.0 / (1.0 + lam)
        else:
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a)
                         / (1.0 + 2.276 * a + 2.577 * a * a))
    g = np.where(xy2 == 0.0, 1.0, g)
    return np.where((v[0] * m[0] + v[1] * m[1] + v[2] * m[2]) * v[2] <= 0.0, 0.0, g)


def _erf(x):
    """erf of x >= 0 (an array) by Abramowitz and Stegun's 7.1.26, within 1.5e-7 (scipy's
    import would cost a load more than the tables)."""
    t = 1.0 / (1.0 + 0.3275911 * x)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                          + t * 1.061405429))))
    return 1.0 - poly * np.exp(-x * x)


def _fresnel(cos_i, eta):
    """Exact unpolarised Fresnel reflectance at cos_i > 0 onto relative index eta, and the
    transmitted cosine (0 past total internal reflection, where the reflectance is 1)."""
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    a_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    a_p = (cos_t - eta * cos_i) / (cos_t + eta * cos_i)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (a_s * a_s + a_p * a_p)), cos_t


def rough_coat_tables(alpha, eta, ggx, n=None, nodes=None):
    """A roughplastic coat's (transmittance from outside at cos theta = j / (n - 1), j = 0 ..
    n-1, and its internal reflectance), as Mitsuba defines them: the transmittance at wi is the
    mean over the normals visible from wi (density G1(wi, m) max(0, wi.m) D(m) / cos theta_i)
    of G1(t, m) (1 - F(wi.m)), t wi refracted through m, where it goes down; the internal
    reflectance is 2 mean_j(cos_j R(cos_j)) over the same cosines, R the same mean of
    G1(r, m) F(wi.m, 1 / eta) for the reflection r, from inside. The means are integrals over
    normals drawn from D(m) cos theta_m ((u1, u2) by its inverse), by Gauss-Legendre in u1 and
    u2, nodes x nodes points (Mitsuba integrates the visible normals' own parameters; by
    default 64 for Beckmann, within 5e-5 of 300 x 300 points, and 96 for GGX, whose heavier
    tails converge slower: within 1.2e-3 of it)."""
    from ..bsdf import TABLE
    n = TABLE if n is None else n
    nodes = (96 if ggx else 64) if nodes is None else nodes
    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (x + 1.0), 0.25 * np.outer(w, w).ravel()
    u1, u2 = (a.ravel() for a in np.meshgrid(x, 0.5 * x, indexing="ij"))   # (wi has y 0:
    # the integrands are even in y, so half the azimuths, each counted twice, cover them all)
    tan2 = alpha * alpha * (u1 / (1.0 - u1) if ggx else -np.log1p(-u1))
    cos_m = 1.0 / np.sqrt(1.0 + tan2)
    sin_m = np.sqrt(np.maximum(0.0, 1.0 - cos_m * cos_m))
    m = (sin_m * np.cos(2 * np.pi * u2), sin_m * np.sin(2 * np.pi * u2), cos_m)
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, n))[:, None]
    wi = (np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu)                   # (n, 1) each
    c = wi[0] * m[0] + wi[2] * m[2]                                        # (n, N)
    visible = _smith_g1(ggx, alpha, wi, m, exact=True) * np.maximum(c, 0.0) / (mu * cos_m)
    lit = c > 0.0
    cp = np.where(lit, c, 1.0)
    f, cos_t = _fresnel(cp, eta)
    scale = cp / eta - cos_t
    t = (m[0] * scale - wi[0] / eta, m[1] * scale, m[2] * scale - wi[2] / eta)   # refracted
    through = np.where(lit & (t[2] < 0.0) & (f < 1.0),
                       _smith_g1(ggx, alpha, t, m) * (1.0 - f), 0.0)
    transmittance = (visible * through) @ w
    f_in, _ = _fresnel(cp, 1.0 / eta)
    r = (2.0 * cp * m[0] - wi[0], 2.0 * cp * m[1], 2.0 * cp * m[2] - wi[2])   # reflected
    back = np.where(lit & (r[2] > 0.0), _smith_g1(ggx, alpha, r, m) * f_in, 0.0)
    reflectance = (visible * back) @ w
    mu = mu[:, 0]
    return transmittance, float(2.0 * np.mean(reflectance * mu))


def nearest_texels(pixels):
    """(pixels with each texel repeated k times along each axis, k) for a filter_type nearest
    bitmap: ptrace's bilinear lookup of the copy returns Mitsuba's nearest texel everywhere but
    within 1 / (2 k) of a texel of the texel edges, where it ramps across the edge over 1 / k of
    a texel, the same mean over any footprint that covers the ramp. k is the largest up to
    NEAREST_REPEAT whose copy has at most NEAREST_TEXELS texels (1: the image as it is)."""
    rows, columns = pixels.shape[:2]
    k = max(1, min(NEAREST_REPEAT, math.isqrt(NEAREST_TEXELS // max(rows * columns, 1))))
    if k == 1:
        return pixels, 1
    return np.repeat(np.repeat(np.asarray(pixels), k, axis=0), k, axis=1), k


def uv_transform(texture):
    """The 3 x 3 matrix a bitmap applies to Mitsuba's (u, v): its to_uv (the 2D part of the
    4 x 4 transform), after 0.6's uscale, vscale, uoffset and voffset (u scale + offset)."""
    matrix = np.eye(3)
    if texture.has("to_uv"):
        m = texture.transform("to_uv").matrix
        matrix = np.array([[m[0, 0], m[0, 1], m[0, 3]], [m[1, 0], m[1, 1], m[1, 3]],
                           [0.0, 0.0, 1.0]])
    old = np.array([[texture.float("uscale", 1.0), 0.0, texture.float("uoffset", 0.0)],
                    [0.0, texture.float("vscale", 1.0), texture.float("voffset", 0.0)],
                    [0.0, 0.0, 1.0]])
    return matrix @ old
