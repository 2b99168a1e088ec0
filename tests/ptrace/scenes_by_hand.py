"""Small scenes built from arrays (no file) for analytic light-transport tests."""
import numpy as np

import accel
from ptrace.camera import Camera
from ptrace.scene import (
    AMBIENT,
    DIFFUSE,
    DIRECTIONAL,
    POINT,
    CameraSpec,
    Lights,
    Materials,
    Scene,
    area_weighted_normals,
)


def make_scene(vertices=None, faces=None, centers=None, radii=None, materials=(),
               material_index=(), lights=()):
    vertices = np.zeros((0, 3)) if vertices is None else np.asarray(vertices, dtype=float)
    faces = np.zeros((0, 3), dtype=int) if faces is None else np.asarray(faces)
    geometry = accel.Geometry(vertices, faces, centers, radii)
    return Scene(path="<test scene>", geometry=geometry,
                 vertex_normals=area_weighted_normals(geometry.vertices, geometry.faces),
                 material_index=np.asarray(material_index, dtype=np.int32),
                 materials=Materials.from_records(list(materials)),
                 lights=Lights.from_records(list(lights)),
                 camera=CameraSpec(view_point=np.array([0.0, 0.0, 1.0]), position=np.zeros(3)))


def looking_down(height, width=32, screen_dist=16.0):
    """A camera at (0, height, 0) looking straight down -y, image x along +x."""
    axes = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]).T   # columns: right, up, backward
    return Camera(np.array([0.0, height, 0.0]), np.zeros(3), axes, screen_dist, width, width,
                  1e-4, 1e4)


def floor_plane(albedo, half=50.0):
    """Two triangles spanning the plane y = 0."""
    vertices = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]]
    return dict(vertices=vertices, faces=[[0, 2, 1], [0, 3, 2]],
                materials=[dict(kind=DIFFUSE, albedo=(albedo,) * 3)], material_index=[0, 0])


def point_light(position, radiance):
    return dict(kind=POINT, radiance=(radiance,) * 3, position=position)


def directional_light(direction, radiance):
    d = np.asarray(direction, dtype=float)
    return dict(kind=DIRECTIONAL, radiance=(radiance,) * 3, direction=d / np.linalg.norm(d))


def ambient_light(radiance):
    return dict(kind=AMBIENT, radiance=(radiance,) * 3)


def pixel_hits_on_floor(camera):
    """World points where each pixel centre's ray meets y = 0, image rows top first."""
    ys, xs = np.mgrid[0:camera.height, 0:camera.width]
    py = (camera.height - 1 - ys) + 0.5
    d = camera.directions(xs + 0.5, py)
    t = -camera.position[1] / d[..., 1]
    return camera.position + t[..., None] * d


def furnace(albedo, radiance):
    """A closed diffuse sphere (radius 1, seen from inside) with a point light at its centre.

    The point light (no falloff, like the course) gives every wall point direct radiance
    a P / pi; the sphere sees only itself, so each bounce multiplies by a:
    L = (a P / pi) (1 + a + ... + a^(m-1)) -> a P / (pi (1 - a)).
    """
    scene = make_scene(centers=[[0, 0, 0]], radii=[1.0],
                       materials=[dict(kind=DIFFUSE, albedo=(albedo,) * 3)], material_index=[0],
                       lights=[point_light((0, 0, 0), radiance)])
    camera = Camera(np.array([0.0, 0.0, 0.3]), np.zeros(3), np.eye(3), 10.0, 16, 16, 1e-3, 1e3)
    return scene, camera
