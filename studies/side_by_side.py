"""The speed targets, side by side: an older checkout of ptrace against this tree, in one run.

    git worktree add /tmp/old 62c98f2          # the last wavefront commit
    python studies/side_by_side.py /tmp/old  # prints each figure, writes /tmp/targets.json

Each figure runs in a fresh process per version (the older one with PYTHONPATH at its checkout
and its own numba cache): the seed's cow command through the CLI (median of 3, start-up
included), CBbunny -s 16 -l 8 -m 6 and CBspheres -s 64 -l 16 -m 6 (the render call, 480x360, 2
threads, kernels compiled beforehand), and the README's render cold (an empty numba cache) and
warm (median of 3), beside `ptrace --info` (interpreter, imports and loading alone). These
machines are noisy and their speed changes from day to day: quote the ratios.
"""
import json
import os
import subprocess
import sys
import tempfile
import time

S = os.environ.get('PTRACE_SCENES', os.path.join(os.path.dirname(__file__), '..', '..', 'shared',
                                                  'scenes', 'cs184')) + '/'
SHIPPED = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'scenes', 'cornell.dae')
NEW = dict(os.environ)
PY = sys.executable
def cli(env, args):
    t = time.perf_counter()
    r = subprocess.run([PY, '-m', 'ptrace', *args], env=env, capture_output=True, text=True,
                       cwd=tempfile.gettempdir())
    assert r.returncode == 0, r.stderr
    return time.perf_counter() - t, r.stdout.strip().splitlines()[-1]
RENDER = """
import sys, time, json, ptrace
s = ptrace.load(sys.argv[1]); kw = json.loads(sys.argv[2])
ptrace.render(s, resolution=(8, 6), **kw)
st = {}; t = time.perf_counter(); ptrace.render(s, resolution=(480, 360), threads=2, stats=st, **kw)
print(time.perf_counter() - t, st['rays'])
"""
def render(env, scene, kw):
    r = subprocess.run([PY, '-c', RENDER, S + scene, json.dumps(kw)], env=env, capture_output=True,
                       text=True, cwd=tempfile.gettempdir())
    assert r.returncode == 0, r.stderr
    sec, rays = r.stdout.split()[-2:]
    return float(sec), int(rays)
def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    old_tree = argv[0] if argv else '/tmp/old'
    OLD = dict(os.environ, PYTHONPATH=old_tree,
               NUMBA_CACHE_DIR=os.path.join(tempfile.gettempdir(), 'ptrace-old-numba-cache'))
    out = {}
    for name, env in (("old", OLD), ("new", NEW)):
        cow = [cli(env, ['-t', '2', '-s', '64', '-l', '16', '-m', '6', '-r', '480', '360', '-f',
                         os.path.join(tempfile.gettempdir(), f'cow_{name}.png'),
                         S + 'meshedit/cow.dae'])[0] for _ in range(3)]
        out[f"cow CLI {name}"] = sorted(cow)[1]
        print(name, "cow CLI", cow, flush=True)
    for name, env in (("old", OLD), ("new", NEW)):
        out[f"CBbunny -s 16 -l 8 -m 6 {name}"] = render(env, 'sky/CBbunny.dae',
                                                        dict(spp=16, light_samples=8, max_depth=6))
        print(name, out[f"CBbunny -s 16 -l 8 -m 6 {name}"], flush=True)
    for name, env in (("old", OLD), ("new", NEW)):
        out[f"CBspheres -s 64 -l 16 -m 6 {name}"] = render(
            env, 'sky/CBspheres.dae', dict(spp=64, light_samples=16, max_depth=6))
        print(name, out[f"CBspheres -s 64 -l 16 -m 6 {name}"], flush=True)
    for name, env in (("old", OLD), ("new", NEW)):
        with tempfile.TemporaryDirectory() as cache:
            e = dict(env, NUMBA_CACHE_DIR=cache)
            args = ['-s', '16', '-l', '4', '-m', '5', '-f',
                    os.path.join(tempfile.gettempdir(), f'cornell_{name}.png'), SHIPPED]
            cold = cli(e, args)
            warm = [cli(e, args) for _ in range(3)]
        info = [cli(env, ['--info', SHIPPED])[0] for _ in range(3)]
        out[f"README cold {name}"] = cold
        out[f"README warm {name}"] = sorted(warm)[1]
        out[f"--info {name}"] = sorted(info)[1]
        print(name, "cold", cold, "warm", sorted(warm)[1], "info", sorted(info)[1], flush=True)
    json.dump(out, open(os.path.join(tempfile.gettempdir(), 'targets.json'), 'w'), indent=1)


if __name__ == '__main__':
    main()
