"""Two versions' render seconds in adjacent pairs: the median ratio, for machines too noisy for
two separate series of timings.

    git worktree add /tmp/before COMMIT
    python studies/pairs.py /tmp/before . -- -t 2 -s 16 -m 5 -l 1 -r 480 360 SCENE
    python studies/pairs.py --flags-b "--sampler independent" . . -- -s 16 SCENE

Each render runs the command line (`ptrace -q ARGS`) in a fresh process with PYTHONPATH at its
tree and a numba cache of its own (the trees' kernels differ; the same tree shares one), after
one small untimed render of each that compiles or loads its kernels. Pair i renders A then B
(B then A for odd i, so neither always runs on the machine as the other left it) and records
B's render seconds over A's (the figure the command prints: the render alone, not the start).
On the 2-core virtual machines this project runs on, a single render's time moves by 10 % or
more from minute to minute, and a pair's ratio by about as much; the median of 8 or more pairs
moves far less, and the pairs' spread is printed beside it.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile


def render_seconds(tree, args, cache):
    """The render seconds `ptrace -q ARGS` prints, run from `tree`."""
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree), NUMBA_CACHE_DIR=cache)
    done = subprocess.run([sys.executable, "-m", "ptrace.app.cli", "-q", *args], env=env,
                          capture_output=True, text=True)
    found = re.search(r" render ([0-9.]+) s ", done.stdout)
    if done.returncode != 0 or not found:
        sys.exit(f"pairs: {tree}: {done.stderr.strip() or done.stdout.strip()}")
    return float(found.group(1))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tree_a")
    parser.add_argument("tree_b")
    parser.add_argument("-n", "--pairs", type=int, default=8)
    parser.add_argument("--flags-b", default="", help="more flags for B's renders")
    mine, args = (sys.argv[1:], []) if "--" not in sys.argv else (
        sys.argv[1:sys.argv.index("--")], sys.argv[sys.argv.index("--") + 1:])
    options = parser.parse_args(mine)
    for tree in (options.tree_a, options.tree_b):
        if not os.path.isfile(os.path.join(tree, "ptrace", "__init__.py")):
            parser.error(f"{tree} is not a ptrace tree (no ptrace/__init__.py)")
    if not args:
        parser.error("no ptrace arguments: give them after --")
    output = tempfile.mkdtemp(prefix="pairs-")
    caches = {tree: os.path.join(tempfile.gettempdir(), "pairs-cache-" + re.sub(
        r"\W", "_", os.path.abspath(tree))) for tree in (options.tree_a, options.tree_b)}

    def run(which, warm=False):
        tree = options.tree_a if which == "a" else options.tree_b
        extra = options.flags_b.split() if which == "b" else []
        small = ["-s", "1", "-r", "48", "36"] if warm else []
        return render_seconds(tree, [*args, *extra, *small, "-f",
                                     os.path.join(output, f"{which}.exr")], caches[tree])

    run("a", warm=True)
    run("b", warm=True)
    ratios = []
    for pair in range(options.pairs):
        if pair % 2 == 0:
            a = run("a")
            b = run("b")
        else:
            b = run("b")
            a = run("a")
        ratios.append(b / a)
        print(f"pair {pair + 1}: A {a:.3f} s, B {b:.3f} s, B/A {b / a:.3f}", flush=True)
    ratios.sort()
    print(f"median B/A {statistics.median(ratios):.3f} over {len(ratios)} pairs (from "
          f"{ratios[0]:.3f} to {ratios[-1]:.3f})")


if __name__ == "__main__":
    main()
