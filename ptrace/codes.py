"""The integrator's integer codes and defaults that the settings need, in a module without
numba: ptrace.rendering.settings (read by both commands, pickled to Dask workers) imports them from
here, and the kernels compile them in as constants."""
from collections import namedtuple

RR_CAP = 0.95           # default Russian roulette cap: continue with min(cap, max(throughput))
# default first vertex after whose BSDF sample roulette may end a path: 5, Mitsuba's, chosen by
# relative MSE x seconds on three course scenes at -m 5 against ptrace's earlier 2 and pbrt-v4's
# rule (benchmarks/results/error_vs_time.md): starting at 2, q = min(0.95, throughput) ends dim
# paths early and turns a dim mirror's chains into rare heavy ones (CBcoil's per-pixel spread,
# tests/ptrace/test_per_pixel.py)
RR_DEPTH = 5
PATH, NORMALS = 0, 1    # what the path loop computes per sample
# Options.light_sampler: every light at every vertex (-l samples of each: the course's), or -l
# samples at a vertex each of one light chosen by power (ptrace.lights.light_selection) or by
# the light BVH at the vertex (ptrace.light_bvh), or AUTO: every light while a scene has at most
# AUTO_EVERY_LIGHT of them, else AUTO_MANY: the tree, whose lower error outweighed the cost of
# its walks in a room of a thousand lights (benchmarks/results/many_lights.md)
LIGHTS_ALL, LIGHTS_POWER, LIGHTS_AUTO, LIGHTS_BVH = 0, 1, 2, 3
AUTO_EVERY_LIGHT = 4
AUTO_MANY = LIGHTS_BVH

# The integrator's options record (ptrace.rendering.settings.Settings.kernel_options builds it).
# Its class names the sampler: Options the Sobol' sampler, IndependentOptions the independent
# one. The class is the record's numba type, so a kernel compiles the one sampler a render uses
# (ptrace.integrator.sample_1d and sample_2d).
Options = namedtuple("Options", ["mode", "seed", "spp", "light_samples", "max_depth",
                                 "hemisphere", "roulette", "rr_cap", "rr_depth", "mis",
                                 "light_sampler", "hide_emitters"],
                     defaults=[LIGHTS_AUTO, False])


class IndependentOptions(Options):
    __slots__ = ()
