"""One frame of a `ptrace view` session as the page gets it: its image, drawn from a snapshot of
the session's sums, and the stats message sent with it.

Separate from ptrace.app.view_session, whose Preview decides when a frame is due and takes the
snapshot under its lock; what follows from the snapshot is computed here, from its values alone.
"""
import time

import numpy as np

from ..features import aov_images
from ..image import course_8bit, rate_colours
from .view_render import mean_image


def draw(rgb, counts, features, width, height, spp, exposure, mode, fallback, override, denoise,
         denoised_of):
    """The frame's images from a snapshot of the sums (rgb, counts and the AOVs' features per
    pixel, or features None): (radiance, counts (height, width), top row first, the 8-bit
    pixels to send, the rate colours or None, the scale the page enlarges them by, the AOV
    images or None, the denoised radiance or None). override: a quick frame's (small image,
    scale, full-size image), sent small; otherwise the summed image at 2**exposure, the
    fallback image where nothing is summed yet, as the rate view in mode "rate", or denoised
    (denoised_of(radiance, aovs)) when denoise is on and the AOVs are summed."""
    w, h = width, height
    gain = np.float32(2.0 ** exposure)
    rate, scale, aovs, denoised = None, 1, None, None
    if features is not None:
        aovs = aov_images(features, counts, (h, w))
    if override is not None:      # a quick frame: sent small, scaled up by the page
        small, scale, radiance = override
        encoded = course_8bit(small * gain)
        counts = counts.reshape(h, w)[::-1]
    else:
        radiance = mean_image((rgb, None, None, counts), w, h)
        counts = counts.reshape(h, w)[::-1]
        if fallback is not None:
            radiance = np.where(counts[..., None] > 0, radiance, fallback)
        if mode == "rate":
            encoded = rate = rate_colours(counts / spp)
        elif denoise and aovs is not None:
            denoised = denoised_of(radiance, aovs)
            encoded = course_8bit(denoised * gain)
        else:
            encoded = course_8bit(radiance * gain)
    return radiance, counts, encoded, rate, scale, aovs, denoised


def stats(*, seq, kind, width, height, scale, quick, pixels, done_samples, spp, mode, denoised,
          exposure, seconds, rays, state, request, request_at):
    """The stats message of frame number seq (kind: "quick", "progress", "pass", "done" or
    "redraw") of a job over `pixels` pixels, done_samples of whose pixels * spp samples are
    traced, in `seconds` with `rays` rays; request and request_at: the last camera message's id
    and when it came (its latency is told on the first quick or pass frame after it)."""
    remaining = pixels * spp - done_samples
    return {"type": "frame", "seq": seq, "kind": kind, "width": width, "height": height,
            "scale": scale,
            "spp": 1.0 if quick else done_samples / pixels,
            "target": spp, "mode": mode, "denoised": denoised,
            "exposure": exposure, "seconds": seconds,
            "rays_per_second": rays / seconds if seconds else 0.0,
            "eta_seconds": seconds / done_samples * remaining
            if done_samples and state == "rendering" else None,
            "state": state, "request": request, "cell": pixels != width * height,
            "latency_ms": None if request_at is None or kind not in ("quick", "pass")
            else 1000 * (time.perf_counter() - request_at)}
