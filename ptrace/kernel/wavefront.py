"""The wavefront path loop's driver: the records its stages take, and one block of (pixel,
sample) paths traced as waves of stage calls.

A block's paths are cut into waves of at most WAVE_PATHS paths (fewer when -l and the lights
would make a wave's shadow queue longer than SHADOW_RAYS). Each wave: camera rays; then, until
no path is left, closest hits (the backend's stage), the hit stage (surface, emission found,
the paths to shade, sorted by material kind), the light stage (every shading point's light
samples into the shadow queue; ptrace.kernel.lighting), each kind's shading kernel (its BSDF
on those samples, bounces; ptrace.kernel.shading), any hits over the shadow queue (the
backend's) and their light added (with -H: the hemisphere's rays, their closest hits and the
emission they find). Python calls each stage once per bounce of a wave; the stages run without
the GIL, so the render's threads overlap. Waves are folded into the block's per-pixel sums in
path order, which is sample order: the image does not depend on the wave size."""
import threading
from collections import namedtuple

import numpy as np
from numba.core.dispatcher import Dispatcher

from accel.compiled import new_scratch
from accel.interpreted import sized

from .. import codes
from ..scene import (
    ANGULAR,
    AREA,
    DIFFUSE,
    EXACT,
    GLASS,
    GLOSSY,
    GLTF_PBR,
    MICROFACET,
    MIRROR,
    PLASTIC,
    REFRACTION,
    ROUGH_PLASTIC,
    SPOT,
)
from ..solid_angle import rectangle_axes_table
from .aovs import features_stage
from .guide import HISTORY_ROWS, RECORD_ROWS, record_stage, snapshot_stage, uniform_guide
from .layout import Wave
from .lighting import light_stage
from .shading import shading_stage
from .stages import (
    add_stage,
    camera_stage,
    fold_stage,
    hit_stage,
    normals_stage,
    probe_found_stage,
    shadow_stage,
)
from .trace import (
    any_stage,
    closest_stage,
    probe_stage,
    shadowed_stage,
    visible_probe_stage,
    visible_stage,
)

# paths a wave holds at most (its rows about 1.4 MB): fewer calls from Python than smaller waves,
# and larger ones gained nothing (benchmarks/results/wavefront_gate.md)
WAVE_PATHS = 4096
SHADOW_RAYS = 1 << 16  # shadow rays a wave's queue holds at most (about 9 MB)

GUIDE_DEPTH = 8    # (--guiding) the vertices of a path that training records, at most

SHADED = (DIFFUSE, MIRROR, GLASS, REFRACTION, MICROFACET, GLOSSY, GLTF_PBR,
          PLASTIC, ROUGH_PLASTIC)   # all but EMISSION

AreaLights = namedtuple("AreaLights", ["radiance", "position", "direction", "edge_x", "edge_y",
                                       "area", "faced", "hit_lower", "hit_upper", "hit_skip",
                                       "hit_light", "axes"])
SurfaceArrays = namedtuple("SurfaceArrays", ["kind", "emission", "albedo", "transmittance",
                                             "ior", "alpha", "metallic", "eta", "k",
                                             "specular"])


def simple(scene):
    """Whether the scene's lights are area lights alone (no other kind, no environment, and no
    emissive geometry but their faces) and its surfaces the course's, untextured and opaque (no
    texture, no vertex colours, no glTF material, no cut-outs): its stages then take small
    records of their own."""
    from ..emitters import emitter_arrays
    m, used = scene.materials, np.unique(np.asarray(scene.material_index))
    textured = any(np.any(np.asarray(getattr(m, field))[used] >= 0) for field in (
        "albedo_texture", "emission_texture", "roughness_texture", "normal_texture"))
    return (set(np.asarray(scene.lights.kind).tolist()) <= {AREA}
            and emitter_arrays(scene)[1].shape[0] == 0 and not textured
            and np.asarray(scene.vertex_colours).size == 0 and GLTF_PBR not in used_kinds(scene)
            and not np.any(np.asarray(m.cutoff) != 0.0))


def angular_spots(scene):
    """Whether the scene's spots fall off as Mitsuba's (ptrace.scene's ANGULAR, of a Mitsuba
    XML file): its shading kernels are then made for that falloff."""
    lights = scene.lights
    return bool(np.any((np.asarray(lights.kind) == SPOT)
                       & (np.asarray(lights.falloff) == ANGULAR)))


def exact_glass(scene):
    """Whether the scene's glass reflects with the exact Fresnel reflectance (ptrace.scene's
    EXACT, of a Mitsuba dielectric): its glass kernel is then made for it."""
    m = scene.materials
    return bool(np.any((np.asarray(m.kind) == GLASS) & (np.asarray(m.fresnel) == EXACT)))


class Entries:
    """Stage calls without numba's dispatch: a dispatcher types every argument of every call
    (18-20 us for the hit and shading stages, whose records hold dozens of arrays; 5 us for a
    trace stage), holding the GIL, once per stage and bounce of every wave. The first call of
    a stage goes through its dispatcher (which compiles or loads it); the entry point of the
    signature that call's arguments have is kept and called from then on (1.6-2.3 us: the
    arguments are unboxed, not typed). A render's calls of one stage pass arguments of the same
    types (its records, its wave's arrays, Python ints), so the kept entry point is the one the
    dispatcher would choose (the stages that take the caller's arrays, camera_stage and
    add_stage, once per wave or block, go through their dispatchers); `tag` names an argument
    that may be replaced between calls (the guide), whose change resolves the entry point
    again. Anything that is not a numba dispatcher (NUMBA_DISABLE_JIT, a benchmark's wrapper)
    is called as it is."""

    def __init__(self):
        self._entries = {}

    def __call__(self, stage, *args, tag=None):
        kept = self._entries.get(stage)
        if kept is not None and kept[0] is tag:
            return kept[1](*args)
        result = stage(*args)
        entry = stage
        if isinstance(stage, Dispatcher):   # (a wrapper made by functools.wraps is not one)
            cres = stage.overloads.get(tuple(stage.typeof_pyval(a) for a in args))
            if cres is not None:
                entry = cres.entry_point
        self._entries[stage] = (tag, entry)
        return result


def used_kinds(scene):
    """The material kinds of the scene's primitives, sorted."""
    used = np.unique(np.asarray(scene.material_index))
    return sorted(set(np.asarray(scene.materials.kind)[used].tolist()))


class Wavefront:
    """What a render job's wavefront needs beside the pixels: the stage records (built once
    from the job's kernel records) and each thread's wave buffers."""

    def __init__(self, records, options, camera, accel_record, kinds, area_only, mode,
                 guided=False, angular=False, exact=False):
        """records: the job's (shapes, materials, lights); kinds: the material kinds the scene's
        primitives have; area_only: its lights are area lights alone and its surfaces
        untextured (simple); mode: its light sampler (Settings.light_mode); guided: the
        non-delta kinds' bounces mix the path guide (self.guide, a
        ptrace.kernel.guide.GuideArrays that ptrace.guiding sets between passes) with the
        BSDF, and while self.trainer is set each block's records go to trainer.add; angular:
        its spots fall off as Mitsuba's (angular_spots); exact: its glass reflects with the exact
        Fresnel reflectance (exact_glass)."""
        shapes, materials, lights = records
        self.shapes, self.options, self.camera, self.accel = shapes, options, camera, accel_record
        self.materials = materials     # the full record: the AOVs read it
        if mode == codes.LIGHTS_BVH and lights.bvh_pmf.shape[0] == 0:
            mode = codes.LIGHTS_POWER     # records without the tree choose by power
        self.hemisphere = bool(options.hemisphere)
        general = not area_only or mode != codes.LIGHTS_ALL or self.hemisphere
        if general:     # any light: the full records
            self.surfaces, self.lights = materials, lights
            findable = lights.findable
        else:           # area lights: records of just what the stages read
            m = materials
            self.surfaces = SurfaceArrays(m.kind, m.emission, m.albedo, m.transmittance, m.ior,
                                          m.alpha, m.metallic, m.eta, m.k, m.specular)
            self.lights = AreaLights(lights.radiance, lights.position, lights.direction,
                                     lights.edge_x, lights.edge_y, lights.area, lights.faced,
                                     lights.hit_lower, lights.hit_upper, lights.hit_skip,
                                     lights.hit_light,
                                     sized(rectangle_axes_table, lights.area.shape[0])(
                                         lights.position, lights.edge_x, lights.edge_y))
            findable = lights.radiance.shape[0] > 0
        # the shading kernels of the kinds the scene has: no other is ever compiled (none at
        # all for the normals integrator)
        self.normals = options.mode == codes.NORMALS
        self.guided = bool(guided) and not self.normals and not self.hemisphere
        self.stages = [] if self.normals else [(kind, shading_stage(kind, general,
                                                                   self.hemisphere,
                                                                   self.guided, exact))
                                               for kind in kinds if kind in SHADED]
        # the general lights' samples of every kind's shading points and their bent normals:
        # one stage, compiled once for the scene's light setup (area lights alone and untextured
        # surfaces: none, the kinds' kernels sample their lights in the same pass)
        self.light_stage = light_stage(mode, self.hemisphere, angular) \
            if self.stages and general else None
        self.guide = uniform_guide()
        self.trainer = None
        self.depth = max(1, min(GUIDE_DEPTH, options.max_depth)) if self.guided else 1
        self.hit_stage = None if self.normals else hit_stage(general, mode)
        # cut-out surfaces: the backend's stages that trace past them (the records hold an
        # empty cutoff array when no material is cut)
        self.cutouts = general and materials.cutoff.shape[0] > 0
        self.mis = bool(options.mis and findable and not self.hemisphere)
        per_vertex = max(1, lights.radiance.shape[0] * options.light_samples)
        self.wave_paths = int(max(1, min(WAVE_PATHS, SHADOW_RAYS // per_vertex)))
        self.shadow_rays = self.wave_paths * lights.radiance.shape[0] * options.light_samples
        self._local = threading.local()
        self.call = Entries()

    def _wave(self):
        wave = getattr(self._local, "wave", None)
        if wave is None:
            wave = self._local.wave = self.new_wave()
        return wave

    def new_wave(self):
        """A wave's arrays for this render (each thread keeps its own, used again for every
        wave)."""
        wave = Wave(self.wave_paths, self.shadow_rays, self.hemisphere)
        wave.scratch = new_scratch(self.accel)   # the backend's, for this thread's traces
        columns = self.wave_paths * self.depth if self.guided else 1
        wave.history = np.zeros((HISTORY_ROWS, columns))   # (guided) the vertices to record
        wave.records = np.zeros((RECORD_ROWS, columns))
        return wave

    def trace(self, pixel_x, pixel_y, rows, first_sample, pass_n, sum_rgb, sum_l, sum_l2, count,
              features):
        """Samples first_sample .. + pass_n - 1 of each pixel added to the sums at rows, and
        their AOVs to features if it has rows ((n, 8), else (0, 8)). Returns (dropped, rays
        traced)."""
        wave = self._wave()
        scratch, call = wave.scratch, self.call
        floats, ints, queue = wave.floats, wave.ints, wave.queue
        shapes, options = self.shapes, self.options
        sums = np.zeros((pixel_x.shape[0], 5))
        aovs = features.shape[0] > 0
        feature_sums = np.zeros((pixel_x.shape[0] if aovs else 0, 8))
        counts = np.zeros(pixel_x.shape[0], dtype=np.int64)
        total = pixel_x.shape[0] * pass_n
        dropped = rays = 0
        trainer, records = self.trainer, []
        for start in range(0, total, self.wave_paths):
            size = min(self.wave_paths, total - start)
            # (through the dispatcher, as add_stage: the caller's arrays are typed on each call)
            camera_stage(self.camera, options, pixel_x, pixel_y, first_sample, pass_n, start,
                         size, floats, ints, queue)
            if aovs:   # the camera rays' first hits, before any stage moves on from them
                self._closest(wave, scratch, size)
                features_stage(shapes, self.materials, floats, ints, size, wave.features)
            if self.normals:   # the camera rays' hits, coloured by their normals
                if not aovs:
                    self._closest(wave, scratch, size)
                normals_stage(shapes, floats, ints, size)
            else:
                self.paths(wave, scratch, size, traced=aovs)
                if trainer is not None:
                    kept = record_stage(floats, size, wave.history, self.depth, wave.records)
                    records.append(wave.records[:, :kept].copy())
            wave_dropped, wave_rays = call(fold_stage, floats, ints, start, size, pass_n, sums,
                                           counts, wave.features, feature_sums)
            dropped += wave_dropped
            rays += wave_rays
        add_stage(sums, counts, rows, sum_rgb, sum_l, sum_l2, count, feature_sums, features)
        if trainer is not None and rows.shape[0]:
            trainer.add((first_sample, int(rows[0])), np.concatenate(records, axis=1))
        return dropped, rays

    def kernels(self, aovs=False):
        """Every stage kernel a render of this job may call, each with arguments of the types
        trace() calls it with (a wave of this job's own, one path): [(dispatcher, args)], the
        largest kernels first. ptrace.kernel.ahead compiles them before the render, on every
        core. aovs: the render asks for AOVs (trace's features has rows)."""
        wave, scratch = self.new_wave(), new_scratch(self.accel)
        floats, ints, queue, after = wave.floats, wave.ints, wave.queue, wave.next
        shadow, shadow_path, blocked = wave.shadow, wave.shadow_path, wave.blocked
        shapes, surfaces, lights, options = self.shapes, self.surfaces, self.lights, self.options
        accel, one = self.accel, np.zeros(1, dtype=np.int64)
        sums, feature_sums = np.zeros((1, 5)), np.zeros((1 if aovs else 0, 8))
        if self.cutouts:
            closest = (visible_stage, (accel, scratch, shapes, surfaces, options, floats, ints,
                                       queue, 1))
        else:
            closest = (closest_stage, (accel, scratch, floats, ints, queue, 1))
        calls = [(stage, (shapes, surfaces, lights, options, self.mis, floats, ints, after[0:1],
                          1, shadow, shadow_path, wave.shadow_key, 0, queue, 0, self.guide,
                          wave.history, self.depth))
                 for _kind, stage in self.stages]
        if self.light_stage is not None:
            calls.append((self.light_stage, (shapes, surfaces, lights, options, floats, ints,
                                             after, 1, shadow, shadow_path, wave.shadow_key, 0)))
        if not self.normals:
            calls.append((self.hit_stage, (shapes, surfaces, lights, options, self.mis, floats,
                                           ints, queue, 1, after, wave.starts)))
        calls += [closest, (camera_stage, (self.camera, options, one, one, 0, 1, 0, 1, floats,
                                           ints, queue))]
        if aovs:
            calls.append((features_stage, (shapes, self.materials, floats, ints, 1,
                                           wave.features)))
        if self.normals:
            calls.append((normals_stage, (shapes, floats, ints, 1)))
        elif self.hemisphere:
            calls.append((visible_probe_stage, (accel, scratch, shapes, surfaces, options, ints,
                                                shadow, shadow_path, wave.shadow_key, 1,
                                                wave.probe_prim, wave.probe_uv))
                         if self.cutouts else
                         (probe_stage, (accel, scratch, shadow, 1, wave.probe_prim,
                                        wave.probe_uv)))
            calls.append((probe_found_stage, (shapes, surfaces, lights, floats, shadow,
                                              shadow_path, wave.probe_prim, wave.probe_uv, 1)))
        else:
            calls.append((shadowed_stage, (accel, scratch, shapes, surfaces, options, ints,
                                           shadow, shadow_path, wave.shadow_key, 1, blocked))
                         if self.cutouts else
                         (any_stage, (accel, scratch, shadow, 1, blocked)))
            calls.append((shadow_stage, (floats, shadow, shadow_path, blocked, 1)))
        if self.guided:   # the training passes'
            calls += [(snapshot_stage, (floats, ints, queue, 1, wave.history, self.depth)),
                      (record_stage, (floats, 1, wave.history, self.depth, wave.records))]
        calls += [(fold_stage, (floats, ints, 0, 1, 1, sums, one, wave.features, feature_sums)),
                  (add_stage, (sums, one, one, np.zeros((1, 3)), np.zeros(1), np.zeros(1), one,
                               feature_sums, np.zeros((1 if aovs else 0, 8))))]
        return calls

    def _closest(self, wave, scratch, n):
        """The closest hits of the n queued paths' rays (past cut-out surfaces if the scene
        has them)."""
        if self.cutouts:
            self.call(visible_stage, self.accel, scratch, self.shapes, self.surfaces,
                      self.options, wave.floats, wave.ints, wave.queue, n)
        else:
            self.call(closest_stage, self.accel, scratch, wave.floats, wave.ints, wave.queue, n)

    def paths(self, wave, scratch, n, traced=False):
        """Carry the wave's n queued paths, whose rays are set (slots as camera_stage leaves
        them: throughput 1, no radiance, vertex 0, one ray), to their ends: each path's
        radiance in its R, G, B rows and the rays it traced in its RAYS row. traced: their
        first closest hits are found already (the AOVs' features needed them)."""
        floats, ints, queue, after = wave.floats, wave.ints, wave.queue, wave.next
        shadow, shadow_path, blocked = wave.shadow, wave.shadow_path, wave.blocked
        shadow_key, cutouts = wave.shadow_key, self.cutouts
        shapes, surfaces, lights, options = self.shapes, self.surfaces, self.lights, self.options
        accel, mis, starts = self.accel, self.mis, wave.starts
        guide, history, depth = self.guide, wave.history, self.depth
        snapshot = self.trainer is not None
        call = self.call
        while n:
            if not traced:
                self._closest(wave, scratch, n)
            traced = False
            hits = n
            n = call(self.hit_stage, shapes, surfaces, lights, options, mis, floats, ints, queue,
                     n, after, starts)
            if snapshot:   # the radiance the bounces' records start from
                snapshot_stage(floats, ints, queue, hits, history, depth)
            if not n:
                break
            shadows = 0
            if self.light_stage is not None:   # every kind's light samples (bent normals)
                shadows = call(self.light_stage, shapes, surfaces, lights, options, floats, ints,
                               after, n, shadow, shadow_path, shadow_key, 0)
            n = 0
            for kind, stage in self.stages:   # each kind's paths, through its kernel
                first, end = starts[kind], starts[kind + 1]
                if end > first:
                    shadows, n = call(stage, shapes, surfaces, lights, options, mis, floats,
                                      ints, after[first:end], end - first, shadow, shadow_path,
                                      shadow_key, shadows, queue, n, guide, history, depth,
                                      tag=guide)
            if shadows and self.hemisphere:   # the hemisphere's rays, and what they find
                if cutouts:
                    visible_probe_stage(accel, scratch, shapes, surfaces, options, ints, shadow,
                                        shadow_path, shadow_key, shadows, wave.probe_prim,
                                        wave.probe_uv)
                else:
                    probe_stage(accel, scratch, shadow, shadows, wave.probe_prim, wave.probe_uv)
                probe_found_stage(shapes, surfaces, lights, floats, shadow, shadow_path,
                                  wave.probe_prim, wave.probe_uv, shadows)
            elif shadows:
                if cutouts:
                    shadowed_stage(accel, scratch, shapes, surfaces, options, ints, shadow,
                                   shadow_path, shadow_key, shadows, blocked)
                else:
                    call(any_stage, accel, scratch, shadow, shadows, blocked)
                call(shadow_stage, floats, shadow, shadow_path, blocked, shadows)
