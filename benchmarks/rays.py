"""Scenes and ray sets shared by the benchmarks and studies.

scenes_dir() is the course scenes' folder ($PTRACE_SCENES, else ../shared/scenes/cs184 beside
the repository); make_rays(kind, geometry, n) is the batch of n rays of one kind that
accel_rays times (the same seeds every run, so every tool and revision traces the same rays);
scene_light(scene) is the area light that shadow rays aim at.
"""
import math
import os
from pathlib import Path

from accel import raygen

RAY_KINDS = ("random", "camera", "secondary", "shadow")


def scenes_dir():
    """The folder of the course scenes, as a Path."""
    here = Path(__file__).resolve().parent.parent
    return Path(os.environ.get("PTRACE_SCENES", here.parent / "shared" / "scenes" / "cs184"))


def make_rays(kind, geometry, n, light=None):
    """n rays of `kind` (RAY_KINDS) at the geometry, seed 0: random from a sphere around it
    toward its bounds; camera, one pinhole ray per pixel of a 4:3 image of about n pixels;
    secondary from points on its triangles in random directions; shadow from the same points
    to a light (`light`, else accel.raygen.light_square above the bounds)."""
    if kind == "random":
        return raygen.sphere_rays(geometry, n, seed=0)
    if kind == "camera":
        width = max(1, round(math.sqrt(n * 4 / 3)))
        return raygen.camera_rays(geometry, width, max(1, n // width), seed=0)
    if kind == "shadow":
        return raygen.shadow_rays(geometry, n, seed=0, light=light)
    return raygen.surface_rays(geometry, n, seed=0)


def scene_light(scene):
    """(centre, edge_x, edge_y) of the scene's first area light, or None."""
    from ptrace.scene import AREA
    lights = scene.lights
    for i in range(len(lights)):
        if lights.kind[i] == AREA:
            return lights.position[i], lights.edge_x[i], lights.edge_y[i]
    return None
