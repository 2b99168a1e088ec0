"""Where a wave's paths keep their state: two blocks indexed [field, path], one float64 row per
field (FLOATS rows x wave size) and one int64 row per field (INTS rows x wave size), each stored
path by path (the transpose of a C array: a path's fields are adjacent in memory), and the
shadow queue's (SHADOW_FLOATS rows x its size, field by field). A stage takes the whole block
and a queue of path slots, so its arguments are a few arrays, whatever the fields."""
import numpy as np

from ..scene import BSDF_NAMES

# the float rows of a path: its ray (origin, direction, interval) and closest hit (t, u, v);
# throughput and radiance; the vertex it left (point q and shading normal qn) and the BSDF pdf
# of the bounce that left it; the surface at its hit (point, geometric normal, shading normal,
# spawn offset)
(OX, OY, OZ, DX, DY, DZ, TMIN, TMAX, T, U, V, TR, TG, TB, R, G, B, QX, QY, QZ, QNX, QNY, QNZ,
 PDF, PX, PY, PZ, GX, GY, GZ, NX, NY, NZ, OFFSET) = range(34)
FLOATS = 34
# the int rows: the pixel (y * width + x) and sample, the hit primitive and its material, the
# vertex the path is at (0: the camera's), the rays it traced, whether its last bounce was a
# delta BSDF's, and its ray's key (ptrace.cutouts: the random numbers of the surfaces it passes);
# the first shadow row of its light samples at its vertex and their count (the light stage's)
PIXEL, SAMPLE, PRIM, MAT, VERTEX, RAYS, DELTA, KEY, SFIRST, SCOUNT = range(10)
INTS = 10
# the shadow queue's rows: origin, direction, end, and the light it carries if it is clear (with
# -H: the hemisphere's rays, each with the weight of the emission it finds); for a light sample
# the light stage leaves the unit direction to the light, its cosine over density and weight,
# and that density times the weight (negative for a delta light), which the shading kernel
# turns, with its BSDF, into the light carried (ptrace.kernel.lighting)
(SOX, SOY, SOZ, SDX, SDY, SDZ, STMAX, SR, SG, SB, SWX, SWY, SWZ, SSCALE, SLPDF) = range(15)
SHADOW_FLOATS = 15


class Wave:
    """The arrays of one wave of `size` paths with room for `shadows` shadow rays, kept by one
    thread and used again for every wave it runs; with `probes` (-H), room for those rays'
    closest hits too."""

    def __init__(self, size, shadows, probes=False):
        self.size, self.shadows = size, shadows
        # stored path by path, indexed [field, path] through a transposed view: a stage that
        # visits a path then loads the few cache lines its fields share, not one line per field
        # (7 % more paths per CPU second on the course's CBbunny than field by field)
        self.floats = np.zeros((size, FLOATS)).T
        self.ints = np.zeros((size, INTS), dtype=np.int64).T
        self.queue = np.zeros(size, dtype=np.int64)       # the paths a stage runs over
        self.next = np.zeros(size, dtype=np.int64)        # the paths a stage hands on
        self.starts = np.zeros(len(BSDF_NAMES) + 1, dtype=np.int64)   # kinds' queues in next
        self.features = np.zeros((8, size))   # the AOVs of each path's camera hit
        self.shadow = np.zeros((SHADOW_FLOATS, max(shadows, 1)))
        self.shadow_path = np.zeros(max(shadows, 1), dtype=np.int64)
        self.shadow_key = np.zeros(max(shadows, 1), dtype=np.int64)
        self.blocked = np.zeros(max(shadows, 1), dtype=np.bool_)
        hits = max(shadows, 1) if probes else 1
        self.probe_prim = np.zeros(hits, dtype=np.int64)    # (-H) each ray's closest hit
        self.probe_uv = np.zeros((2, hits))

    @staticmethod
    def bytes(size, shadows, probes=False):
        """The memory a wave of this size holds."""
        return (size * 8 * (FLOATS + INTS + 10) + max(shadows, 1) * (8 * SHADOW_FLOATS + 17)
                + (max(shadows, 1) * 24 if probes else 0))
