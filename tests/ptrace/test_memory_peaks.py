"""Peak memory of reading textures, environment maps and meshes, and of building the
accelerators over them: each measured in a fresh Python process as the growth of its peak
resident size (Linux's VmHWM, reset through /proc/self/clear_refs) over its resident size
just before, per texel or per triangle. Each limit is just under twice the figure measured
when it was set (benchmarks/results/memory.md has the figures and the large inputs), so a
change that doubles what a texel or a triangle costs fails here, while noise does not."""
import json
import subprocess
import sys
import textwrap

import numpy as np
import PIL.Image

# Just under twice the peak bytes measured on the sizes below (AMD EPYC Zen 1, Linux, numpy 2):
# a doubling fails, the few percent the figures move between runs do not
# (ply bvh: 288 before the BVH build's float32 boxes and blocks, 219 after; with int32 faces,
# shared by Embree, ply 143 -> 134, ply bvh 237 -> 207, ply embree 262 -> 235, each the mean
# of two runs)
MEASURED = {"texture": 15.8, "environment": 25.2, "ply": 134.0, "ply bvh": 207.0,
            "ply embree": 235.0, "obj": 725.0}
LIMITS = {key: 1.9 * value for key, value in MEASURED.items()}

PROBE = textwrap.dedent("""
    import json, sys
    import numpy as np

    def status(key):
        with open("/proc/self/status") as handle:
            for line in handle:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024

    def peak(work):
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")          # the peak resident size starts again from now
        before = status("VmRSS")
        kept = work()
        return status("VmHWM") - before, kept

    import accel, accel.interpreted, ptrace, trimesh
    from ptrace.environment import environment_arrays, load_environment
    kind, path, *backends = sys.argv[1:]
    figures = {}
    if kind == "environment":       # OpenImageIO's start-up, before measuring
        environment_arrays(load_environment(path.replace("big", "tiny")))

        def work():
            environment = load_environment(path)
            return environment, environment_arrays(environment)
        grown, _ = peak(work)
        figures[kind] = grown
    else:
        tiny = ptrace.load(path.replace("big", "tiny"))
        accel.interpreted.SMALL = -1   # the tiny file's build compiled, as the big one's is
        for backend in backends:     # compiled (or loaded from the cache) before measuring
            accel.build(backend, tiny.geometry)
        grown, scene = peak(lambda: ptrace.load(path))
        figures[kind] = grown
        for backend in backends:
            figures[f"{kind} {backend}"] = grown + peak(
                lambda: accel.build(backend, scene.geometry))[0]
    print(json.dumps(figures))
""")


def measure(kind, path, *backends):
    result = subprocess.run([sys.executable, "-c", PROBE, kind, str(path), *backends],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def grid_mesh(n_tri):
    """A bumpy square of n_tri triangles: (vertices float32 (V, 3), faces int32 (n_tri, 3))."""
    k = int(np.ceil(np.sqrt(n_tri / 2))) + 1
    xs, ys = np.meshgrid(np.linspace(-1, 1, k), np.linspace(-1, 1, k))
    zs = 0.05 * np.sin(5 * xs) * np.cos(7 * ys)
    vertices = np.stack([xs.ravel(), zs.ravel(), ys.ravel()], 1).astype(np.float32)
    index = np.arange(k * k).reshape(k, k)
    a, b, c, d = (index[:-1, :-1].ravel(), index[:-1, 1:].ravel(), index[1:, :-1].ravel(),
                  index[1:, 1:].ravel())
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])[:n_tri]
    return vertices, faces.astype(np.int32)


def write_ply(path, vertices, faces):
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    records = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    records["n"], records["i"] = 3, faces
    path.write_bytes(head.encode() + vertices.astype("<f4").tobytes() + records.tobytes())


def write_obj(path, vertices, faces):
    with open(path, "w") as handle:
        np.savetxt(handle, vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(handle, faces + 1, fmt="f %d %d %d")


def per(figures, key, count):
    value = figures[key] / count
    print(f"{key}: {value:.1f} bytes each (limit {LIMITS[key]:.0f})")
    return value


def test_a_texture_costs_about_its_float32_texels(tmp_path):
    """An OBJ with a 2048 x 2048 sRGB PNG as map_Kd: decoded and converted a band of rows at
    a time into its 12 bytes a texel of float32 RGB."""
    size = 2048
    rows = (np.arange(size) % 256).astype(np.uint8)
    image = np.repeat(rows[:, None, None], size, axis=1).repeat(3, axis=2)
    quad = ("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
            "usemtl t\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    for name, pixels in (("big", image), ("tiny", image[:4, :4])):  # tiny: OpenImageIO's
        PIL.Image.fromarray(pixels).save(tmp_path / f"{name}.png")   # start-up, unmeasured
        (tmp_path / f"{name}.mtl").write_text(f"newmtl t\nKd 1 1 1\nmap_Kd {name}.png\n")
        (tmp_path / f"{name}.obj").write_text(f"mtllib {name}.mtl\n" + quad)
    figures = measure("texture", tmp_path / "big.obj")
    assert per(figures, "texture", size * size) < LIMITS["texture"]


def test_an_environment_map_costs_its_image_and_tables(tmp_path):
    """A 2048 x 1024 PNG given as an environment: float32 radiance (12 bytes a pixel) and
    float32 conditional cdfs (4), made a band of rows at a time (whose working arrays weigh
    more on an image this small than on the issue's 16384 x 8192: 16.1 bytes there)."""
    width, height = 2048, 1024
    image = np.zeros((height, width, 3), np.uint8)
    image[:] = (np.arange(height) % 256).astype(np.uint8)[:, None, None]
    PIL.Image.fromarray(image).save(tmp_path / "big.png")
    PIL.Image.fromarray(image[:4, :8]).save(tmp_path / "tiny.png")
    figures = measure("environment", tmp_path / "big.png")
    assert per(figures, "environment", width * height) < LIMITS["environment"]


def test_a_binary_ply_and_its_accelerators_per_triangle(tmp_path):
    """A 200k-triangle binary PLY read straight into the flat arrays, then each backend built
    over it: the peak over the process before the load, per triangle."""
    n_tri = 200_000
    write_ply(tmp_path / "big.ply", *grid_mesh(n_tri))
    write_ply(tmp_path / "tiny.ply", *grid_mesh(2))
    figures = measure("ply", tmp_path / "big.ply", "bvh", "embree")
    for key in ("ply", "ply bvh", "ply embree"):
        assert per(figures, key, n_tri) < LIMITS[key]


def test_an_obj_per_triangle(tmp_path):
    """A 100k-triangle OBJ of `v` and `f` lines: the reader's peak per triangle."""
    n_tri = 100_000
    write_obj(tmp_path / "big.obj", *grid_mesh(n_tri))
    write_obj(tmp_path / "tiny.obj", *grid_mesh(2))
    figures = measure("obj", tmp_path / "big.obj")
    assert per(figures, "obj", n_tri) < LIMITS["obj"]
