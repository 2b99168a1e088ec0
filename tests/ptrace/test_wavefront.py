"""The path loop's wavefront (ptrace.kernel) gives the same image bit for bit whatever the wave
size, the threads or the crop, and `bvh` the same as `naive`; its memory does not grow with -s,
-m or -l; it compiles a shading kernel only for the material kinds a scene has, and none for
the normals integrator. (What the images should be is checked against analytic answers and
Mitsuba's references elsewhere: test_estimators, test_light_transport, test_per_pixel.)"""
import functools

import numba
import numpy as np
import pytest
from numba.core import types

import ptrace
from ptrace import bsdf, codes, integrator, lights
from ptrace.kernel import layout, lighting, shading, stages, wavefront
from ptrace.rendering.settings import Settings
from ptrace.rendering.tiles import RenderJob
from ptrace.scene import DIFFUSE, GLASS, MIRROR

from conftest import REPO, course_scene

CORNELL = REPO / "scenes" / "cornell.dae"
SMALL = dict(spp=3, light_samples=2, max_depth=5, rr_depth=2)


def framed(scene, eye_z, width=24, height=18):
    """A camera that sees the whole box (the course's camera at this size sees a crop)."""
    return ptrace.look_at(scene, eye=(0.0, 0.75, eye_z), target=(0.0, 0.75, 0.0), fov=50,
                          width=width, height=height)


@pytest.fixture(scope="module")
def cornell():
    scene = ptrace.load(str(CORNELL))
    return scene, framed(scene, 3.5)


def assert_same(first, second):
    assert first.shape == second.shape
    assert np.array_equal(first, second), f"max difference {np.abs(first - second).max()}"
    assert first.mean() > 0.01     # lit: a black image would match trivially


def test_bvh_gives_naives_image_and_embree_its_light(cornell):
    scene, camera = cornell
    images = {kind: ptrace.render(scene, camera=camera, accel=kind, **SMALL)
              for kind in ("naive", "bvh", "embree")}
    assert_same(images["naive"], images["bvh"])
    assert images["embree"].mean() == pytest.approx(images["bvh"].mean(), rel=0.02)


@pytest.mark.parametrize("options", [dict(), dict(hemisphere=True), dict(integrator="normals")],
                         ids=["path", "hemisphere", "normals"])
def test_same_image_whatever_the_wave_size_threads_and_crop(cornell, monkeypatch, options):
    scene, camera = cornell
    options = dict(SMALL, **options)
    reference = ptrace.render(scene, camera=camera, threads=2, **options)
    monkeypatch.setattr(wavefront, "WAVE_PATHS", 7)       # waves cut pixels' samples apart
    assert_same(reference, ptrace.render(scene, camera=camera, threads=1, **options))
    crop = ptrace.render(scene, camera=camera, crop=(5, 4, 9, 7), **options)   # y from the bottom
    assert_same(crop, reference[18 - 4 - 7:18 - 4, 5:5 + 9])


def test_a_wave_holds_the_same_memory_whatever_spp_and_depth_and_bounds_light_samples(cornell):
    cornell, camera = cornell
    sizes = set()
    for spp, depth in ((1, 1), (4096, 10_000)):
        job = RenderJob.build(cornell, Settings(spp=spp, max_depth=depth), camera)
        sizes.add((job.wavefront.wave_paths, job.wavefront.shadow_rays))
    assert len(sizes) == 1
    job = RenderJob.build(cornell, Settings(light_samples=2 ** 16), camera)
    lights = len(cornell.lights)
    assert job.wavefront.shadow_rays <= wavefront.SHADOW_RAYS
    assert job.wavefront.wave_paths * lights * 2 ** 16 == job.wavefront.shadow_rays
    assert layout.Wave.bytes(job.wavefront.wave_paths, job.wavefront.shadow_rays) < 10 << 20


def test_the_normals_integrator_compiles_no_shading_kernel(cornell):
    scene, camera = cornell
    job = RenderJob.build(scene, Settings(integrator="normals"), camera)
    assert job.wavefront.stages == [] and job.wavefront.hit_stage is None


def test_only_the_kinds_a_scene_has_get_a_kernel(cornell):
    scene, camera = cornell
    job = RenderJob.build(scene, Settings(), camera)
    assert [kind for kind, _ in job.wavefront.stages] == [DIFFUSE]
    spheres = ptrace.load(str(course_scene("sky/CBspheres.dae")))
    job = RenderJob.build(spheres, Settings(), camera)
    assert [kind for kind, _ in job.wavefront.stages] == [DIFFUSE, MIRROR, GLASS]


def calls(dispatcher, signature=None):
    """The numba functions that a kernel's own code calls, from its types: the kernel is typed
    afresh (its cached copy keeps no types), with the signature it was compiled for."""
    signature = signature or dispatcher.signatures[0]
    fresh = numba.njit(nogil=True, _nrt=False)(dispatcher.py_func)
    fresh.compile(signature)
    typemap = fresh.overloads[signature].fndesc.typemap
    return {ty.dispatcher.py_func for ty in typemap.values() if isinstance(ty, types.Dispatcher)}


def called_with(dispatcher, callee):
    """The argument types with which a kernel's own code calls the numba function `callee`
    (the kernel typed afresh, as calls() does)."""
    signature = dispatcher.signatures[0]
    fresh = numba.njit(nogil=True, _nrt=False)(dispatcher.py_func)
    fresh.compile(signature)
    fndesc = fresh.overloads[signature].fndesc
    for expr, called in fndesc.calltypes.items():
        if getattr(expr, "op", None) != "call":
            continue
        kind = fndesc.typemap.get(expr.func.name)
        if isinstance(kind, types.Dispatcher) and kind.dispatcher is callee:
            return called.args
    raise AssertionError(f"{dispatcher.py_func.__qualname__} does not call {callee}")


def test_a_shading_kernel_types_no_code_of_other_kinds_and_a_delta_kind_none_for_lights():
    """Each kind's kernel calls its own kind's BSDF functions, not the dispatch over every kind
    (which would compile every kind's code into it); a delta kind's has no light sampling, and
    no kind's has the general lights' samplers (the light stage's)."""
    scene = ptrace.load(str(course_scene("sky/CBspheres.dae")))
    ptrace.render(scene, spp=1, resolution=(8, 6), max_depth=3)
    plain = lambda kind: shading.shading_stage(kind, False, False, False)
    diffuse, mirror = calls(plain(DIFFUSE)), calls(plain(MIRROR))
    own = lambda kind: {f.py_func for f in bsdf.BSDFS[kind]}
    every_kind = set().union(*(own(kind) for kind in bsdf.BSDFS))
    general = {f.py_func for f in (lighting.any_light, lighting.chosen_light,
                                   lighting.any_light_angular, lighting.chosen_light_angular)}
    light_sampling = general | {f.py_func for f in (lights.sample_area, lights.sample_area_row)}
    # what the probe sees: the diffuse kernel's BSDF and its area lights' samples
    assert own(DIFFUSE) <= diffuse and lights.sample_area_row.py_func in diffuse
    assert diffuse & every_kind == own(DIFFUSE) and not diffuse & general
    assert bsdf.mirror_sample.py_func in mirror
    assert mirror & every_kind <= own(MIRROR) and not mirror & light_sampling


def constants(dispatcher):
    """The closure constants of a kernel made by a factory, by name."""
    function = dispatcher.py_func
    return dict(zip(function.__code__.co_freevars,
                    (cell.cell_contents for cell in function.__closure__ or ())))


def test_the_light_stage_samples_lights_with_its_scenes_spot_falloff_alone(tmp_path):
    """A scene without Mitsuba's spots (a point light) gets the general light stage, whose
    light samplers reach glTF's spot falloff and nothing of Mitsuba's; a scene of Mitsuba's
    spots gets the stage whose samplers reach Mitsuba's alone."""
    path = tmp_path / "lit.xml"
    path.write_text('<scene version="3.0.0"><shape type="rectangle"><bsdf type="diffuse"/>'
                    '</shape><emitter type="point"><point name="position" x="0" y="0" z="1"/>'
                    '</emitter></scene>', encoding="utf-8")
    point = ptrace.load(str(path))
    path.write_text(path.read_text().replace(
        '<emitter type="point"><point name="position" x="0" y="0" z="1"/></emitter>',
        '<emitter type="spot"><transform name="to_world"><lookat origin="0 0 1" target="0 0 0"/>'
        '</transform></emitter>'), encoding="utf-8")
    assert not wavefront.angular_spots(point)
    assert wavefront.angular_spots(ptrace.load(str(path)))
    for angular in (False, True):
        stage = lighting.light_stage(codes.LIGHTS_ALL, False, angular)
        samplers = (lighting.any_light_angular, lighting.chosen_light_angular) if angular else \
            (lighting.any_light, lighting.chosen_light)
        assert constants(stage)["any_light_"] is samplers[0]
        assert constants(stage)["chosen_light_"] is samplers[1]
        # both sample a light of its kind through their factory's of_its_kind
        assert all(constants(constants(sampler)["of_its_kind"])["ANGULAR"] is angular
                   for sampler in samplers)
    assert constants(lights.sample_light)["ANGULAR"] is False
    assert constants(lights.sample_light_angular)["ANGULAR"] is True
    # each is typed with the other's falloff pruned away
    light_record = integrator.scene_records(point)[2]
    signature = (numba.typeof(light_record), types.int64) + (types.float64,) * 5
    for sampler, own, other in ((lights.sample_light, lights.spot_falloff,
                                 lights.spot_angular_falloff),
                                (lights.sample_light_angular, lights.spot_angular_falloff,
                                 lights.spot_falloff)):
        typed = calls(sampler, signature)
        assert own.py_func in typed and other.py_func not in typed


def test_a_glass_kernel_reflects_with_its_scenes_fresnel_alone(tmp_path):
    """A Mitsuba dielectric's scene gets the glass kernel of the exact Fresnel reflectance, the
    course's glass keeps Schlick's; other kinds' kernels are the same whatever the flag."""
    path = tmp_path / "glass.xml"
    path.write_text('<scene version="3.0.0"><shape type="sphere"><bsdf type="dielectric"/>'
                    '</shape></scene>', encoding="utf-8")
    assert wavefront.exact_glass(ptrace.load(str(path)))
    assert not wavefront.exact_glass(ptrace.load(str(course_scene("sky/CBspheres.dae"))))
    for exact, sample in ((False, bsdf.glass_sample), (True, bsdf.dielectric_sample)):
        stage = shading.shading_stage(GLASS, False, False, False, exact)
        assert constants(stage)["BSDF_SAMPLE"] is sample
    assert shading.shading_stage(DIFFUSE, False, False, False, True) \
        is shading.shading_stage(DIFFUSE, False, False, False)


def test_the_emission_a_ray_finds_types_the_light_trees_pmfs_only_for_its_sampler(tmp_path):
    """A scene of a point light (the general stages, every light sampled) compiles nothing of
    the light BVH's or the power sampler's weights; the light BVH's variant, typed for the
    same arguments, does call the tree's."""
    path = tmp_path / "point.xml"
    path.write_text('<scene version="3.0.0"><shape type="rectangle"><bsdf type="diffuse"/>'
                    '</shape><emitter type="point"><point name="position" x="0" y="0" z="1"/>'
                    '</emitter></scene>', encoding="utf-8")
    ptrace.render(ptrace.load(str(path)), spp=1, resolution=(8, 6), max_depth=3,
                  light_sampler="all")
    found = integrator.emission_found(codes.LIGHTS_ALL)
    # the arguments the hit stage passes it (loaded from the cache, found itself never compiles)
    signature = called_with(stages.hit_stage(True, codes.LIGHTS_ALL), found)
    tree = {integrator.tree_samples.py_func, integrator.bvh_prim_pmf.py_func}
    every = calls(found, signature)
    assert integrator.every_light_samples.py_func in every
    assert not every & (tree | {integrator.power_samples.py_func})
    assert tree <= calls(integrator.emission_found(codes.LIGHTS_BVH), signature)


def _recording(monkeypatch):
    """Every compiled function the wavefront calls, wrapped to record (dispatcher, argument
    types) of each call made once the returned set has a None in it (from then on)."""
    seen = set()

    def wrap(dispatcher):
        def recorded(*args):
            if None in seen:
                seen.add((dispatcher, tuple(dispatcher.typeof_pyval(a) for a in args)))
            return dispatcher(*args)
        recorded.dispatcher = dispatcher
        return recorded

    for name, value in list(vars(wavefront).items()):
        if isinstance(value, numba.core.registry.CPUDispatcher):
            monkeypatch.setattr(wavefront, name, wrap(value))
    for factory in ("shading_stage", "light_stage", "hit_stage"):
        made = getattr(wavefront, factory)
        monkeypatch.setattr(wavefront, factory,
                            lambda *args, made=made, **kw: wrap(made(*args, **kw)))
    return seen


@pytest.mark.parametrize("options", [dict(), dict(hemisphere=True), dict(integrator="normals"),
                                     dict(light_sampler="power", aovs=True),
                                     dict(guiding="on", spp=4)],
                         ids=["path", "hemisphere", "normals", "power-aovs", "guided"])
def test_the_kernels_compiled_ahead_are_those_a_render_calls(cornell, monkeypatch, options):
    """Wavefront.kernels (what ptrace.kernel.ahead compiles before a cold render) lists each
    stage a render calls, with the argument types it calls it with, and nothing else: a kernel
    missing from the list would compile alone on the render's first call, and one listed but
    never called would be compiled for nothing."""
    scene, camera = cornell
    seen = _recording(monkeypatch)
    options = dict(SMALL, **options)
    aovs = {} if options.pop("aovs", False) else None
    planned = {}

    def compile_ahead(job, with_aovs=False):
        planned["calls"] = job.wavefront.kernels(with_aovs)
        seen.add(None)   # the calls of the render's passes (not the job's records)
        return 0

    monkeypatch.setattr(RenderJob, "compile_ahead", compile_ahead)
    assert ptrace.render(scene, camera=camera, aovs=aovs, **options).mean() > 0.0
    listed = {(call.dispatcher, tuple(call.dispatcher.typeof_pyval(a) for a in args))
              for call, args in planned["calls"]}
    assert len(listed) == len(planned["calls"])
    assert seen - {None} == listed


def test_stage_calls_after_the_first_go_to_the_entry_point_of_their_arguments_types():
    """wavefront.Entries: a stage's first call goes through its dispatcher, later calls to the
    compiled entry point of the signature the first call's arguments have (same results); a
    new tag (the guide, replaced between passes) resolves it again, and what is not a numba
    dispatcher is called as it is."""
    @numba.njit(nogil=True)
    def accumulate(values, n):
        values[0] += n
        return values[0]

    call = wavefront.Entries()
    values = np.zeros(1)
    assert call(accumulate, values, 1) == 1.0
    tag, entry = call._entries[accumulate]
    assert tag is None and entry is accumulate.overloads[accumulate.signatures[0]].entry_point
    assert call(accumulate, values, 2) == 3.0 and values[0] == 3.0
    guide = object()
    assert call(accumulate, values, 4, tag=guide) == 7.0
    assert call._entries[accumulate][0] is guide
    assert call(len, [1, 2]) == 2 and call._entries[len] == (None, len)
    wrapped = functools.wraps(accumulate)(lambda *args: accumulate(*args))
    assert call(wrapped, values, 1) == 8.0 and call._entries[wrapped] == (None, wrapped)
