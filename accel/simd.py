"""Explicit SIMD for the BVH's two hot loops: the slab test of a wide node's children, and the
triangle test of a leaf's block of four triangles (numba intrinsics that emit LLVM vector IR).

Why by hand. numba compiles with LLVM's SLP vectoriser off (NUMBA_SLP_VECTORIZE=0), so scalar
code written lane by lane stays scalar; turning it on is a process-wide numba setting that would
change every numba function in the user's process too, and it did not vectorise the traversal's
scalar slab test profitably when tried (benchmarks/results/accel_rays.md). These intrinsics
write the vector operations themselves, so what runs does not depend on numba's configuration.

Exactness. Each lane performs exactly the IEEE float64 operations of the scalar kernels in
accel.kernels, in the same order, with no fast-math flags (so nothing is reassociated or fused
into a multiply-add): each lane's t, u and v are bit for bit what watertight() or
moller_trumbore() returns for that triangle, which is what keeps bvh equal to naive, primitive
for primitive and t for t. A missed lane is t = NaN (u = v = 0), as the scalar kernels' MISS.
The slab test need not match anything bit for bit, only never miss a box the ray meets: it
computes in float32 on the float32 box planes (rounded outward when the BVH is built, so a box
can only grow), from ray origins moved outward by more than float32's rounding can move a t
(accel.bvh_slab._ray_planes), which tests/accel/test_simd.py checks against exact rational
arithmetic on grazing rays.

LLVM lowers an 8-lane float32 vector to one AVX2 register and a 4-lane float64 one to another
(numba compiles for the host CPU). Loads are declared with the element's alignment
only, so an array that lost its 64-byte alignment (a copy) still works.
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

_I32 = ir.IntType(32)
_I64 = ir.IntType(64)
_F32 = ir.FloatType()
_F64 = ir.DoubleType()


def _vector(element, lanes):
    return ir.VectorType(element, lanes)


def _splat(builder, value, lanes):
    """A vector of `lanes` copies of the float64 `value`."""
    vector = _vector(_F64, lanes)
    one = builder.insert_element(ir.Constant(vector, None), value, ir.Constant(_I32, 0))
    return builder.shuffle_vector(one, ir.Constant(vector, None),
                                  ir.Constant(_vector(_I32, lanes), [0] * lanes))


def _constant(builder, value, lanes):
    return _splat(builder, ir.Constant(_F64, value), lanes)


def _check_array(array, dtype, name):
    if not (isinstance(array, types.Array) and array.ndim == 2 and array.layout == "C"
            and array.dtype == dtype):
        raise TypingError(f"{name} must be a C-contiguous 2D {dtype} array, not {array}")


def _row_pointer(context, builder, array_type, array, row, column):
    """Pointer to element (row, column) of a C-contiguous 2D array (row and column are i64)."""
    ary = context.make_array(array_type)(context, builder, array)
    row_length = cgutils.unpack_tuple(builder, ary.shape, 2)[1]
    index = builder.add(builder.mul(row, row_length), column)
    return builder.gep(ary.data, [index], inbounds=True)


def _load(builder, pointer, element, lanes):
    """`lanes` consecutive elements from `pointer`, widened to float64."""
    vector_type = _vector(element, lanes)
    vector = builder.load(builder.bitcast(pointer, vector_type.as_pointer()),
                          align=4 if element is _F32 else 8)
    return builder.fpext(vector, _vector(_F64, lanes)) if element is _F32 else vector


def _lanes_mask(builder, condition, lanes):
    """An i1 vector as an int64 bit mask (bit c for lane c)."""
    return builder.zext(builder.bitcast(condition, ir.IntType(lanes)), _I64)


def _tuple(context, builder, signature, mask, vectors, lanes):
    """(mask, (lanes of vectors[0]), (lanes of vectors[1]), ...) as the signature's tuple."""
    parts = [mask]
    for vector, part_type in zip(vectors, signature.return_type.types[1:]):
        lane_values = [builder.extract_element(vector, ir.Constant(_I32, lane))
                       for lane in range(lanes)]
        parts.append(context.make_tuple(builder, part_type, lane_values))
    return context.make_tuple(builder, signature.return_type, parts)


def make_slab_test(width):
    """The slab test of a node's `width` children in float32, as a numba intrinsic:

        mask, (t_0, ..., t_{width-1}) = slab_test(nodes, row, planes, ray, lo, hi)

    nodes: C-contiguous float32 rows; row `row` holds six planes of `width` values each,
    starting at the columns in `planes` = (near x, near y, near z, far x, far y, far z) (int64),
    the near plane of an axis being the one a ray along it meets first. ray = (near origin x, y,
    z, far origin x, y, z, near inverse x, y, z, far inverse x, y, z) and lo, hi: float32
    (accel.bvh._ray_planes). Per child: t0 = max(lo, (near plane - near origin) * near inverse),
    t1 = min(hi, (far plane - far origin) * far inverse) over the three axes, and the child is
    hit where t0 <= t1; t_c is its t0, inf where missed. The caller moves the origins and scales
    the inverses outward so that t0 is at most the exact entry t and t1 at least the exact exit
    t: a box that the ray meets within [lo, hi] is never missed. A NaN t (0 * inf, for an
    origin on the plane of an axis the ray is parallel to) is skipped by the max or min that
    meets it first (numba's max(a, b) is `b if b > a else a`), and may hide the axis it is
    paired with: either way the box can only be kept, never lost. An empty slot's box (lower
    +inf, upper -inf) gives +-inf on every axis, never NaN, so it is always missed.
    """
    @intrinsic
    def slab_test(typingctx, nodes, row, planes, ray, lo, hi):
        _check_array(nodes, types.float32, "nodes")
        signature = types.Tuple((types.int64, types.UniTuple(types.float32, width)))(
            nodes, row, planes, ray, lo, hi)

        def codegen(context, builder, signature, args):
            nodes_value, row_value, planes_value, ray_value, lo_value, hi_value = args
            plane_columns = cgutils.unpack_tuple(builder, planes_value, 6)
            values = cgutils.unpack_tuple(builder, ray_value, 12)
            vector = _vector(_F32, width)

            def splat(value):
                one = builder.insert_element(ir.Constant(vector, None), value,
                                             ir.Constant(_I32, 0))
                return builder.shuffle_vector(one, ir.Constant(vector, None),
                                              ir.Constant(_vector(_I32, width), [0] * width))

            def plane_t(column, origin, inverse):   # (plane - o) * inverse, per lane
                pointer = _row_pointer(context, builder, signature.args[0], nodes_value,
                                       row_value, column)
                planes = builder.load(builder.bitcast(pointer, vector.as_pointer()), align=4)
                return builder.fmul(builder.fsub(planes, splat(origin)), splat(inverse))

            def larger(acc, value):    # numba's max(acc, value): value if value > acc else acc
                return builder.select(builder.fcmp_ordered(">", value, acc), value, acc)

            def smaller(acc, value):
                return builder.select(builder.fcmp_ordered("<", value, acc), value, acc)

            near = [plane_t(plane_columns[a], values[a], values[6 + a]) for a in range(3)]
            far = [plane_t(plane_columns[3 + a], values[3 + a], values[9 + a]) for a in range(3)]
            t0 = larger(larger(splat(lo_value), near[0]), larger(near[1], near[2]))
            t1 = smaller(smaller(splat(hi_value), far[0]), smaller(far[1], far[2]))
            hit = builder.fcmp_ordered("<=", t0, t1)
            entries = builder.select(hit, t0, splat(ir.Constant(_F32, float("inf"))))
            return _tuple(context, builder, signature, _lanes_mask(builder, hit, width),
                          [entries], width)

        return signature, codegen

    return slab_test


# A leaf's triangles are stored in blocks of BLOCK: row b of a float64 (blocks, 9 * BLOCK) array
# holds vertex j's coordinate a of lane l at column (3 j + a) BLOCK + l; unused lanes are NaN. A
# float32 array of blocks is read the same way, each coordinate widened to float64 as it is
# loaded (for meshes whose coordinates are all float32 values: the same float64s, in half the
# memory).
BLOCK = 4
BLOCK_COLUMNS = 9 * BLOCK


def _block_coordinate(context, builder, array_type, blocks, block, vertex, axis):
    """The BLOCK lanes of one vertex coordinate of a block (axis an i64 value)."""
    column = builder.add(ir.Constant(_I64, 3 * BLOCK * vertex),
                         builder.mul(axis, ir.Constant(_I64, BLOCK)))
    pointer = _row_pointer(context, builder, array_type, blocks, block, column)
    return _load(builder, pointer, _F32 if array_type.dtype == types.float32 else _F64, BLOCK)


def _block_result(context, builder, signature, miss, t, u, v, lo, hi):
    """(mask of lanes with lo <= t <= hi, t per lane, u, v); missed lanes t = NaN, u = v = 0."""
    zero = _constant(builder, 0.0, BLOCK)
    t = builder.select(miss, _constant(builder, float("nan"), BLOCK), t)
    u = builder.select(miss, zero, u)
    v = builder.select(miss, zero, v)
    inside = builder.and_(builder.fcmp_ordered(">=", t, _splat(builder, lo, BLOCK)),
                          builder.fcmp_ordered("<=", t, _splat(builder, hi, BLOCK)))
    return _tuple(context, builder, signature, _lanes_mask(builder, inside, BLOCK), [t, u, v],
                  BLOCK)


def _block_signature(blocks, block, ray, lo, hi):
    dtype = getattr(blocks, "dtype", None)   # float64 or float32 blocks
    _check_array(blocks, dtype if dtype in (types.float32, types.float64) else types.float64,
                 "blocks")
    lanes = types.UniTuple(types.float64, BLOCK)
    return types.Tuple((types.int64, lanes, lanes, lanes))(blocks, block, ray, lo, hi)


@intrinsic
def watertight_block(typingctx, blocks, block, shear, lo, hi):
    """accel.kernels.watertight on the BLOCK triangles of block `block`, lane by lane:

        mask, (t_0..t_3), (u_0..u_3), (v_0..v_3) = watertight_block(blocks, block, shear, lo, hi)

    shear is accel.kernels.shear_setup() of the ray (kx, ky, kz, px, py, pz, sx, sy, sz); bit l
    of mask is set where lane l is hit with lo <= t <= hi.
    """
    signature = _block_signature(blocks, block, shear, lo, hi)

    def codegen(context, builder, signature, args):
        blocks_value, block_value, shear_value, lo_value, hi_value = args
        kx, ky, kz, px, py, pz, sx, sy, sz = cgutils.unpack_tuple(builder, shear_value, 9)

        def coordinate(vertex, axis, origin):   # the vertex coordinate, minus the ray's origin
            lanes = _block_coordinate(context, builder, signature.args[0], blocks_value,
                                      block_value, vertex, axis)
            return builder.fsub(lanes, _splat(builder, origin, BLOCK))

        b = builder
        sx, sy, sz = (_splat(b, value, BLOCK) for value in (sx, sy, sz))
        ax, ay, az = coordinate(0, kx, px), coordinate(0, ky, py), coordinate(0, kz, pz)
        bx, by, bz = coordinate(1, kx, px), coordinate(1, ky, py), coordinate(1, kz, pz)
        cx, cy, cz = coordinate(2, kx, px), coordinate(2, ky, py), coordinate(2, kz, pz)
        ax, ay = b.fadd(ax, b.fmul(sx, az)), b.fadd(ay, b.fmul(sy, az))
        bx, by = b.fadd(bx, b.fmul(sx, bz)), b.fadd(by, b.fmul(sy, bz))
        cx, cy = b.fadd(cx, b.fmul(sx, cz)), b.fadd(cy, b.fmul(sy, cz))
        e0 = b.fsub(b.fmul(bx, cy), b.fmul(by, cx))
        e1 = b.fsub(b.fmul(cx, ay), b.fmul(cy, ax))
        e2 = b.fsub(b.fmul(ax, by), b.fmul(ay, bx))
        zero = _constant(b, 0.0, BLOCK)

        def any_of(predicate):
            return b.or_(b.or_(b.fcmp_ordered(predicate, e0, zero),
                               b.fcmp_ordered(predicate, e1, zero)),
                         b.fcmp_ordered(predicate, e2, zero))

        det = b.fadd(b.fadd(e0, e1), e2)
        miss = b.or_(b.and_(any_of("<"), any_of(">")), b.fcmp_ordered("==", det, zero))
        inv = b.fdiv(_constant(b, 1.0, BLOCK), det)
        t = b.fmul(b.fmul(b.fadd(b.fadd(b.fmul(e0, az), b.fmul(e1, bz)), b.fmul(e2, cz)), sz),
                   inv)
        return _block_result(context, b, signature, miss, t, b.fmul(e1, inv), b.fmul(e2, inv),
                             lo_value, hi_value)

    return signature, codegen


@intrinsic
def moller_trumbore_block(typingctx, blocks, block, ray, lo, hi):
    """accel.kernels.moller_trumbore on the BLOCK triangles of block `block`, lane by lane:

        mask, (t_0..t_3), (u_0..u_3), (v_0..v_3) = moller_trumbore_block(blocks, block, ray, lo,
                                                                         hi)

    ray = (ox, oy, oz, dx, dy, dz); mask as watertight_block's.
    """
    signature = _block_signature(blocks, block, ray, lo, hi)

    def codegen(context, builder, signature, args):
        blocks_value, block_value, ray_value, lo_value, hi_value = args
        ox, oy, oz, dx, dy, dz = (_splat(builder, value, BLOCK)
                                  for value in cgutils.unpack_tuple(builder, ray_value, 6))

        def vertex(j):
            return [_block_coordinate(context, builder, signature.args[0], blocks_value,
                                      block_value, j, ir.Constant(_I64, axis))
                    for axis in range(3)]

        b = builder
        (p0x, p0y, p0z), (p1x, p1y, p1z), (p2x, p2y, p2z) = vertex(0), vertex(1), vertex(2)
        e1x, e1y, e1z = b.fsub(p1x, p0x), b.fsub(p1y, p0y), b.fsub(p1z, p0z)
        e2x, e2y, e2z = b.fsub(p2x, p0x), b.fsub(p2y, p0y), b.fsub(p2z, p0z)

        def dot(ax, ay, az, bx, by, bz):
            return b.fadd(b.fadd(b.fmul(ax, bx), b.fmul(ay, by)), b.fmul(az, bz))

        def cross(ax, ay, az, bx, by, bz):
            return (b.fsub(b.fmul(ay, bz), b.fmul(az, by)), b.fsub(b.fmul(az, bx), b.fmul(ax, bz)),
                    b.fsub(b.fmul(ax, by), b.fmul(ay, bx)))

        s1x, s1y, s1z = cross(dx, dy, dz, e2x, e2y, e2z)
        det = dot(s1x, s1y, s1z, e1x, e1y, e1z)
        zero, one = _constant(b, 0.0, BLOCK), _constant(b, 1.0, BLOCK)
        inv = b.fdiv(one, det)
        sx, sy, sz = b.fsub(ox, p0x), b.fsub(oy, p0y), b.fsub(oz, p0z)
        u = b.fmul(dot(s1x, s1y, s1z, sx, sy, sz), inv)
        s2x, s2y, s2z = cross(sx, sy, sz, e1x, e1y, e1z)
        v = b.fmul(dot(s2x, s2y, s2z, dx, dy, dz), inv)
        t = b.fmul(dot(s2x, s2y, s2z, e2x, e2y, e2z), inv)
        miss = b.or_(b.fcmp_ordered("==", det, zero),
                     b.or_(b.or_(b.fcmp_ordered("<", u, zero), b.fcmp_ordered(">", u, one)),
                           b.or_(b.fcmp_ordered("<", v, zero),
                                 b.fcmp_ordered(">", b.fadd(u, v), one))))
        return _block_result(context, b, signature, miss, t, u, v, lo_value, hi_value)

    return signature, codegen
