"""PathTracer: drives the integrator's kernels (ptrace.integrator) wave by wave for a batch of
camera rays, handing every ray batch to the accelerator. Knows nothing of pixels or passes."""
import numpy as np

import accel

from . import integrator as k
from .scene import DIRECTIONAL, EMISSION, POINT
from .shading import normal_colours, shading_normals


class PathTracer:
    def __init__(self, scene, backend, seed, integrator="path", light_samples=1, max_depth=1,
                 hemisphere=False, roulette=True):
        self.scene = scene
        self.backend = backend
        self.seed = int(seed)
        self.integrator = integrator
        self.light_samples = light_samples
        self.max_depth = max_depth
        self.hemisphere = hemisphere
        self.roulette = roulette
        self.rays_traced = 0
        self.warnings = []
        geometry = scene.geometry
        self.scale = k.primitive_scale(geometry) if integrator == "path" else None
        materials = scene.materials
        self.kinds = np.ascontiguousarray(materials.kind, dtype=np.int64)
        lights = scene.lights
        delta = int(np.isin(lights.kind, [POINT, DIRECTIONAL]).sum())
        if hemisphere:
            self.samples_per_vertex = len(lights) * light_samples
            emitters = np.isin(scene.material_index,
                               np.nonzero(materials.kind == EMISSION)[0]).any()
            if integrator == "path" and max_depth >= 1 and not emitters:
                self.warnings.append(
                    "hemisphere sampling (-H) sees only emissive geometry and this scene has "
                    "none (its lights are point, directional, ambient or area lights without "
                    "a mesh): direct light will be black")
        else:
            self.samples_per_vertex = delta + light_samples * (len(lights) - delta)
        self.rays_per_path = 1 + (self.samples_per_vertex if integrator == "path" else 0)

    # -- one wave of camera rays --------------------------------------------------------------
    def trace(self, pixel, sample, rays):
        n = len(rays)
        hits = self.backend.intersect(rays)
        self.rays_traced += n
        if self.integrator == "normals":
            g = self.scene.geometry
            normals = shading_normals(self.scene.vertex_normals, g.faces, g.centers, g.radii,
                                      rays.origins, rays.directions, hits.t, hits.prim, hits.u,
                                      hits.v, np.empty((n, 3)))
            return normal_colours(normals, hits.prim, np.empty((n, 3)))
        return self._paths(pixel, sample, rays, hits)

    def _surface(self, rays, hits):
        g = self.scene.geometry
        n = len(rays)
        point, geo, normal = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
        material, offset = np.empty(n, dtype=np.int64), np.empty(n)
        k.surfaces(g.vertices, g.faces, g.centers, g.radii, self.scene.vertex_normals,
                   self.scene.material_index, self.kinds, self.scale, rays.origins,
                   rays.directions, hits.t, hits.prim, hits.u, hits.v, point, geo, normal,
                   material, offset)
        return point, geo, normal, material, offset

    def _paths(self, pixel, sample, rays, hits):
        n = len(rays)
        m = self.scene.materials
        out = np.zeros((n, 3))
        owner = np.arange(n)
        directions = rays.directions
        throughput = np.ones((n, 3))
        point, geo, normal, material, offset = self._surface(rays, hits)
        alive = material >= 0
        radiance = np.zeros((n, 3))
        k.add_emission(material, self.kinds, m.emission, throughput, alive, radiance)
        for vertex in range(1, self.max_depth + 1):
            if not alive.any():
                break
            if self.samples_per_vertex:
                self._direct(vertex, pixel, sample, directions, point, geo, normal, material,
                             offset, alive, throughput, radiance)
            if vertex == self.max_depth:
                break
            count = alive.shape[0]
            origins, new_dirs = np.empty((count, 3)), np.empty((count, 3))
            delta = np.zeros(count, dtype=np.bool_)
            k.bounce(self.seed, vertex, pixel, sample, directions, point, geo, normal, material,
                     offset, alive, self.kinds, m.albedo, m.transmittance, m.ior, m.alpha, m.eta,
                     m.k, throughput, self.roulette and vertex >= 2, origins, new_dirs,
                     delta)
            # retire finished paths into out; compact the live ones for the bounce wave
            live = (np.empty(count, dtype=np.int64), np.empty(count, dtype=np.int64),
                    np.empty(count, dtype=np.int64), np.empty((count, 3)), np.empty((count, 3)),
                    np.empty(count, dtype=np.bool_), np.empty((count, 3)), np.empty((count, 3)))
            n_live = k.retire_and_compact(alive, owner, pixel, sample, throughput, radiance,
                                          delta, origins, new_dirs, out, *live)
            owner, pixel, sample, throughput, radiance, delta, origins, directions = \
                (array[:n_live] for array in live)
            bounce_rays = accel.Rays(origins, directions)
            hits = self.backend.intersect(bounce_rays)
            self.rays_traced += len(bounce_rays)
            point, geo, normal, material, offset = self._surface(bounce_rays, hits)
            alive = material >= 0
            # a delta bounce sees emitters directly (light sampling cannot)
            k.add_emission(material, self.kinds, m.emission, throughput, alive & delta, radiance)
        out[owner] += radiance
        return out

    def _direct(self, vertex, pixel, sample, directions, point, geo, normal, material, offset,
                alive, throughput, radiance):
        m, lights = self.scene.materials, self.scene.lights
        per_path = self.samples_per_vertex
        count = alive.shape[0] * per_path
        origins, dirs = np.empty((count, 3)), np.empty((count, 3))
        tmax, weight = np.empty(count), np.empty((count, 3))
        if self.hemisphere:
            k.hemisphere_samples(self.seed, vertex, pixel, sample, directions, point, geo, normal,
                                 material, offset, alive, self.kinds, m.albedo, m.alpha, m.eta,
                                 m.k, per_path, origins, dirs, tmax, weight)
            rays = accel.Rays(origins, dirs, 0.0, tmax)
            hits = self.backend.intersect(rays)
            hit_material = np.where(hits.prim >= 0,
                                    self.scene.material_index[np.maximum(hits.prim, 0)], -1)
            k.gather(weight, hits.prim >= 0, True, hit_material, self.kinds, m.emission,
                     per_path, throughput, radiance)
        else:
            k.light_samples(self.seed, vertex, pixel, sample, directions, point, geo, normal,
                            material, offset, alive, self.kinds, m.albedo, m.alpha, m.eta, m.k,
                            lights.kind, lights.radiance, lights.position, lights.direction,
                            lights.edge_x, lights.edge_y, lights.area, self.light_samples,
                            per_path, origins, dirs, tmax, weight)
            rays = accel.Rays(origins, dirs, 0.0, tmax)
            blocked = self.backend.occluded(rays)
            k.gather(weight, ~blocked & (tmax >= 0), False, np.empty(0, dtype=np.int64),
                     self.kinds, m.emission, per_path, throughput, radiance)
        self.rays_traced += int((tmax >= 0).sum())
