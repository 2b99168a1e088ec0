"""The compiled light-sampling kernel computes what its Python source says.

Until 2026-11-24 light_samples and hemisphere_samples set the shading frame only under
`if usable:` inside their prange loop; compiled, that frame was an undefined value, and the
microfacet BSDF's answer (it reads wo's x and y, which the diffuse one does not) depended on
what had been compiled earlier in the process: CBbunny_microfacet_cu came out 3.7x too dark,
or with NaN samples, after other tests had run. The oracle here is the kernel's own Python
(`py_func`), run on the same inputs."""
import numpy as np

import ptrace
from ptrace import integrator


def test_light_samples_matches_its_python_on_a_microfacet_scene(scenes_dir, monkeypatch):
    captured = {}
    kernel = integrator.light_samples

    def recording(*args):
        kernel(*args)
        captured.setdefault("args", [a.copy() if isinstance(a, np.ndarray) else a
                                     for a in args])
    monkeypatch.setattr(integrator, "light_samples", recording)
    scene = ptrace.load(scenes_dir / "sky" / "CBbunny_microfacet_cu.dae")
    ptrace.render(scene, spp=2, resolution=(12, 9), max_depth=1, accel="naive")
    args = captured["args"]
    compiled = args[-4:]
    python = [np.zeros_like(a) for a in compiled]
    kernel.py_func(*args[:-4], *python)
    assert np.isfinite(compiled[3]).all()
    assert compiled[3].max() > 0   # some shadow rays carry light
    for ours, reference in zip(compiled, python):
        np.testing.assert_array_equal(ours, reference)
