"""The render settings: one frozen, validated value, built once and passed whole to every
executor (in-process, or pickled to Dask workers), so no option can be dropped on the way."""
from dataclasses import dataclass

import numpy as np

import accel

from .. import codes
from ..errors import PtraceError
from ..scene import DIRECTIONAL, POINT

INTEGRATORS = ("path", "normals")
DIRECT = ("mis", "light")             # --direct; -H replaces both by hemisphere sampling
SAMPLERS = ("sobol", "independent")   # --sampler
LIGHT_SAMPLERS = ("auto", "all", "power", "bvh")   # --light-sampler
LIGHT_SAMPLER_CODES = {"auto": codes.LIGHTS_AUTO, "all": codes.LIGHTS_ALL,
                       "power": codes.LIGHTS_POWER, "bvh": codes.LIGHTS_BVH}
GUIDING = ("off", "on", "auto")       # --guiding
BVH_SPLITS = ("mean", "sah")          # --bvh-split (accel.bvh.SPLITS; checked by a test)

# The ranges of the integer settings (the CLI's flags and render()'s keywords alike). The kernels
# take them as int64; within these ranges every sample has its own random numbers: the Sobol
# sampler's point index (sample * light samples + j) is 32 bits, and a vertex's light dimensions
# (2 per light sample) stay below the emitter-selection ones (2**23). A value outside is refused
# rather than passed on (a uint64 beyond int64 would compile a new kernel and render black).
RANGES = {
    "seed": (0, 2 ** 63 - 1),
    "spp": (1, 2 ** 32),
    "light_samples": (1, 2 ** 16),
    "max_depth": (0, 10_000),
    "rr_depth": (1, 10_000),
}
NAMES = {"seed": "seed (--seed)", "spp": "samples per pixel (-s)",
         "light_samples": "light samples (-l)", "max_depth": "max depth (-m)",
         "rr_depth": "the roulette depth"}


def _is_int(value):
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def check_integer(name, value, low, high):
    """Refuse anything but an integer in [low, high], naming the setting and its range."""
    if not (_is_int(value) and low <= value <= high):
        raise PtraceError(f"{name} must be an integer from {low} to {high}, got {value!r}")


@dataclass(frozen=True)
class Settings:
    """What a render computes, apart from the scene, the camera and the pixels.

    spp: samples per pixel (-s); accel: the backend (naive, bvh, embree); integrator: path or
    normals; seed; light_samples (-l): samples per area or ambient light per shading point;
    max_depth (-m); hemisphere (-H): direct light by uniform hemisphere sampling; roulette: Russian
    roulette (False runs every path to max_depth; the course has no such flag); rr_cap: roulette
    continues with probability min(rr_cap, max throughput); rr_depth: the first vertex at which it
    may end a path (default 5, as Mitsuba; 2: from the second bounce, ptrace's rule before);
    adaptive (-a): None or (samples per batch, tolerance); direct: "mis" (light samples and the
    BSDF's sample combined by multiple importance sampling) or "light" (the course's light sampling
    alone); sampler: "sobol" (Owen-scrambled Sobol', stratified) or "independent" (the course's
    uniform random numbers); bvh_split: the BVH's split, "mean" (at the mean centroid, the course's
    suggestion) or "sah" (binned surface area heuristic); only with accel="bvh".
    light_sampler: "all" (at each vertex -l samples of every light, one of each point or
    directional light: the course's estimator), "power" (-l samples at each vertex, each of one
    light chosen by its estimated power), "bvh" (-l samples at each vertex, each of one light or
    emissive primitive chosen by a light BVH for that vertex, ptrace.light_bvh) or "auto" (all
    while a scene has at most ptrace.codes.AUTO_EVERY_LIGHT lights, the emissive primitives
    counting as one, else ptrace.codes.AUTO_MANY). guiding: "off", "on" (path guiding,
    ptrace.guiding: training passes of -s learn where light comes from, and the rest sample
    bounces from the guide and the BSDF) or "auto" (on, unless training shows the guide does
    not lower the variance); with the path integrator, in-process, without -H or -a.
    hide_emitters: the camera does not see the emitters and the environment it meets directly
    (their light still reaches every surface, and mirrors and glass still show them), as Mitsuba's
    integrators' hide_emitters; a Mitsuba scene's own setting unless given.
    """
    spp: int = 1
    accel: str = "bvh"
    integrator: str = "path"
    seed: int = 0
    light_samples: int = 1
    max_depth: int = 1
    hemisphere: bool = False
    roulette: bool = True
    rr_cap: float = codes.RR_CAP
    rr_depth: int = codes.RR_DEPTH
    adaptive: tuple = None
    direct: str = "mis"
    sampler: str = "sobol"
    bvh_split: str = "mean"
    light_sampler: str = "auto"
    guiding: str = "off"
    hide_emitters: bool = False

    def __post_init__(self):
        for name in ("spp", "seed", "light_samples", "max_depth", "rr_depth"):
            check_integer(NAMES[name], getattr(self, name), *RANGES[name])
        if self.spp * self.light_samples > RANGES["spp"][1]:
            raise PtraceError(f"samples per pixel (-s) times light samples (-l) must be at most "
                              f"{RANGES['spp'][1]} (the sampler's 32-bit point index), got "
                              f"{self.spp} x {self.light_samples}")
        for name, what, choices in (("accel", "accelerator", accel.KINDS),
                                    ("integrator", "integrator", INTEGRATORS),
                                    ("direct", "direct-light estimator", DIRECT),
                                    ("sampler", "sampler", SAMPLERS),
                                    ("light_sampler", "light sampler", LIGHT_SAMPLERS),
                                    ("guiding", "guiding mode", GUIDING),
                                    ("bvh_split", "BVH split", BVH_SPLITS)):
            value = getattr(self, name)
            if value not in choices:
                raise PtraceError(f"unknown {what} {value!r}; choose one of "
                                  f"{', '.join(choices)}")
        if self.guiding != "off" and (self.integrator != "path" or self.hemisphere
                                      or self.adaptive is not None):
            raise PtraceError("guiding (--guiding) works with the path integrator only, without "
                              "hemisphere sampling (-H) or adaptive sampling (-a)")
        if self.bvh_split != "mean" and self.accel != "bvh":
            raise PtraceError(f"a BVH split applies only to the bvh accelerator, not "
                              f"{self.accel}")
        if not (isinstance(self.rr_cap, (int, float, np.floating, np.integer))
                and 0.0 < self.rr_cap <= 1.0):
            raise PtraceError(f"the roulette cap must be in (0, 1], got {self.rr_cap!r}")
        set_ = object.__setattr__
        for name in ("spp", "seed", "light_samples", "max_depth", "rr_depth"):
            set_(self, name, int(getattr(self, name)))
        set_(self, "hemisphere", bool(self.hemisphere))
        set_(self, "roulette", bool(self.roulette))
        set_(self, "hide_emitters", bool(self.hide_emitters))
        set_(self, "rr_cap", float(self.rr_cap))
        if self.adaptive is not None:
            try:
                batch, tolerance = self.adaptive
            except (TypeError, ValueError):
                raise PtraceError(f"adaptive must be (batch, tolerance), got {self.adaptive!r}") \
                    from None
            try:
                good = (_is_int(batch) and 1 <= batch <= RANGES["spp"][1]
                        and 0 < float(tolerance) < float("inf"))
            except (TypeError, ValueError):
                good = False
            if not good:
                raise PtraceError(f"adaptive sampling needs a batch between 1 and "
                                  f"{RANGES['spp'][1]} and a finite tolerance > 0, got {batch!r} "
                                  f"{tolerance!r}")
            set_(self, "adaptive", (int(batch), float(tolerance)))

    @classmethod
    def from_options(cls, spp=1, accel="bvh", integrator="path", seed=0, **options):
        """Settings from render()'s keywords; an unknown option is an error, not ignored."""
        known = {"light_samples", "max_depth", "adaptive", "hemisphere", "roulette", "rr_cap",
                 "rr_depth", "direct", "sampler", "bvh_split", "light_sampler", "guiding",
                 "hide_emitters"}
        unknown = set(options) - known
        if unknown:
            raise PtraceError(f"unknown render option(s): {', '.join(sorted(unknown))}")
        return cls(spp=spp, accel=accel, integrator=integrator, seed=seed, **options)

    def accel_options(self):
        """The keywords of accel.build for this render's backend."""
        return {"split": self.bvh_split} if self.accel == "bvh" else {}

    def kernel_options(self):
        """The integrator's Options record (ptrace.codes.Options, or IndependentOptions for the
        independent sampler)."""
        mode = codes.NORMALS if self.integrator == "normals" else codes.PATH
        options = codes.Options if self.sampler == "sobol" else codes.IndependentOptions
        return options(mode, self.seed, self.spp, self.light_samples, self.max_depth,
                       self.hemisphere, self.roulette, self.rr_cap, self.rr_depth,
                       self.direct == "mis", LIGHT_SAMPLER_CODES[self.light_sampler],
                       self.hide_emitters)

    def rays_per_path(self, scene):
        """Rays a path traces at its first vertex: the camera ray and its direct-light rays (the
        size of a work unit, for tiling; deeper vertices add about as many each)."""
        if self.integrator == "normals":
            return 1
        lights = scene.lights
        if self.hemisphere:
            return 1 + max(len(lights), 1) * self.light_samples
        delta = int(np.isin(lights.kind, [POINT, DIRECTIONAL]).sum())
        emitters = int(_emitters(scene) > 0)
        bsdf_ray = int(self.direct == "mis" and len(lights) - delta + emitters > 0)
        if self.light_mode(scene) != codes.LIGHTS_ALL:
            return 1 + self.light_samples + bsdf_ray
        return 1 + delta + self.light_samples * (len(lights) - delta + emitters) + bsdf_ray

    def light_mode(self, scene, emitters=None):
        """The light sampler a render of this scene uses (LIGHTS_ALL, LIGHTS_POWER or
        LIGHTS_BVH; the stages are made for it, ptrace.kernel.wavefront): auto resolved by the
        file's lights and the emissive primitives counting as one (emitters: their count, if
        the caller has it)."""
        code = LIGHT_SAMPLER_CODES[self.light_sampler]
        if code != codes.LIGHTS_AUTO:
            return code
        emitters = _emitters(scene) if emitters is None else emitters
        count = len(scene.lights) + int(emitters > 0)
        return codes.LIGHTS_ALL if count <= codes.AUTO_EVERY_LIGHT else codes.AUTO_MANY

    def uses_light_tree(self, scene):
        """Whether a render of this scene chooses lights by the light BVH (its records then
        need the tree: ptrace.integrator.scene_records)."""
        return self.integrator == "path" and self.light_mode(scene) == codes.LIGHTS_BVH

    def light_tree_entries(self, scene):
        """How many entries a render of this scene puts in its light BVH: 0 without one, else
        at most its lights and its emissive primitives (ptrace.budget charges them)."""
        if self.integrator != "path" or LIGHT_SAMPLER_CODES[self.light_sampler] not in (
                codes.LIGHTS_AUTO, codes.LIGHTS_BVH):
            return 0
        emitters = _emitters(scene)
        bvh = self.light_mode(scene, emitters) == codes.LIGHTS_BVH
        return len(scene.lights) + emitters if bvh else 0


def _emitters(scene):
    """How many emissive primitives make one more light (those that are no file light's face):
    ptrace.emitters.emitter_arrays decides, imported here when a render's work is sized rather
    than when the settings are read, since ptrace.lights is compiled code."""
    from ..emitters import emitter_arrays
    return emitter_arrays(scene)[1].shape[0]
