# Depsgraph -> native RenderScene: meshes (modifiers applied, instances included), Gaussian objects recovered
# from their evaluated meshes, Principled materials, lights in Blender units, the world and the camera.

import bpy
import numpy as np

from .. import gaussian_mesh, native

# Cycles' Principled BSDF v1 (Blender 2.8-3.x) has the principled (Disney) diffuse with roughness-dependent
# retro-reflection; v2 (Blender 4.x) a Lambertian diffuse.
PRINCIPLED_DIFFUSE = "PRINCIPLED" if bpy.app.version < (4, 0, 0) else "LAMBERT"


def _input(node, *names):
    """The first of the named inputs a node has (Blender 4 renamed several Principled inputs)."""
    for name in names:
        socket = node.inputs.get(name)
        if socket is not None:
            return socket
    return None


def _value(node, default, *names):
    socket = _input(node, *names)
    if socket is None:
        return default
    value = socket.default_value
    try:
        return tuple(value)[:3]
    except TypeError:
        return float(value)


class MaterialTable:
    """Blender materials -> native material indices, converted once each."""

    def __init__(self, render_scene, warn):
        self.render_scene = render_scene
        self.warn = warn
        self.indices = {}
        self.default = render_scene.add_material()

    def index(self, material):
        if material is None:
            return self.default
        key = material.name_full
        if key not in self.indices:
            self.indices[key] = self.render_scene.add_material(**self._convert(material))
        return self.indices[key]

    def _convert(self, material):
        fallback = {"base_color": tuple(material.diffuse_color)[:3], "metallic": float(material.metallic),
                    "roughness": float(material.roughness)}
        if not material.use_nodes or material.node_tree is None:
            return fallback
        output = next((n for n in material.node_tree.nodes
                       if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output), None)
        surface = output.inputs["Surface"] if output else None
        if surface is None or not surface.is_linked:
            return fallback
        node = surface.links[0].from_node
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            linked = [s.name for s in node.inputs if s.is_linked and s.name in
                      ("Base Color", "Metallic", "Roughness", "Transmission", "Transmission Weight")]
            if linked:
                self.warn(f"Material '{material.name}': textures or node inputs on {', '.join(linked)} are not "
                          "supported yet; their unconnected values are used")
            specular = _value(node, 0.5, "Specular", "Specular IOR Level")
            return {
                "base_color": _value(node, (0.8, 0.8, 0.8), "Base Color"),
                "metallic": _value(node, 0.0, "Metallic"),
                "roughness": _value(node, 0.5, "Roughness"),
                "specular": min(1.0, max(0.0, specular)),
                "transmission": _value(node, 0.0, "Transmission Weight", "Transmission"),
                "ior": max(1.0, _value(node, 1.45, "IOR")),
                "emission_color": _value(node, (0.0, 0.0, 0.0), "Emission Color", "Emission"),
                "emission_strength": _value(node, 1.0, "Emission Strength"),
                "alpha": _value(node, 1.0, "Alpha"),
                "diffuse_model": PRINCIPLED_DIFFUSE,
            }
        if kind == "ShaderNodeBsdfDiffuse":
            return {"base_color": _value(node, (0.8, 0.8, 0.8), "Color"), "roughness": 1.0, "specular": 0.0}
        if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            return {"base_color": _value(node, (0.8, 0.8, 0.8), "Color"), "metallic": 1.0,
                    "roughness": _value(node, 0.5, "Roughness")}
        if kind == "ShaderNodeBsdfGlass":
            return {"base_color": _value(node, (1.0, 1.0, 1.0), "Color"), "transmission": 1.0,
                    "roughness": _value(node, 0.0, "Roughness"), "ior": max(1.0, _value(node, 1.45, "IOR"))}
        if kind == "ShaderNodeEmission":
            return {"base_color": (0.0, 0.0, 0.0), "specular": 0.0,
                    "emission_color": _value(node, (1.0, 1.0, 1.0), "Color"),
                    "emission_strength": _value(node, 1.0, "Strength")}
        self.warn(f"Material '{material.name}': '{node.name}' is not a Principled BSDF; its viewport colour is used")
        return fallback


def _light_kwargs(light, matrix):
    scale = matrix.to_scale()
    common = {"color": tuple(light.color), "power": float(light.energy),
              "matrix": np.array(matrix.normalized(), dtype=np.float32)}
    if light.type == "SUN":
        return dict(common, type="SUN", sun_angle=float(light.angle))
    if light.type == "SPOT":
        return dict(common, type="SPOT", spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
    if light.type == "AREA":
        shape = "AREA_DISK" if light.shape in ("DISK", "ELLIPSE") else "AREA_RECTANGLE"
        size_y = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
        return dict(common, type=shape, size_x=float(light.size * scale.x), size_y=float(size_y * scale.y))
    return dict(common, type="POINT")


def _world(scene):
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0), 0.0
    if world.use_nodes and world.node_tree is not None:
        output = next((n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"
                       and n.is_active_output), None)
        if output and output.inputs["Surface"].is_linked:
            node = output.inputs["Surface"].links[0].from_node
            if node.bl_idname == "ShaderNodeBackground":
                return _value(node, (0.05, 0.05, 0.05), "Color"), _value(node, 1.0, "Strength")
    return tuple(world.color), 1.0


def triangle_mesh_arrays(mesh):
    """Vertices, triangles and per-triangle material slots of any mesh (loop triangles, bulk reads)."""
    mesh.calc_loop_triangles()
    vertices = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", vertices)
    triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    slots = np.empty(len(mesh.loop_triangles), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("material_index", slots)
    return vertices.reshape(-1, 3), triangles.reshape(-1, 3), slots


class SceneStats:
    def __init__(self):
        self.splats = 0
        self.triangles = 0
        self.lights = 0
        self.warnings = []


def build_render_scene(depsgraph, warn=None):
    """A native RenderScene of everything visible in the evaluated depsgraph. Returns (scene, stats)."""
    core = native.core()
    render_scene = core.RenderScene()
    stats = SceneStats()
    seen_warnings = set()

    def warn_once(message):
        if message not in seen_warnings:
            seen_warnings.add(message)
            stats.warnings.append(message)
            if warn:
                warn(message)

    materials = MaterialTable(render_scene, warn_once)
    mesh_cache = {}
    for instance in depsgraph.object_instances:
        obj = instance.object
        matrix = instance.matrix_world
        if obj.type == "MESH" and gaussian_mesh.is_gaussian_object(obj):
            cloud = gaussian_mesh.recover_mesh_gaussians(core, obj.data, obj.raysplats,
                                                         np.array(matrix, dtype=np.float64))
            if len(cloud["opacities"]):
                render_scene.add_gaussians(cloud["positions"], cloud["rotations"], cloud["scales"],
                                           cloud["opacities"], cloud["sh"])
                stats.splats += len(cloud["opacities"])
        elif obj.type in ("MESH", "CURVE", "SURFACE", "META", "FONT"):
            # Instances of one mesh (collection, particle, Geometry Nodes instances) share its arrays.
            key = obj.data.as_pointer() if obj.type == "MESH" else None
            arrays = mesh_cache.get(key) if key else None
            if arrays is None:
                mesh = obj.data if obj.type == "MESH" else obj.to_mesh()
                try:
                    arrays = triangle_mesh_arrays(mesh)
                finally:
                    if obj.type != "MESH":
                        obj.to_mesh_clear()
                if key:
                    mesh_cache[key] = arrays
            vertices, triangles, slots = arrays
            if not len(triangles):
                continue
            slot_materials = np.array([materials.index(slot.material) for slot in obj.material_slots]
                                      or [materials.default], dtype=np.uint32)
            face_materials = slot_materials[np.minimum(slots, len(slot_materials) - 1)]
            render_scene.add_mesh(vertices, triangles, np.array(matrix, dtype=np.float32),
                                  face_materials=face_materials)
            stats.triangles += len(triangles)
        elif obj.type == "LIGHT":
            render_scene.add_light(**_light_kwargs(obj.data, matrix))
            stats.lights += 1
    color, strength = _world(depsgraph.scene)
    render_scene.set_world(color, strength)
    return render_scene, stats


def camera_settings(scene, camera_object, width, height):
    """The native camera description of a Blender camera object."""
    cam = camera_object.data
    camera = {
        "matrix": np.array(camera_object.matrix_world.normalized(), dtype=np.float32),
        "lens": cam.lens, "sensor_width": cam.sensor_width, "sensor_height": cam.sensor_height,
        "sensor_fit": cam.sensor_fit, "shift_x": cam.shift_x, "shift_y": cam.shift_y,
        "clip_start": cam.clip_start, "clip_end": cam.clip_end, "ortho_scale": cam.ortho_scale,
    }
    if cam.type == "ORTHO":
        camera["type"] = "ORTHO"
    elif cam.type == "PANO":
        # Blender 4 keeps panoramic settings on the camera; Blender 3 in Cycles' properties (ours here).
        source = cam if hasattr(cam, "panorama_type") else cam.raysplats
        panorama = source.panorama_type
        if panorama not in ("EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID"):
            raise ValueError(f"Camera '{camera_object.name}': panorama type {panorama} is not supported "
                             "(equirectangular and fisheye are)")
        camera["type"] = panorama
        for key in ("fisheye_fov", "fisheye_lens", "latitude_min", "latitude_max", "longitude_min",
                    "longitude_max"):
            camera[key] = float(getattr(source, key))
    else:
        camera["type"] = "PERSP"
    return camera


def render_settings(scene, width, height, samples, seed_offset=0):
    settings = scene.raysplats
    return {
        "width": width, "height": height, "samples": samples, "max_bounces": settings.max_bounces,
        "seed": settings.seed + seed_offset, "compositing": settings.compositing,
        "transmittance_threshold": settings.transmittance_threshold, "gaussian_mode": settings.gaussian_mode,
        "meshes_shadow_gaussians": settings.meshes_shadow_gaussians,
        "caustics_reflective": settings.caustics_reflective, "caustics_refractive": settings.caustics_refractive,
        "transparent_background": bool(scene.render.film_transparent),
    }


def resolution(scene):
    scale = scene.render.resolution_percentage / 100.0
    return max(1, int(scene.render.resolution_x * scale)), max(1, int(scene.render.resolution_y * scale))


