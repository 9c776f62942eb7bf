# Shared helpers of the Blender tests: data paths, a fresh scene, and an independent numpy reference of the
# Gaussian model (covariances, SH evaluation) to check exported files against.
import os
import struct
import types

import bpy
import numpy as np

DATA_DIR = os.environ.get("RAYSPLATS_DATA_DIR", "")
TMP_DIR = os.environ.get("RAYSPLATS_TMP_DIR", "/tmp")


def data_file(name):
    path = os.path.join(DATA_DIR, name)
    if not os.path.exists(path):
        raise FileNotFoundError(f"test data '{path}' is missing (see shared/data/README.md)")
    return path


def tmp_file(name):
    return os.path.join(TMP_DIR, name)


def reset_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def reset_render_scene(width, height, samples):
    """An empty scene rendered by RaySplats at width x height (100 %) with `samples` samples per pixel."""
    reset_scene()
    scene = bpy.context.scene
    scene.render.engine = "RAYSPLATS"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = samples
    return scene


def use_cycles_on_cpu(scene, samples, pixel_filter=("BOX", 1.0), seed=1):
    """Cycles on the CPU as the agreement tests compare with: a fixed sample count (adaptive sampling and denoising
    off), the pixel filter (type, width) and the seed given."""
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = samples
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.pixel_filter_type, cycles.filter_width = pixel_filter
    cycles.seed = seed
    return cycles


def cycles_paths_as_compared(cycles, bounces=4):
    """Cycles' light paths as the agreement tests compare them with RaySplats': `bounces` of every kind, no clamping,
    caustics off (RaySplats follows Cycles' caustics tricks, off in its settings too), no glossy blur, every light
    sampled."""
    cycles.max_bounces = cycles.diffuse_bounces = cycles.glossy_bounces = cycles.transmission_bounces = bounces
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    cycles.caustics_reflective = cycles.caustics_refractive = False
    cycles.blur_glossy = 0.0
    cycles.light_sampling_threshold = 0.0


def raysplats_paths_as_compared(scene, bounces=4):
    """RaySplats' settings as the agreement tests compare them with Cycles' (cycles_paths_as_compared): every pixel at
    the full sample count, `bounces` bounces, seed 1, caustics off."""
    settings = scene.raysplats
    settings.use_adaptive_sampling = False
    settings.max_bounces = bounces
    settings.seed = 1
    settings.caustics_reflective = settings.caustics_refractive = False


def add_camera_looking_at(scene, location, target):
    """A new perspective camera at `location` looking at `target` (+Y up in its image), the scene's camera."""
    import mathutils

    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = location
    camera.rotation_euler = (mathutils.Vector(target) - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.camera = camera
    return camera


def principled(name, color, metallic=0.0, roughness=0.5, transmission=0.0, ior=1.45, distribution="GGX"):
    """A new material whose Principled BSDF has these inputs."""
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    node = material.node_tree.nodes["Principled BSDF"]
    node.distribution = distribution
    node.inputs["Base Color"].default_value = (*color, 1.0)
    node.inputs["Metallic"].default_value = metallic
    node.inputs["Roughness"].default_value = roughness
    node.inputs["IOR"].default_value = ior
    (node.inputs.get("Transmission Weight") or node.inputs.get("Transmission")).default_value = transmission
    return material


def add_with_material(primitive, material, **kwargs):
    """A new object made by the bpy.ops.mesh primitive operator with `kwargs`, its mesh given `material`."""
    primitive(**kwargs)
    obj = bpy.context.object
    obj.data.materials.append(material)
    return obj


def pixel_centre_scene(width, height, samples, world_color, camera_height):
    """An empty scene with a camera `camera_height` above z = 0 looking down (-Z), a uniform world, and both engines'
    samples at the pixel centre: pixel filters Gaussian 0.01 px wide, no adaptive sampling, Cycles on the CPU."""
    scene = reset_render_scene(width, height, samples=samples)
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    set_world_color(world, world_color)
    scene.world = world
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, 0.0, camera_height)
    scene.camera = camera
    scene.raysplats.pixel_filter, scene.raysplats.filter_width = "GAUSSIAN", 0.01
    scene.raysplats.use_adaptive_sampling = False
    use_cycles_on_cpu(scene, samples, pixel_filter=("GAUSSIAN", 0.01), seed=scene.cycles.seed)
    return scene


def interior(index, *more):
    """Pixels whose 3 x 3 neighbourhood has one value in every array given: away from every edge."""
    mask = np.zeros(index.shape, dtype=bool)
    mask[1:-1, 1:-1] = True
    for array in (index,) + more:
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                mask[1:-1, 1:-1] &= array[1:-1, 1:-1] == array[1 + dy:array.shape[0] - 1 + dy,
                                                               1 + dx:array.shape[1] - 1 + dx]
    return mask


def flat_gaussian_cloud(centres, sigma, opacity, color=(0.8, 0.3, 0.2)):
    """Flat Gaussians (z extent 1e-4) of one size, opacity and display colour, as the core's cloud dict."""
    count = len(centres)
    sh = np.zeros((count, 1, 3), dtype=np.float32)
    sh[:, 0] = (np.asarray(color) - 0.5) / 0.28209479177387814
    return {"positions": np.asarray(centres, dtype=np.float32),
            "rotations": np.tile(np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32), (count, 1)),
            "scales": np.tile(np.array([sigma, sigma, 1e-4], dtype=np.float32), (count, 1)),
            "opacities": np.full(count, opacity, dtype=np.float32), "sh": sh, "sh_degree": 0}


def emission_material(name, color=(1.0, 1.0, 1.0)):
    """A material that only emits `color` at strength 1."""
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (*color, 1.0)
    emission.inputs["Strength"].default_value = 1.0
    material.node_tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return material


def camera_above_scene(width, height, samples, camera_type, ortho_scale):
    """An empty RaySplats scene (fixed samples, seed 3) with a black world and a camera at (0, 0, 10) looking down -Z
    (`camera_type` PERSP or ORTHO, `ortho_scale` units across an orthographic view)."""
    scene = reset_render_scene(width, height, samples)
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    set_world_color(world, (0.0, 0.0, 0.0))
    scene.world = world
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, 0.0, 10.0)
    camera.data.type = camera_type
    camera.data.ortho_scale = ortho_scale
    scene.camera = camera
    scene.raysplats.use_adaptive_sampling = False
    scene.raysplats.seed = 3
    return scene


def flat_gaussian_alpha(px, py, centres, sigma, opacity):
    """The alpha of a layer of flat_gaussian_cloud() at points (px, py) of its plane: its Gaussians' alphas as the core
    clamps and cuts them (at Mahalanobis radius 3, src/render/gaussian_primitives.h), composited (they lie in one
    plane, at one distance)."""
    transmittance = np.ones_like(px)
    for cx, cy, _ in centres:
        r2 = ((px - cx) ** 2 + (py - cy) ** 2) / sigma ** 2
        a = opacity * np.exp(-0.5 * r2)
        transmittance *= 1.0 - np.where((a < 1.0 / 255.0) | (r2 > 9.0), 0.0, np.minimum(a, 0.99))
    return 1.0 - transmittance


class RecordingLayout:
    """Stands in for a panel's UILayout: records each property drawn as (owner type name, property, its text)."""

    def __init__(self, log=None):
        self.log = [] if log is None else log
        self.use_property_split = self.use_property_decorate = self.active = self.enabled = False
        self.operator_context = "INVOKE_DEFAULT"

    def prop(self, owner, name, text=None, **kwargs):
        self.log.append((type(owner).__name__, name, text))

    def column(self, *args, **kwargs):
        return RecordingLayout(self.log)

    row = box = grid_flow = column_flow = split = column

    def label(self, *args, **kwargs):
        pass

    separator = label

    def operator(self, *args, **kwargs):
        return types.SimpleNamespace()

    def prop_search(self, owner, name, *args, **kwargs):
        self.prop(owner, name)

    def template_curve_mapping(self, owner, name, *args, **kwargs):
        self.prop(owner, name)


def convert_to_blender_splats(obj):
    """Object > Convert to Blender's own splats (Blender 5.3) on `obj` alone; returns the active object after it."""
    for other in bpy.context.view_layer.objects:
        other.select_set(other is obj)
    bpy.context.view_layer.objects.active = obj
    result = bpy.ops.object.raysplats_to_native_splats()
    assert result == {"FINISHED"}, result
    return bpy.context.view_layer.objects.active


def drive(obj, path, index, expression):
    """Animates a property by a driver of the frame (a Blender simple expression, evaluated at subframes too): motion
    at exactly constant speed, with no keyframe interpolation to set."""
    fcurve = obj.driver_add(path, index)
    fcurve.driver.type = "SCRIPTED"
    fcurve.driver.expression = expression


def native():
    from raysplats import native as native_module
    return native_module.core()


def rotation_matrices(quaternions):
    q = np.asarray(quaternions, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


def covariances(cloud, planar=False):
    """Σ = R diag(s²) Rᵀ per Gaussian; planar=True keeps only the two largest axes (what a polygon carries)."""
    r = rotation_matrices(cloud["rotations"])
    s2 = np.asarray(cloud["scales"], dtype=np.float64) ** 2
    if planar:
        s2 = s2.copy()
        # The import spans the polygon with the two largest axes, ties going to the lower index, so the
        # dropped axis is the smallest with ties going to the highest index (isotropic Gaussians exist).
        smallest = 2 - np.argmin(s2[:, ::-1], axis=1)
        s2[np.arange(len(s2)), smallest] = 0.0
    return np.einsum("nij,nj,nkj->nik", r, s2, r)


def relative_errors(actual, expected):
    """Per-item Frobenius relative error of stacks of matrices or vectors."""
    actual = np.asarray(actual, dtype=np.float64).reshape(len(actual), -1)
    expected = np.asarray(expected, dtype=np.float64).reshape(len(expected), -1)
    return np.linalg.norm(actual - expected, axis=1) / np.maximum(np.linalg.norm(expected, axis=1), 1e-30)


# Reference 3DGS SH basis (Kerbl et al. 2023, utils/sh_utils.py), written out independently of the core.
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435)


def sh_colors(sh, directions):
    """Colour of each Gaussian (sh: N x coeffs x 3) seen along unit directions (N x 3), without the clamp."""
    x, y, z = directions[:, 0:1], directions[:, 1:2], directions[:, 2:3]
    coeffs = sh.shape[1]
    basis = [np.full_like(x, C0)]
    if coeffs > 1:
        basis += [-C1 * y, C1 * z, -C1 * x]
    if coeffs > 4:
        xx, yy, zz = x * x, y * y, z * z
        basis += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy)]
    if coeffs > 9:
        basis += [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
                  C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
                  C3[6] * x * (xx - 3 * yy)]
    b = np.concatenate(basis, axis=1)  # N x coeffs
    return 0.5 + np.einsum("nk,nkc->nc", b, sh.astype(np.float64))


def import_file(name, **options):
    result = bpy.ops.import_scene.gaussian_splats(filepath=data_file(name), **options)
    assert result == {"FINISHED"}, result
    return bpy.context.view_layer.objects.active


def export_file(name, **options):
    path = tmp_file(name)
    if os.path.exists(path):
        os.remove(path)
    result = bpy.ops.export_scene.gaussian_splats(filepath=path, **options)
    assert result == {"FINISHED"}, result
    return native().read_splats(path)


def load_image(path):
    """An image file's pixels as float32 RGBA, rows bottom to top (linear for EXR)."""
    image = bpy.data.images.load(path)
    pixels = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    result = pixels.reshape(image.size[1], image.size[0], 4)
    bpy.data.images.remove(image)
    return result


def render_to_array(name):
    """Renders the scene with F12's operator into a 32-bit EXR and returns its linear RGBA pixels."""
    scene = bpy.context.scene
    from raysplats.blender.compat import use_single_image
    path = tmp_file(name + ".exr")
    use_single_image(scene.render.image_settings, "OPEN_EXR")
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return load_image(path)


def set_world_color(world, color):
    """Gives `world` a uniform background colour (strength 1). Blender 5.0's new worlds always use nodes, and their
    Background node, not World.color (the viewport colour since), is what renderers show; before, a new world has no
    nodes and renderers use World.color."""
    world.color = color
    if world.use_nodes and world.node_tree is not None:
        for node in world.node_tree.nodes:
            if node.bl_idname == "ShaderNodeBackground":
                node.inputs["Color"].default_value = (*color, 1.0)
                node.inputs["Strength"].default_value = 1.0


def select_faces(obj, faces):
    """In Edit Mode: exactly these faces of obj selected (the caller sets the select mode and updates the mesh)."""
    import bmesh

    bpy.ops.mesh.select_all(action="DESELECT")
    edit = bmesh.from_edit_mesh(obj.data)
    edit.faces.ensure_lookup_table()
    for face in faces:
        edit.faces[face].select_set(True)


def _read_exr_header(data, pos):
    """One OpenEXR header from byte `pos`: (channels [(name, pixel type)], data window, compression, chunk count,
    the position after its terminating null byte)."""
    channels, window, compression, chunks = [], None, None, None
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        type_end = data.index(b"\0", end + 1)
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5:type_end + 5 + size]
        if name == "channels":
            at = 0
            while value[at] != 0:
                name_end = value.index(b"\0", at)
                pixel_type = struct.unpack_from("<i", value, name_end + 1)[0]
                channels.append((value[at:name_end].decode(), pixel_type))
                at = name_end + 1 + 16
        elif name == "dataWindow":
            window = struct.unpack("<4i", value)
        elif name == "compression":
            compression = value[0]
        elif name == "chunkCount":
            (chunks,) = struct.unpack("<i", value)
        pos = type_end + 5 + size
    return channels, window, compression, chunks, pos + 1


def read_uncompressed_exr(path):
    """{channel name: float32 array (rows top to bottom)} of an uncompressed, 32-bit float scanline OpenEXR file,
    single-part (Blender 3.4-4.x's multilayer files) or multi-part (Blender 5.0's: one part per pass). Written from
    the OpenEXR file layout (headers, chlist, offset tables, scanline chunks; a multi-part file ends its header list
    with an empty header and starts each chunk with its part number), not with Blender, so that it checks what
    Blender wrote."""
    data = open(path, "rb").read()
    assert data[:4] == b"\x76\x2f\x31\x01", "not an OpenEXR file"
    multipart = bool(struct.unpack_from("<I", data, 4)[0] & 0x1000)
    pos, parts = 8, []
    while True:
        channels, window, compression, chunks, pos = _read_exr_header(data, pos)
        assert compression == 0, "compressed EXR"
        assert all(t == 2 for _, t in channels), "not 32-bit float"
        parts.append((channels, window, chunks if multipart else window[3] - window[1] + 1))
        if not multipart or data[pos] == 0:
            break
    pos += 1 if multipart else 0
    result = {}
    for part, (channels, window, chunks) in enumerate(parts):
        width, height = window[2] - window[0] + 1, window[3] - window[1] + 1
        offsets = struct.unpack_from(f"<{chunks}Q", data, pos)
        pos += 8 * chunks
        for name, _ in channels:
            result[name] = np.empty((height, width), dtype=np.float32)
        for offset in offsets:
            if multipart:
                assert struct.unpack_from("<i", data, offset)[0] == part
                offset += 4
            y, _size = struct.unpack_from("<2i", data, offset)
            at = offset + 8
            for name, _ in channels:
                result[name][y - window[1]] = np.frombuffer(data, dtype="<f4", count=width, offset=at)
                at += 4 * width
    return result


def render_multilayer_exr(name):
    """F12 with the operator into an uncompressed 32-bit multilayer EXR, read back: {"ViewLayer.Pass.Channel": float32
    array, rows top to bottom}."""
    from raysplats.blender.compat import use_multilayer_exr
    scene = bpy.context.scene
    settings = scene.render.image_settings
    use_multilayer_exr(settings)
    settings.color_depth = "32"
    settings.exr_codec = "NONE"
    scene.render.filepath = tmp_file(name + ".exr")
    bpy.ops.render.render(write_still=True)
    return read_uncompressed_exr(scene.render.filepath)
