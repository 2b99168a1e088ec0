"""Render the README's pictures into docs/renders/ with the ptrace command line (run from the
repository root: python docs/make_renders.py). The course scene comes from PTRACE_SCENES
(default ../shared/scenes/cs184)."""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.environ.get("PTRACE_SCENES", os.path.join(ROOT, "..", "shared", "scenes", "cs184"))
OUT = os.path.join(ROOT, "docs", "renders")
SIZE = ["-r", "320", "240"]
COMMANDS = {
    "room_obj": ["-s", "256", "-l", "4", "-m", "6", *SIZE, "scenes/files/room.obj"],
    "pbr_glb": ["-s", "256", "-l", "4", "-m", "6", *SIZE, "scenes/files/pbr.glb"],
    "colours_ply": ["-s", "64", "-l", "4", "-m", "4", *SIZE, "scenes/files/colours.ply"],
    "sky_bunny": ["-s", "64", "-l", "4", "-m", "5", "-e", "scenes/sky.exr", *SIZE,
                  os.path.join(SCENES, "sky", "bunny_unlit.dae")],
    "thin_lens": ["-s", "256", "-l", "4", "-m", "5", "-b", "0.08", "-d", "4.5", *SIZE,
                  "scenes/cornell.dae"],
}

if __name__ == "__main__":
    os.makedirs(OUT, exist_ok=True)
    for name, args in COMMANDS.items():
        output = os.path.join(OUT, f"{name}.png")
        command = [sys.executable, "-m", "ptrace", "-q", "-f", output, *args]
        print("ptrace " + " ".join(command[3:]), flush=True)
        subprocess.run(command, cwd=ROOT, check=True)
        os.remove(os.path.join(OUT, f"{name}_rate.png"))
