"""Feature buffers (AOVs): what each camera ray's first hit is, averaged per pixel like the
radiance, for a denoiser's guides and for users: albedo, shading normal and distance.

The kernel side is `ptrace.kernel.aovs.hit_features`, which the wavefront's features_stage takes of
each camera ray's hit when a render asks for AOVs (`ptrace.render(..., aovs={})`, the CLI's
`--aov`): the camera rays are traced once more for it, before the paths start from them, so a
render without AOVs pays nothing and a render with them pays one ray per sample. Here: the
names, the per-pixel images from the sums, and the denoiser. `denoise` runs Intel Open Image Denoise
through the optional `pyoidn` package (`pip install "ptrace[denoise]"`).
"""
import numpy as np

AOV_NAMES = ("albedo", "normal", "depth")
AOV_CHANNELS = {"albedo": ("albedo.R", "albedo.G", "albedo.B"),
                "normal": ("normal.X", "normal.Y", "normal.Z"), "depth": ("depth.Z",)}
FEATURES = 8      # per-pixel sums: albedo (3), normal (3), distance over hits, hits


def parse_aovs(text):
    """`--aov albedo,normal,depth` -> a tuple of names; ValueError naming what is unknown."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in AOV_NAMES]
    if unknown or not names:
        raise ValueError(f"--aov takes a comma-separated list of {', '.join(AOV_NAMES)}; got "
                         f"{text!r}")
    return names


def aov_images(sum_features, count, shape):
    """{name: image} from per-pixel feature sums and sample counts (rows bottom first, as the
    render's sums), top row first: albedo and normal are means over the samples (a miss counts
    zero, like black radiance), depth the mean distance over the samples that hit (inf where
    none did)."""
    n = np.maximum(count, 1)[:, None]
    height, width = shape
    flip = lambda a: a.reshape((height, width) + a.shape[1:])[::-1].astype(np.float32)  # noqa: E731
    hits = sum_features[:, 7]
    depth = np.where(hits > 0, sum_features[:, 6] / np.maximum(hits, 1), np.inf)
    return {"albedo": flip(sum_features[:, 0:3] / n), "normal": flip(sum_features[:, 3:6] / n),
            "depth": flip(depth)}


def require_denoiser():
    """pyoidn, or a PtraceError naming the extra that installs it (checked before a render, so
    that a missing denoiser does not cost the render first)."""
    from .errors import PtraceError
    try:
        import pyoidn
    except ImportError:
        raise PtraceError("--denoise needs Intel Open Image Denoise's Python package: "
                          "pip install \"ptrace[denoise]\" (or pip install pyoidn)") from None
    return pyoidn


def denoised_path(path):
    """Where --denoise writes: NAME_denoised.EXT beside NAME.EXT."""
    import os
    stem, extension = os.path.splitext(path)
    return f"{stem}_denoised{extension}"


def denoise(image, albedo=None, normal=None):
    """Intel Open Image Denoise's RT filter (HDR) on a linear image, guided by albedo and normal
    AOVs when given, through pyoidn (the optional extra ptrace[denoise]; imported only here).
    The result is biased: keep the noisy image beside it."""
    pyoidn = require_denoiser()
    colour = np.ascontiguousarray(np.nan_to_num(image, nan=0.0, posinf=0.0), dtype=np.float32)
    guides = {}
    if albedo is not None:
        guides["albedo"] = np.ascontiguousarray(np.clip(albedo, 0.0, 1.0), dtype=np.float32)
    if normal is not None:
        guides["normal"] = np.ascontiguousarray(np.clip(normal, -1.0, 1.0), dtype=np.float32)
        if albedo is None:   # OIDN takes a normal only beside an albedo
            guides["albedo"] = np.ones_like(colour)
    return pyoidn.denoise(colour, hdr=True, **guides)
