"""load_mitsuba: a Mitsuba 3 XML scene (and the 0.4-0.6 files Mitsuba upgrades) into a Scene.

ptrace.io.mitsuba_xml parses the file into plugins; this module turns them into ptrace's
geometry, materials (ptrace.io.mitsuba_materials), lights and camera. What each plugin becomes
is docs/usage.md's table "Mitsuba scenes". What ptrace draws differently is one note per kind;
what it would draw wrongly (media, unsupported plugins, a mirroring camera) is refused in one
SceneError line naming the file and the element. The scene has the file's lights only: no
default light, so an unlit file renders black as it does in Mitsuba.
"""
import math

import numpy as np

import accel

from .. import budget
from ..budget import BudgetError
from ..environment import Environment
from ..errors import SceneError
from ..rendering.settings import RANGES
from ..scene import (
    ANGULAR,
    DIRECTIONAL,
    EMISSION,
    PHYSICAL,
    POINT,
    SPOT,
    FileCamera,
    Lights,
    Materials,
    Scene,
    Textures,
    area_weighted_normals,
)
from . import mitsuba_shapes as shapes
from .files import describe_failure
from .materials import TexturePool, read_image_file
from .mitsuba_materials import Materials as MaterialTable
from .mitsuba_serialized import read_serialized
from .mitsuba_xml import Colour, Plugin, Reader

SHAPES = ("obj", "ply", "serialized", "rectangle", "cube", "disk", "sphere")
# integrators whose expected image is the path tracer's (of 3.x and of the 0.6 files upgraded)
UPSAMPLE, FINE_ENVMAP = 16, 2048     # latlong_from_mitsuba's resampling of small maps
INTEGRATORS = ("path", "volpath", "volpathmis", "ptracer", "prb", "prbvolpath", "bdpt", "mlt",
               "pssmlt", "erpt", "sppm", "photonmapper", "volpath_simple", "guided_path")


def load_mitsuba(path, defines=None):
    """Read a Mitsuba XML scene; defines ({name: value}, the CLI's -D) set $name before the
    file's <default>s. Any problem raises SceneError."""
    path = str(path)
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            return Builder(path, defines).build()
    except (SceneError, BudgetError):
        raise
    except Exception as error:      # a case the explicit checks missed: still one line
        raise SceneError(path, f"could not read the scene: {describe_failure(error)}") \
            from error


class Builder:
    """Walks the scene's plugins into flat arrays."""

    def __init__(self, path, defines):
        self.path = path
        self.reader = Reader(path, defines)
        self.notes = []
        self.pool = TexturePool(path)
        self.materials = MaterialTable(self.reader, self.pool, self.notes)
        self.vertices, self.faces, self.normals, self.uvs, self.tri_materials = [], [], [], [], []
        self.centres, self.radii, self.sphere_materials = [], [], []
        self.count = 0
        self.lights, self.cameras, self.environment = [], [], None
        self.settings = {}
        self.delta_scale = 1        # of point, spot and directional lights (_integrator)

    def build(self):
        scene = self.reader.read()
        self.notes.extend(self.reader.notes)
        if self.reader.upgrade:
            self.notes.append(f"a Mitsuba {self.reader.version} file, upgraded as Mitsuba 3 "
                              f"upgrades it")
        self._count_meshes(scene)
        # an area emitter declared at the top with an id and <ref>'d from shapes (as
        # Mitsuba's cbox-rgb.xml does) is each shape's, not an emitter of its own
        self.shape_emitters = {id(p) for shape in scene.children if shape.tag == "shape"
                               for p in list(shape.children) + list(shape.params.values())
                               if isinstance(p, Plugin) and p.tag == "emitter"}
        for plugin in scene.children:
            handler = getattr(self, "_" + plugin.tag, None)
            if handler is not None:
                handler(plugin)
            elif plugin.tag in ("medium", "volume", "phase"):
                plugin.fail("participating media are not supported by ptrace")
        return self._finish()

    # --- shapes ---------------------------------------------------------------------------

    def _count_meshes(self, scene):
        """Check the memory budget (ptrace.budget) for the triangles of every mesh file the
        scene places (mitsuba_shapes.file_triangles), before any of them is read; each is
        charged again as it is read."""
        total, count = 0, 0
        for shape in scene.children:
            if shape.tag == "shape" and shape.type in ("obj", "ply", "serialized") and \
                    shape.params.get("filename") is not None:
                path = self.reader.resolve(shape, shape.string("filename"))
                total += shapes.file_triangles(shape, path)
                count += 1
        if count:
            budget.current().charge(
                self.path, f"the {total:,} triangles of its {count} mesh "
                           f"file{'s' if count > 1 else ''}", 0,
                total * budget.LOAD_BYTES_PER_TRIANGLE)

    def _shape(self, shape):
        if shape.type not in SHAPES:
            shape.fail(f"shape type {shape.type!r} is not supported (ptrace reads "
                       f"{', '.join(SHAPES)})")
        for name in ("interior", "exterior"):
            if shape.has(name):
                shape.fail("participating media (interior, exterior) are not supported")
        bsdf = self._one(shape, "bsdf")
        emitter = self._one(shape, "emitter")
        if emitter is not None and emitter.type != "area":
            emitter.fail("only an area emitter can sit on a shape")
        radiance = None
        if emitter is not None:
            radiance = self._radiance(emitter, "radiance")
            self._unread(emitter)
        material = self.materials.index(bsdf)
        if shape.type == "sphere":
            centre, radius = shapes.sphere(shape)
            material = self.materials.untextured(material, "<shape type=\"sphere\">")
            if radiance is not None:
                material = self.materials.emitter(radiance)
                self.notes.append("<shape type=\"sphere\">: an area emitter on a sphere does "
                                  "not also reflect (ptrace's emitters do not)")
            self.centres.append(centre)
            self.radii.append(radius)
            self.sphere_materials.append(material)
            self._unread(shape)
            return
        if shape.type in ("obj", "ply"):
            name = shape.string("filename")
            if name is None:
                shape.fail("has no filename")
            vertices, faces, uv = shapes.mesh_file(shape, self.reader.resolve(shape, name),
                                                   self.notes, self.materials.textures(material))
        elif shape.type == "serialized":
            name = shape.string("filename")
            if name is None:
                shape.fail("has no filename")
            vertices, faces, uv, flat = read_serialized(self.reader.resolve(shape, name),
                                                        shape.integer("shape_index", 0))
            shape.params.setdefault("face_normals", flat)
        else:
            vertices, faces, uv = getattr(shapes, shape.type)()
        transform = self.materials.uv_transforms.get(material)
        one_sided = material in self.materials.one_sided
        # Mitsuba's black back, where a one-sided surface can be seen from behind (the
        # file's own vertex indices, before face_normals splits them)
        open_back = one_sided and radiance is None and not shapes.closed(vertices, faces)
        if uv is None:
            material = self.materials.untextured(material, f"<shape type=\"{shape.type}\">")
        elif transform is not None:
            uv = uv @ transform[:2, :2].T + transform[:2, 2]
        vertices, faces, uv = shapes.placed(shape, vertices, faces, uv)
        if radiance is not None:    # the emitting front, and behind it the reflecting back
            front = self.materials.glowing(material, radiance)
            self._add_triangles(vertices, faces, uv, self.materials.emitter(radiance)
                                if front is None else front)
            vertices, faces, uv = self._backing(shape, vertices, faces, uv)
            self.notes.append(f"<shape type=\"{shape.type}\">: an area emitter: its shape "
                              f"emits from its front only, as Mitsuba's, and "
                              + ("is black from its back (its BSDF is one-sided)" if one_sided
                                 else "reflects with its BSDF from its back")
                              + f" ({shapes.BACKING:g} of its size behind)"
                              + (", not from its front" if front is None else ""))
            self._add_triangles(vertices, faces, uv,
                                self.materials.black() if one_sided else material)
            self._unread(shape)
            return
        self._add_triangles(vertices, faces, uv, material)
        if open_back:
            self._add_triangles(*self._backing(shape, vertices, faces, uv),
                                self.materials.black())
        self._unread(shape)

    def _backing(self, shape, vertices, faces, uv):
        """shapes.backing of a placed shape, its triangles charged to the memory budget first
        (the count before reading, _count_meshes, has only the files' own triangles: whether a
        mesh is open is known once it is read)."""
        budget.current().triangles(shape.path, len(faces),
                                   f"the back of {shape.where} ({len(faces):,} triangles)")
        return shapes.backing(vertices, faces, uv)

    def _add_triangles(self, vertices, faces, uv, material):
        self.vertices.append(vertices)
        self.faces.append(faces + self.count)
        self.normals.append(area_weighted_normals(vertices, faces))
        self.uvs.append(np.zeros((len(faces), 3, 2)) if uv is None else uv)
        self.tri_materials.append(np.full(len(faces), material, np.int32))
        self.count += len(vertices)

    def _one(self, plugin, tag):
        found = [p for p in plugin.children if p.tag == tag] + \
            [v for k, v in plugin.params.items() if isinstance(v, Plugin) and v.tag == tag
             and plugin.get(k) is not None]
        if len(found) > 1:
            plugin.fail(f"has {len(found)} <{tag}> elements (at most one)")
        return found[0] if found else None

    # --- emitters -------------------------------------------------------------------------

    def _radiance(self, emitter, name, default=(1.0, 1.0, 1.0)):
        value = emitter.colour(name, Colour(default))
        if isinstance(value, Plugin):
            emitter.fail(f"a texture for {name!r} is not supported")
        if min(value) < 0:
            emitter.fail(f"{name} is negative")
        return tuple(value)

    def _emitter(self, emitter):
        transform = emitter.transform("to_world")
        kind = emitter.type
        if kind == "point":
            position = emitter.point("position")
            position = transform.apply([0.0, 0.0, 0.0])[0] if position is None else position
            self.lights.append({"kind": POINT, "model": PHYSICAL, "position": position,
                                "radiance": self._radiance(emitter, "intensity")})
        elif kind == "spot":
            if emitter.has("texture"):
                emitter.fail("a spot light's texture (a projected image) is not supported: "
                             "the image would be wrong")
            cutoff = emitter.float("cutoff_angle", 20.0)
            beam = emitter.float("beam_width", cutoff * 0.75)
            if not 0 < beam <= cutoff < 180:
                emitter.fail("needs 0 < beam_width <= cutoff_angle < 180 degrees")
            axis = transform.vectors([[0.0, 0.0, 1.0]])[0]
            self.lights.append({"kind": SPOT, "model": PHYSICAL,
                                "position": transform.apply([0.0, 0.0, 0.0])[0],
                                "direction": axis / np.linalg.norm(axis),
                                "cos_inner": math.cos(math.radians(beam)),
                                "cos_outer": math.cos(math.radians(cutoff)),
                                "falloff": ANGULAR,     # Mitsuba's: linear in the angle
                                "radiance": self._radiance(emitter, "intensity")})
        elif kind == "directional":
            direction = emitter.point("direction")
            if direction is None:
                direction = transform.vectors([[0.0, 0.0, 1.0]])[0]
            if not np.linalg.norm(direction) > 0:
                emitter.fail("direction is zero")
            self.lights.append({"kind": DIRECTIONAL,
                                "direction": -direction / np.linalg.norm(direction),
                                "radiance": self._radiance(emitter, "irradiance")})
        elif kind in ("constant", "envmap"):
            if self.environment is not None:
                emitter.fail("a second environment emitter (ptrace has one environment)")
            self.environment = self._environment(emitter, transform)
        elif kind == "area":
            if id(emitter) in self.shape_emitters:
                return
            emitter.fail("an area emitter must sit inside a <shape> (or be <ref>'d from one)")
        else:
            emitter.fail(f"emitter type {kind!r} is not supported (ptrace reads area, point, "
                         f"spot, directional, constant, envmap)")
        self._unread(emitter)

    def _environment(self, emitter, transform):
        if emitter.type == "constant":
            return Environment.constant(self._radiance(emitter, "radiance"))
        name = emitter.string("filename")
        if name is None:
            emitter.fail("has no filename")
        path = self.reader.resolve(emitter, name)
        try:
            pixels, _ = read_image_file(path, f"the environment map {name!r}", self.path)
        except (BudgetError, SceneError):
            raise
        except Exception as error:      # noqa: BLE001 - OpenImageIO's failures
            emitter.fail(f"cannot read the image {name!r}: {str(error)[:120]}")
        if pixels.shape[2] < 3:
            pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
        scale = emitter.float("scale", 1.0)
        image = latlong_from_mitsuba(np.asarray(pixels[:, :, :3], np.float64),
                                     transform.inverse[:3, :3]) * scale
        return Environment(np.maximum(image, 0.0), name=path)

    # --- sensor and settings --------------------------------------------------------------

    def _sensor(self, sensor):
        if sensor.type not in ("perspective", "thinlens"):
            sensor.fail(f"sensor type {sensor.type!r} is not supported (ptrace renders "
                        f"perspective and thinlens)")
        from ..rendering.renderer import MAX_SIDE
        film = self._one(sensor, "film")
        width, height = 768, 576        # Mitsuba's film without a <film>
        if film is not None:
            width, height = film.integer("width", 768), film.integer("height", 576)
            if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
                film.fail(f"width and height must be from 1 to {MAX_SIDE}, not "
                          f"{width}x{height}")
        if not self.cameras:    # the first sensor's, as Mitsuba renders the first
            self.settings["resolution"] = (width, height)
        if film is not None:
            if any(film.has(k) for k in ("crop_offset_x", "crop_offset_y", "crop_width",
                                         "crop_height")):
                self.notes.append("<film>: its crop window ignored: ptrace renders the whole "
                                  "image (-p crops)")
            filters = [c for c in film.children if c.tag == "rfilter"] + \
                [v for v in film.params.values() if isinstance(v, Plugin) and v.tag == "rfilter"]
            kind = filters[0].type if filters else "gaussian"
            if kind != "box":
                self.notes.append(f"<film>: its {kind} reconstruction filter (Mitsuba's default: "
                                  f"gaussian) not applied: ptrace's pixels weigh their samples "
                                  f"equally (a box), the same mean, a sharper image")
            for child in film.children:
                child._read.update(child.params)
            film._read.update(film.params)
        sampler = self._one(sensor, "sampler")
        spp = 4     # Mitsuba's independent sampler without a <sampler>
        if sampler is not None:
            spp = sampler.integer("sample_count", 4)
            low, high = RANGES["spp"]
            if not low <= spp <= high:
                sampler.fail(f"sample_count must be from {low} to {high}, not {spp}")
            sampler._read.update(sampler.params)
            self.notes.append(f"<sampler type=\"{sampler.type}\">: ptrace draws its own "
                              f"points (--sampler, Owen-scrambled Sobol' by default) for its "
                              f"sample_count: the same expected image")
        if not self.cameras:
            self.settings["spp"] = spp
        yfov = self._yfov(sensor, width / height)
        matrix = sensor.transform("to_world").matrix
        axes = matrix[:3, :3] @ np.diag([-1.0, 1.0, -1.0])    # Mitsuba: left, up, forward
        lengths = np.linalg.norm(axes, axis=0)
        axes = axes / lengths
        if not np.allclose(axes.T @ axes, np.eye(3), atol=1e-4):
            sensor.fail("to_world shears the camera (its axes are not at right angles)")
        if np.linalg.det(axes) < 0:
            sensor.fail("to_world mirrors the image (a negative scale); ptrace's cameras "
                        "cannot")
        near, far = sensor.float("near_clip", 0.01), sensor.float("far_clip", 10000.0)
        if not 0 < near < far:      # Mitsuba refuses near_clip <= 0 too
            sensor.fail(f"near_clip {near:g} and far_clip {far:g}: need 0 < near_clip < "
                        f"far_clip")
        if sensor.has("near_clip") or sensor.has("far_clip"):
            self.notes.append(f"<sensor type=\"{sensor.type}\">: near_clip {near:g} and "
                              f"far_clip {far:g} cut each camera ray at those distances along "
                              f"it (Mitsuba's: at those depths along the view axis; the same "
                              f"in the image's centre)")
        if sensor.type == "thinlens":
            self._lens(sensor, far)
        else:
            sensor.get("focus_distance")    # Mitsuba's perspective sensor ignores it too
        self.cameras.append(FileCamera(
            name=sensor.id or sensor.type, node=len(self.cameras), kind="perspective",
            position=matrix[:3, 3].copy(), camera_to_world=axes, znear=near, zfar=far,
            yfov=yfov, aspect=width / height))
        self._unread(sensor)

    def _lens(self, sensor, far):
        """The thin lens of a thinlens sensor (Mitsuba's: aperture_radius required,
        focus_distance, the depth of the plane in focus, by default far_clip), for -b and -d
        where the command line does not give them (render_defaults: lens_radius,
        focal_distance); the first sensor's only, as the others are not the default camera."""
        from ..io.limits import LIMIT
        if not sensor.has("aperture_radius"):
            sensor.fail("has no aperture_radius (Mitsuba requires one)")
        radius = sensor.float("aperture_radius")
        distance = sensor.float("focus_distance", far)
        if not 0 <= radius <= LIMIT:
            sensor.fail(f"aperture_radius {radius:g}: need 0 <= aperture_radius <= {LIMIT:g}")
        if not 0 < distance <= LIMIT:
            sensor.fail(f"focus_distance {distance:g}: need 0 < focus_distance <= {LIMIT:g}")
        if not self.cameras:
            self.settings["lens_radius"], self.settings["focal_distance"] = radius, distance
        else:
            self.notes.append(f"<sensor type=\"thinlens\">: not the first sensor: rendered "
                              f"(--camera-index) as a pinhole unless given -b {radius:g} "
                              f"-d {distance:g}")

    def _yfov(self, sensor, aspect):
        """The vertical field of view (degrees) of the sensor's fov on its fov_axis."""
        axis = sensor.string("fov_axis", "x")
        if sensor.has("focal_length") or not sensor.has("fov"):     # Mitsuba's default: 50mm
            text = str(sensor.get("focal_length", "50mm")).strip().removesuffix("mm")
            try:
                focal = float(text)
            except ValueError:
                sensor.fail(f"focal_length {text[:20]!r} is not a length in mm")
            fov, axis = math.degrees(2 * math.atan(math.hypot(36, 24) / (2 * focal))), \
                "diagonal"
        else:
            fov = sensor.float("fov")
        if not 0 < fov < 180:
            sensor.fail(f"fov {fov:g} is not between 0 and 180 degrees")
        half = math.tan(math.radians(fov) / 2)
        if axis == "smaller":
            axis = "x" if aspect < 1 else "y"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
        if axis == "x":
            half /= aspect
        elif axis == "diagonal":
            half /= math.hypot(aspect, 1.0)
        elif axis != "y":
            sensor.fail(f"fov_axis {axis!r} is none of x, y, diagonal, smaller, larger")
        return math.degrees(2 * math.atan(half))

    def _integrator(self, integrator):
        if integrator.type == "moment":     # the moments of its nested integrator's image
            nested = self._one(integrator, "integrator")
            integrator._read.update(integrator.params)
            if nested is None:
                integrator.fail("has no nested <integrator>")
            self.notes.append("<integrator type=\"moment\">: its nested integrator's image "
                              "rendered (not the moments)")
            return self._integrator(nested)
        if integrator.type not in INTEGRATORS + ("direct",):
            integrator.fail(f"integrator type {integrator.type!r} is not supported (ptrace "
                            f"renders what path, direct and the other light-transport "
                            f"integrators render)")
        depth = integrator.integer("max_depth", -1)
        if integrator.type == "direct":
            depth = 2
            # Mitsuba 3's direct integrator sums its emitter_samples samples of a point, spot
            # or directional light without dividing by their count (its MIS weight of a delta
            # light is 1, where an area light's is 1 / emitter_samples): such lights render
            # emitter_samples times as bright, as _finish scales them
            # (with none, only its BSDF samples, which never find such a light)
            self.delta_scale = integrator.integer("emitter_samples", 1)
            if not 0 <= self.delta_scale <= 1 << 16:
                integrator.fail(f"emitter_samples {self.delta_scale} is not from 0 to 65536")
        elif integrator.has("rr_depth"):
            rr_depth = integrator.integer("rr_depth")
            low, high = RANGES["rr_depth"]
            if not low <= rr_depth:
                integrator.fail(f"rr_depth {rr_depth} is less than {low}")
            self.settings["rr_depth"] = min(rr_depth, high)
        elif integrator.type != "path":
            self.notes.append(f"<integrator type=\"{integrator.type}\">: rendered by ptrace's "
                              f"path tracer")
        self.settings["max_depth"] = depth
        if integrator.boolean("hide_emitters", False):
            self.settings["hide_emitters"] = True   # (Settings.hide_emitters)
        integrator._read.update(integrator.params)

    def _unread(self, plugin):
        for name in plugin.unread():
            self.notes.append(f"<{plugin.tag} type=\"{plugin.type}\">: parameter {name!r} "
                              f"ignored")

    # --- the scene ------------------------------------------------------------------------

    def _glowing(self):
        """Whether any material emits (an area emitter's: EMISSION, or glTF's of emission)."""
        return any(r["kind"] == EMISSION or max(r.get("emission", (0.0,))) > 0
                   for r in self.materials.records)

    def _finish(self):
        if self.materials.rough_glass and self.lights:
            # a point, spot or directional light's highlight on slightly rough glass is lit
            # by its direct light, which smooth glass never receives (a glass sphere under a
            # point light: 13 % darker than Mitsuba's)
            self.materials.rough_glass[0].fail(
                "rough glass drawn smooth would miss the highlights of the scene's point, "
                "spot or directional lights (ptrace has no rough glass)")
        if self.delta_scale != 1 and self.lights:
            for light in self.lights:
                light["radiance"] = tuple(self.delta_scale * v for v in light["radiance"])
            self.notes.append(f"<integrator type=\"direct\">: emitter_samples "
                              f"{self.delta_scale}: its point, spot and directional lights "
                              f"rendered {self.delta_scale} times as bright, as Mitsuba 3's "
                              f"direct integrator renders them (it does not divide their "
                              f"samples by emitter_samples, as it does an area light's; with "
                              f"none, its BSDF samples never find them)")
        vertices = np.concatenate(self.vertices) if self.vertices else np.zeros((0, 3))
        faces = np.concatenate(self.faces) if self.faces else np.zeros((0, 3), np.int64)
        normals = np.concatenate(self.normals) if self.normals else np.zeros((0, 3))
        material_index = np.concatenate(self.tri_materials + [np.array(self.sphere_materials,
                                                                       np.int32)])
        uv = np.concatenate(self.uvs) if self.materials.textured and self.uvs else None
        if "max_depth" not in self.settings:    # Mitsuba's path tracer without an <integrator>
            self.settings["max_depth"] = -1
        defaults = self._render_defaults()
        if not self.lights and self.environment is None and not self._glowing():
            self.notes.append("no emitters in the scene: the image is black, as Mitsuba's")
        if not len(faces) and not self.radii:
            self.notes.append("no geometry in the scene")
        scene = Scene(path=self.path,
                      geometry=accel.Geometry(vertices=vertices, faces=faces,
                                              centers=np.array(self.centres).reshape(-1, 3),
                                              radii=np.array(self.radii, np.float64)),
                      vertex_normals=normals, material_index=material_index.astype(np.int32),
                      materials=Materials.from_records(self.materials.records),
                      lights=Lights.from_records(self.lights), notes=self.notes, uv=uv,
                      textures=Textures.from_images(self.pool.images, self.pool.wraps,
                                                    self.pool.names),
                      file_cameras=tuple(self.cameras), render_defaults=defaults)
        if self.environment is not None:
            scene = scene.with_environment(self.environment)
        return scene

    def _render_defaults(self):
        """Scene.render_defaults of the file's first sensor's film and sampler and of its
        integrator (Mitsuba's own defaults where the file leaves one out), with a note that
        says them as ptrace's flags: max_depth counts the camera's segment, -m does not; an
        unbounded max_depth (-1) is ptrace's largest -m."""
        settings = dict(self.settings)
        depth = settings.pop("max_depth")
        high = RANGES["max_depth"][1]
        settings["max_depth"] = high if depth < 0 else min(max(depth - 1, 0), high)
        if depth == 0:
            self.notes.append("<integrator>: max_depth 0 (Mitsuba renders nothing) rendered as "
                              "-m 0: the emitters seen, nothing lit")
        flags = []
        if "resolution" in settings:
            flags.append("-r {} {}".format(*settings["resolution"]))
        if "spp" in settings:
            flags.append(f"-s {settings['spp']}")
        flags.append(f"-m {settings['max_depth']}")
        if "lens_radius" in settings:
            flags.append(f"-b {settings['lens_radius']:g} -d {settings['focal_distance']:g}")
        if "rr_depth" in settings:
            flags.append(f"roulette from depth {settings['rr_depth']}")
        if settings.get("hide_emitters"):
            flags.append("the emitters and the environment the camera meets hidden")
        self.notes.append(f"the file's sensor and integrator render with {', '.join(flags)} "
                          f"where the command line does not say")
        return settings


def latlong_from_mitsuba(image, inverse):
    """ptrace's lat-long image (ptrace.environment's mapping) of a Mitsuba envmap image whose
    to_world's inverse (as Mitsuba keeps it: Transform.inverse) is the 3 x 3 `inverse`: each
    pixel's direction d looked up, bilinearly, where Mitsuba finds it (v = inverse d, not
    normalised, as Mitsuba's; u = atan2(v.x, -v.z) / 2 pi, v = acos(v.y) / pi; column
    u * W - 1/2, row v * (H - 1), as Mitsuba's envmap looks them up). A map narrower than
    FINE_ENVMAP columns comes out up to UPSAMPLE times finer on each side, so that ptrace's
    bilinear lookup of it stays close to Mitsuba's of the original at sharp edges."""
    rows, columns = image.shape[:2]
    scale = max(1, min(UPSAMPLE, FINE_ENVMAP // columns))
    y, x = np.meshgrid((np.arange(rows * scale) + 0.5) / (rows * scale),
                       (np.arange(columns * scale) + 0.5) / (columns * scale), indexing="ij")
    theta, phi = y * np.pi, x * 2 * np.pi - np.pi    # ptrace: phi = atan2(-dz, dx)
    d = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta), -np.sin(theta) * np.sin(phi)],
                 axis=-1)
    local = d @ np.asarray(inverse).T
    u = (np.arctan2(local[..., 0], -local[..., 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(local[..., 1], -1.0, 1.0)) / np.pi
    # Mitsuba's rows run from pole to pole (row 0 at v = 0, the last at v = 1), its columns
    # are cells (column i centred at u = (i + 0.5) / columns)
    fx, fy = u * columns - 0.5, np.clip(v * (rows - 1), 0, rows - 1)
    x0, y0 = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
    tx, ty = (fx - x0)[..., None], (fy - y0)[..., None]
    x1, y1 = (x0 + 1) % columns, np.minimum(y0 + 1, rows - 1)
    x0 %= columns
    top = image[y0, x0] * (1 - tx) + image[y0, x1] * tx
    bottom = image[y1, x0] * (1 - tx) + image[y1, x1] * tx
    return top * (1 - ty) + bottom * ty
