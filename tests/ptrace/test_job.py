"""The render job (ptrace.rendering.tiles.RenderJob) that the in-process executor, a Dask worker and
the viewer's sessions run: its backend built once, reused for other settings and another camera
without building again (only the records that depend on the settings are made again), and
tracing the same bits as a job built afresh."""
import dataclasses
import pathlib

import numpy as np
import pytest

import accel
import ptrace
from ptrace.app import view_render
from ptrace.integrator import scene_records
from ptrace.rendering.settings import Settings
from ptrace.rendering.tiles import RenderJob, new_sums

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


@pytest.fixture(scope="module")
def cornell():
    return ptrace.load(str(SHIPPED))


@pytest.fixture
def builds(monkeypatch):
    """The kinds accel.build is asked for, in order, while the test runs."""
    kinds, real = [], accel.build

    def counted(kind, geometry, **options):
        kinds.append(kind)
        return real(kind, geometry, **options)
    monkeypatch.setattr(accel, "build", counted)
    return kinds


def same_records(a, b):
    """Whether two records (named tuples of arrays, nested) hold equal arrays."""
    if isinstance(a, tuple):
        return type(a) is type(b) and all(same_records(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b)


def test_a_reused_job_builds_nothing_and_traces_a_fresh_jobs_bits(cornell, builds):
    settings = Settings(spp=2, max_depth=2, accel="naive")
    camera = ptrace.course_camera(cornell, 16, 12)
    job = RenderJob.build(cornell, settings, camera)
    assert builds == ["naive"] and job.build_seconds > 0
    moved = view_render.orbit(camera, 0.3, 0.1)
    other = dataclasses.replace(settings, seed=5, max_depth=3, light_samples=2)
    reused = job.reused(other, moved)
    assert builds == ["naive"]                                  # nothing built again
    assert reused.backend is job.backend and reused.records is job.records
    fresh = RenderJob.build(cornell, other, moved)
    pixels = np.arange(40)
    x, y = pixels % 16, pixels // 16
    traced = [(new_sums(40), j) for j in (reused, fresh)]
    counts = [j.trace(x, y, 0, 3, sums, pixels) for sums, j in traced]
    assert counts[0] == counts[1] and counts[0][1] > 0
    assert reused.rays_traced == counts[0][1]
    (a, _), (b, _) = traced
    assert a[3].sum() > 0 and all(p.tobytes() == q.tobytes() for p, q in zip(a, b))


def test_reusing_a_job_makes_the_records_again_only_for_another_light_tree_choice(cornell,
                                                                                   builds):
    """The scene's records hold the light tree only when the settings choose lights by it (the
    path integrator with --light-sampler bvh): a job of the normals view, reused for the image
    view, gets the records a job built for the image view has."""
    normals = Settings(accel="naive", integrator="normals", light_sampler="bvh")
    camera = ptrace.course_camera(cornell, 16, 12)
    job = RenderJob.build(cornell, normals, camera)
    path = dataclasses.replace(normals, integrator="path")
    image = job.reused(path, camera)
    assert image.backend is job.backend and builds == ["naive"]
    assert image.records is not job.records
    assert same_records(image.records, scene_records(cornell, True))
    assert not same_records(job.records, image.records)
    assert job.reused(dataclasses.replace(normals, spp=9), camera).records is job.records
    with pytest.raises(ValueError, match="naive backend"):
        job.reused(dataclasses.replace(normals, accel="bvh"), camera)


def test_the_viewers_sessions_and_camera_moves_share_one_build_per_kind(cornell, builds):
    notices = []
    backends = view_render.Backends(cornell, notices.append)
    settings = Settings(accel="naive")
    camera = ptrace.course_camera(cornell, 16, 12)
    jobs = [backends.job(settings, camera),
            backends.job(settings, view_render.pan(camera, 3, 1)),
            backends.job(dataclasses.replace(settings, spp=8, max_depth=4), camera)]
    assert builds == ["naive"] and len({id(job.backend) for job in jobs}) == 1
    assert len({id(job.records) for job in jobs}) == 1
    assert not np.array_equal(jobs[0].camera.position, jobs[1].camera.position)
    bvh = backends.job(dataclasses.replace(settings, accel="bvh"), camera)
    assert builds == ["naive", "bvh"] and bvh.backend is not jobs[0].backend
