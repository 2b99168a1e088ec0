"""The light BVH as the integrator's light sampler (--light-sampler bvh): unbiased (its image
agrees with every light at every vertex), the probability it chooses a light with is the one the
BSDF-sampled ray's multiple importance weight uses, and it takes -l light samples a vertex."""
import numpy as np
import pytest

import ptrace
from ptrace.integrator import scene_records
from ptrace.light_bvh import bvh_choose, bvh_light_pmf, bvh_prim_pmf
from ptrace.scene import AREA, DIFFUSE, EMISSION, PHYSICAL, POINT, SPOT

from scenes_by_hand import directional_light, looking_down, make_scene, point_light


def area_light(centre, size, radiance):
    return dict(kind=AREA, radiance=(radiance,) * 3, position=centre, direction=(0, -1, 0),
                edge_x=(size, 0, 0), edge_y=(0, 0, size), area=size * size)


def lit_floor():
    """A diffuse floor and wall (two triangles each), under lights of every kind the tree
    holds or leaves beside it: three area lights, a glTF point and spot light, two emissive
    triangles and an emissive sphere (entries); a course point light and a directional light
    (chosen by power beside the tree)."""
    half = 4.0
    lights = [area_light((-1.0, 1.5, 0.0), 0.5, 6.0), area_light((1.2, 2.0, 0.5), 1.0, 1.0),
              area_light((0.0, 1.0, -1.0), 0.2, 40.0), point_light((0.5, 1.0, 1.0), 0.3),
              directional_light((0.3, 1.0, 0.2), 0.2),
              dict(kind=POINT, radiance=(2.0,) * 3, position=(-1.5, 0.8, 1.2), model=PHYSICAL),
              dict(kind=SPOT, radiance=(6.0,) * 3, position=(1.5, 1.5, -1.5),
                   direction=(-0.3, -1.0, 0.3), model=PHYSICAL, cos_inner=0.9, cos_outer=0.7)]
    vertices = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half],
                [-2.0, 0.3, 1.5], [-1.2, 0.3, 1.5], [-1.6, 0.9, 2.0],       # an emissive pair
                [-1.2, 0.3, 1.5], [-0.8, 0.9, 1.5], [-1.6, 0.9, 2.0],
                [2.5, 0, -half], [2.5, 0, half], [2.5, 2.5, half], [2.5, 2.5, -half]]   # wall
    return make_scene(
        vertices=vertices, faces=[[0, 2, 1], [0, 3, 2], [4, 5, 6], [7, 8, 9], [10, 11, 12],
                                  [10, 12, 13]],
        centers=[[0.8, 0.6, -0.8]], radii=[0.2],
        materials=[dict(kind=DIFFUSE, albedo=(0.7,) * 3), dict(kind=EMISSION, emission=(4.0,) * 3),
                   dict(kind=EMISSION, emission=(1.5,) * 3)],
        material_index=[0, 0, 2, 2, 0, 0, 1], lights=lights)


def close_emitters():
    """A diffuse floor lit mostly by three large emissive quads close above it (where a light
    sample's and a BSDF sample's densities are alike, so their weights matter most) and one
    area light."""
    half = 4.0
    vertices = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]]
    faces = [[0, 2, 1], [0, 3, 2]]
    for x, z, y, tilt in ((-1.5, -1.0, 0.4, 0.3), (1.0, 0.5, 0.6, -0.5), (-0.5, 1.8, 0.3, 0.0)):
        base = len(vertices)
        vertices += [[x - 0.8, y - tilt, z - 0.8], [x + 0.8, y + tilt, z - 0.8],
                     [x + 0.8, y + tilt, z + 0.8], [x - 0.8, y - tilt, z + 0.8]]
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return make_scene(
        vertices=vertices, faces=faces,
        materials=[dict(kind=DIFFUSE, albedo=(0.7,) * 3), dict(kind=EMISSION, emission=(2.0,) * 3)],
        material_index=[0, 0] + [1] * 6,
        lights=[area_light((2.0, 1.5, -2.0), 0.5, 4.0)] + [area_light((3, 2, 3), 0.1, 1.0)] * 4)


def lit_floor_under_sky():
    """lit_floor under a constant environment: one more light at infinity beside the tree."""
    from ptrace.environment import Environment
    return lit_floor().with_environment(Environment.constant((0.3, 0.4, 0.5)))


def render(scene, sampler, **options):
    camera = looking_down(5.0, width=24, screen_dist=7.0)
    return ptrace.render(scene, camera=camera, resolution=(24, 24), light_sampler=sampler,
                         **options)


@pytest.mark.parametrize("make, direct, depth", [(lit_floor, "mis", 1), (lit_floor, "light", 1),
                                                (lit_floor, "mis", 3),
                                                (close_emitters, "mis", 1),
                                                (lit_floor_under_sky, "mis", 2)])
def test_bvh_and_every_light_agree_on_the_mean(make, direct, depth):
    """Both estimators are unbiased: the image means, over a few seeds each, agree within four
    standard errors measured from the seeds' spread (a wrong MIS probability for a light the
    BSDF's ray finds, or a light the tree can never choose, moves the mean by more)."""
    scene = make()
    means = {}
    for sampler in ("all", "bvh"):
        means[sampler] = np.array([render(scene, sampler, spp=256, light_samples=2,
                                          max_depth=depth, direct=direct, seed=seed).mean()
                                   for seed in range(6)])
    error = np.sqrt(sum(m.var(ddof=1) / m.size for m in means.values()))
    difference = means["bvh"].mean() - means["all"].mean()
    assert abs(difference) < 4 * error, (means, error)


def _records(scene):
    return scene_records(scene, light_tree=True)[2]


def test_the_probability_chosen_is_the_one_mis_uses():
    """bvh_choose's probability for the light or primitive it chooses at p is, bit for bit,
    bvh_light_pmf's or bvh_prim_pmf's for it there (the density emission_found weighs a
    BSDF-found light by), and the choices' frequencies follow those probabilities."""
    scene = lit_floor()
    lights = _records(scene)
    rng = np.random.default_rng(3)
    count = lights.kind.shape[0]
    prims = scene.geometry.triangle_count + scene.geometry.sphere_count
    for trial in range(4):
        p = rng.uniform([-3, 0, -3], [3, 0.2, 3])
        n = np.array([0.0, 1.0, 0.0]) if trial % 2 == 0 else rng.normal(size=3)
        n /= np.linalg.norm(n)
        light_pmf = np.array([bvh_light_pmf(lights, i, *p, *n) for i in range(count)])
        prim_pmf = np.array([bvh_prim_pmf(lights, k, *p, *n) for k in range(prims)])
        # the emissive primitives' light itself is never chosen whole: its primitives are
        assert light_pmf[count - 1] == 0.0
        assert light_pmf.sum() + prim_pmf.sum() <= 1.0 + 1e-12
        frequency_light, frequency_prim = np.zeros(count), np.zeros(prims)
        samples = 20_000
        for u in (np.arange(samples) + 0.5) / samples:
            light, prim, probability = bvh_choose(lights, u, *p, *n)
            if light < 0:
                continue
            if prim >= 0:
                assert probability == prim_pmf[prim]
                frequency_prim[prim] += 1
            else:
                assert probability == light_pmf[light]
                frequency_light[light] += 1
        # evenly spaced u: each choice owns an interval of u (give or take one sample a node)
        np.testing.assert_allclose(frequency_light / samples, light_pmf, atol=1e-3)
        np.testing.assert_allclose(frequency_prim / samples, prim_pmf, atol=1e-3)


def test_every_light_that_lights_the_floor_can_be_chosen_there():
    """Unbiased: on the floor facing up, every light and emissive primitive that gives it light
    has a probability above zero; the floor's own (not emissive) triangles none."""
    scene = lit_floor()
    lights = _records(scene)
    p, n = (0.3, 0.0, 0.2), (0.0, 1.0, 0.0)
    for light in range(7):       # the file's lights: all light the floor's centre
        assert bvh_light_pmf(lights, light, *p, *n) > 0.0, light
    assert [bvh_prim_pmf(lights, k, *p, *n) > 0.0 for k in range(7)] == \
        [False, False, True, True, False, False, True]


def test_lights_beside_the_tree_keep_their_power_share():
    """The course point light and the directional light are chosen by
    ptrace.lights.selection_weights, the tree taking its lights' summed weight."""
    from ptrace.lights import selection_weights
    scene = lit_floor()
    lights = _records(scene)
    weights = selection_weights(scene)
    share = weights / weights.sum()
    pmf = lights.bvh_pmf
    assert pmf[3] == pytest.approx(share[3]) and pmf[4] == pytest.approx(share[4])
    assert pmf[-1] == pytest.approx(1.0 - share[3] - share[4])
    assert list(lights.light_entry[:7] >= 0) == [True, True, True, False, False, True, True]


def test_bvh_traces_l_shadow_rays_a_vertex():
    scene = lit_floor()
    for samples in (1, 3):
        stats = {}
        render(scene, "bvh", spp=2, light_samples=samples, max_depth=1, direct="light",
               stats=stats)
        assert stats["rays"] <= (1 + samples) * 24 * 24 * 2


def test_records_without_the_tree_choose_by_power():
    """Stages asked for bvh with records built without the tree (scene_records' default)
    choose by power rather than finding no light: the light stage and the hit stage are the
    power sampler's."""
    from ptrace.codes import LIGHTS_BVH, LIGHTS_POWER
    from ptrace.kernel.lighting import light_stage
    from ptrace.kernel.shading import shading_stage
    from ptrace.kernel.stages import hit_stage
    from ptrace.kernel.wavefront import Wavefront
    from ptrace.rendering.settings import Settings
    scene = lit_floor()
    options = Settings(light_sampler="bvh").kernel_options()
    for records, mode in ((scene_records(scene), LIGHTS_POWER),
                          (scene_records(scene)[:2] + (_records(scene),), LIGHTS_BVH)):
        wave = Wavefront(records, options, None, None, [DIFFUSE], False, LIGHTS_BVH)
        assert wave.stages == [(DIFFUSE, shading_stage(DIFFUSE, True, False, False))]
        assert wave.light_stage is light_stage(mode)
        assert wave.hit_stage is hit_stage(True, mode)
    assert Settings(light_sampler="bvh").uses_light_tree(scene)


def test_the_cli_renders_with_the_bvh_sampler(tmp_path):
    """--light-sampler bvh renders the many-light room (a small one) to a file, not black."""
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    room = tmp_path / "room.dae"
    subprocess.run([sys.executable, str(root / "scenes" / "make_many_lights.py"), "--tiles",
                    "4", "--lights", "2", "-o", str(room)], check=True, capture_output=True)
    out = tmp_path / "room.png"
    done = subprocess.run([sys.executable, "-m", "ptrace", str(room), "--light-sampler", "bvh",
                           "-r", "16", "12", "-s", "2", "-m", "2", "--eye", "0,1.6,7.5",
                           "--look-at", "0,1.2,0", "-f", str(out)], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    from PIL import Image
    assert np.asarray(Image.open(out)).mean() > 1.0


def many_area_lights():
    """A diffuse floor under twelve area lights of several sizes and heights, which a
    BSDF-sampled ray finds through ptrace.light_hits' tree."""
    half = 4.0
    vertices = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]]
    rng = np.random.default_rng(12)
    lights = [area_light((x, y, z), size, radiance) for x, y, z, size, radiance in zip(
        rng.uniform(-2.5, 2.5, 12), rng.uniform(0.3, 2.5, 12), rng.uniform(-2.5, 2.5, 12),
        rng.uniform(0.2, 1.5, 12), rng.uniform(0.5, 8.0, 12))]
    return make_scene(vertices=vertices, faces=[[0, 2, 1], [0, 3, 2]],
                      materials=[dict(kind=DIFFUSE, albedo=(0.7,) * 3)], material_index=[0, 0],
                      lights=lights)


@pytest.mark.parametrize("sampler", ["all", "bvh"])
def test_area_lights_a_bsdf_ray_finds_through_the_tree_keep_the_mean(sampler):
    """With MIS, light a BSDF-sampled ray finds on an area light is counted only if the tree
    finds the light: the image agrees with light sampling alone (--direct light, which never
    looks for it) within four standard errors over six seeds."""
    scene = many_area_lights()
    assert scene_records(scene)[2].hit_skip.shape[0] == 2 * 12 - 1
    means = {direct: np.array([render(scene, sampler, spp=128, light_samples=1, max_depth=1,
                                      direct=direct, seed=seed).mean() for seed in range(6)])
             for direct in ("mis", "light")}
    error = np.sqrt(sum(m.var(ddof=1) / m.size for m in means.values()))
    assert abs(means["mis"].mean() - means["light"].mean()) < 4 * error, (means, error)
