"""Write scenes/sky.exr, the environment map ptrace ships (a user's first `-e`, and the tests'):
a lat-long sky, +Y up, 128 x 64, linear radiance. Run from the repository root:

    python scenes/make_sky.py

The sky is a gradient from a pale horizon (1.0, 1.0, 1.0) to a deeper zenith (0.35, 0.55, 1.0),
a dim ground (0.3, 0.25, 0.2) below the horizon, and a small sun (radius 2.5 degrees, radiance
400 x (1.0, 0.95, 0.85)) 30 degrees above the horizon: most of the light comes from a little of
the sphere, which is what importance sampling is for.
"""
import math
import os

import numpy as np

WIDTH, HEIGHT = 128, 64
SUN_ELEVATION, SUN_AZIMUTH, SUN_RADIUS = 30.0, 60.0, 2.5    # degrees
SUN = 400.0 * np.array([1.0, 0.95, 0.85])


def directions(width, height):
    """Unit direction of each pixel centre, with ptrace's (the course's) lat-long mapping:
    theta = pi (y + 0.5) / H from +Y, phi = 2 pi (x + 0.5) / W, d = (sin theta cos(phi - pi),
    cos theta, -sin theta sin(phi - pi))."""
    theta = (np.arange(height) + 0.5) / height * math.pi
    phi = (np.arange(width) + 0.5) / width * 2 * math.pi - math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], axis=-1)


def sky(width=WIDTH, height=HEIGHT):
    d = directions(width, height)
    up = np.clip(d[..., 1], 0.0, 1.0)[..., None]
    image = (1 - up) * np.array([1.0, 1.0, 1.0]) + up * np.array([0.35, 0.55, 1.0])
    image = np.where(d[..., 1:2] < 0, np.array([0.3, 0.25, 0.2]), image)
    e, a = math.radians(SUN_ELEVATION), math.radians(SUN_AZIMUTH)
    sun = np.array([math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)])
    inside = d @ sun >= math.cos(math.radians(SUN_RADIUS))
    image[inside] = SUN
    return image.astype(np.float32)


def main(path=os.path.join(os.path.dirname(os.path.abspath(__file__)), "sky.exr")):
    import OpenImageIO as oiio
    image = sky()
    output = oiio.ImageOutput.create(path)
    spec = oiio.ImageSpec(image.shape[1], image.shape[0], 3, oiio.FLOAT)
    spec.attribute("compression", "zip")
    if output is None or not output.open(path, spec) or not output.write_image(image):
        raise SystemExit(f"{path}: cannot write ({oiio.geterror()})")
    output.close()
    sun = int((image[..., 0] > 100).sum())
    print(f"{path}: {image.shape[1]} x {image.shape[0]}, sun pixels {sun}")


if __name__ == "__main__":
    main()
