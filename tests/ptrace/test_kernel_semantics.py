"""The compiled path loop computes what its Python source says.

Until 2026-11-24 the wavefront's light-sampling kernels set the shading frame only under
`if usable:` inside their prange loop; compiled, that frame was an undefined value, and the
microfacet BSDF's answer (it reads wo's x and y, which the diffuse one does not) depended on
what had been compiled earlier in the process: CBbunny_microfacet_cu came out 3.7x too dark,
or with NaN samples, after other tests had run. The oracle here is the same render with numba's
JIT turned off (NUMBA_DISABLE_JIT=1 in a subprocess): every kernel, the accelerator's compiled
face included, runs as plain Python."""
import os
import subprocess
import sys

import numpy as np

import ptrace

RENDER = """
import sys, numpy as np, ptrace
scene = ptrace.load(sys.argv[1])
image = ptrace.render(scene, spp=2, resolution=(6, 5), max_depth=2, light_samples=2,
                      accel="naive", seed=4)
np.save(sys.argv[2], image)
"""


def test_compiled_loop_matches_its_python_on_a_microfacet_scene(scenes_dir, tmp_path):
    path = scenes_dir / "sky" / "CBspheres_microfacet_al_ag.dae"
    kwargs = dict(spp=2, resolution=(6, 5), max_depth=2, light_samples=2, accel="naive", seed=4)
    compiled = ptrace.render(ptrace.load(path), **kwargs)
    out = tmp_path / "python.npy"
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    subprocess.run([sys.executable, "-c", RENDER, str(path), str(out)], check=True, env=env,
                   timeout=600)
    python = np.load(out)
    assert np.isfinite(compiled).all() and compiled.max() > 0
    np.testing.assert_array_equal(compiled, python)
