# Image textures in the RaySplats engine's materials: an Image Texture on a Principled Base Color or a Diffuse
# BSDF Color, read at the mesh's UVs (default, UV Map node, Texture Coordinate node), for sRGB, Non-Color and
# float images; meshes without UVs and unsupported links give warnings, not errors.
#
# The scene makes the rendered value analytic: a plane filling an orthographic camera that looks straight down,
# a uniform white world of strength 1, no lights, no bounces (max_bounces 0). Each sample is the BSDF-sampled
# world seen from the plane, so the pixel is the directional albedo of the material at normal view:
#   Lambert (Diffuse BSDF; Principled v2 of Blender 4.x with Specular IOR Level 0): albedo = base colour.
#   Principled v1 diffuse (Blender 3.x; Cycles bsdf_principled_diffuse.h) with specular 0 and roughness 1/2, seen
#   along the normal (F_V = 0): f = base/pi [1 - F_L/2 + R_R F_L], R_R = 2 r cos^2(theta_d) = (1 + cos) / 2, so
#   f = base/pi [1 + cos (1 - cos)^5 / 2] and albedo = base [1 + integral_0^1 c^2 (1 - c)^5 dc]
#   = base (1 + B(3, 6)) = base (1 + 1/168).
# The image is a 4 x 4 checker of 16 distinct colours, each cell 4 x 4 texels, so that bilinear filtering only
# blends within half a texel of a cell border; the inner pixels of each cell must show the cell's colour.
import unittest

import bpy
import mathutils
import numpy as np

import splat_testing as st
from raysplats.blender import compat

CELLS, TEXELS_PER_CELL, PIXELS = 4, 4, 64
SIZE = CELLS * TEXELS_PER_CELL
MARGIN = 4  # pixels left out at each cell border (half a texel is 2 pixels)
PRINCIPLED_V1_ALBEDO = 1.0 + 1.0 / 168.0 if compat.PRINCIPLED_VERSION == "V1" else 1.0
RTOL, ATOL = 2e-3, 2e-4  # Monte Carlo noise of the v1 factor (< 3.4 % spread, 4096 samples per cell) and EXR


def srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def cell_colours():
    """16 distinct RGB colours, multiples of 1/255 so that an 8-bit image stores them exactly."""
    k = np.arange(CELLS * CELLS)
    rgb = np.stack([(37 + 13 * k) % 256, (200 - 11 * k) % 256, (60 + 97 * k) % 256], axis=1)
    return (rgb / 255.0).reshape(CELLS, CELLS, 3)  # [cell row from the bottom, cell column]


def make_image(name, kind):
    """The checker as a Blender image: 'SRGB' (8-bit sRGB), 'NON_COLOR' (8-bit data) or 'FLOAT' (linear)."""
    image = bpy.data.images.new(name, SIZE, SIZE, alpha=True, float_buffer=kind == "FLOAT")
    if kind == "NON_COLOR":
        image.colorspace_settings.name = "Non-Color"  # before the pixels: a colour-space change reloads
    texels = np.repeat(np.repeat(cell_colours(), TEXELS_PER_CELL, axis=0), TEXELS_PER_CELL, axis=1)
    rgba = np.concatenate([texels, np.ones((SIZE, SIZE, 1))], axis=2).astype(np.float32)
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    return image


def new_scene():
    st.reset_scene()
    scene = bpy.context.scene
    scene.render.engine = "RAYSPLATS"
    scene.render.resolution_x = scene.render.resolution_y = PIXELS
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = 16
    scene.raysplats.max_bounces = 0
    # Each pixel sees only its own square, so a pixel's value is the mean of the texels under it (the default
    # Blackman-Harris filter, 1.5 px, blends in neighbouring cells and the white world at the border).
    scene.raysplats.pixel_filter, scene.raysplats.filter_width = "BOX", 1.0
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (1.0, 1.0, 1.0))
    scene.world = world
    bpy.ops.mesh.primitive_plane_add(size=2.0)  # UVs (0, 0) .. (1, 1) over x, y = -1 .. 1
    plane = bpy.context.object
    data = bpy.data.cameras.new("Camera")
    data.type, data.ortho_scale = "ORTHO", 2.0
    camera = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, 0.0, 5.0)
    scene.camera = camera
    return scene, plane


def textured_material(image, shader="PRINCIPLED", vector=None):
    """A material with `image` on Base Color (Principled) or Color (Diffuse); `vector`: None (default UVs),
    a UV map name (through a UV Map node) or 'TEXCOORD' (a Texture Coordinate node's UV)."""
    material = bpy.data.materials.new(f"{shader} {image.name}")
    material.use_nodes = True
    tree = material.node_tree
    output = tree.nodes["Material Output"]
    if shader == "PRINCIPLED":
        bsdf = tree.nodes["Principled BSDF"]
        (bsdf.inputs.get("Specular") or bsdf.inputs.get("Specular IOR Level")).default_value = 0.0
        bsdf.inputs["Roughness"].default_value = 0.5
        bsdf.inputs["Base Color"].default_value = (0.1, 0.2, 0.3, 1.0)  # must not show
        colour_input = bsdf.inputs["Base Color"]
    else:
        tree.nodes.remove(tree.nodes["Principled BSDF"])
        bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
        tree.links.new(bsdf.outputs["BSDF"], output.inputs["Surface"])
        colour_input = bsdf.inputs["Color"]
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.links.new(texture.outputs["Color"], colour_input)
    if vector == "TEXCOORD":
        tree.links.new(tree.nodes.new("ShaderNodeTexCoord").outputs["UV"], texture.inputs["Vector"])
    elif vector is not None:
        uv_node = tree.nodes.new("ShaderNodeUVMap")
        uv_node.uv_map = vector
        tree.links.new(uv_node.outputs["UV"], texture.inputs["Vector"])
    return material, tree, texture


def cell_means(image):
    """Mean RGB of the inner pixels of each checker cell, [cell row from the bottom, cell column]."""
    step = PIXELS // CELLS
    means = np.empty((CELLS, CELLS, 3))
    for r in range(CELLS):
        for c in range(CELLS):
            block = image[r * step + MARGIN:(r + 1) * step - MARGIN, c * step + MARGIN:(c + 1) * step - MARGIN, :3]
            means[r, c] = block.reshape(-1, 3).mean(axis=0)
    return means


def sync_warnings():
    from raysplats.engine import sync
    _, stats = sync.build_render_scene(bpy.context.evaluated_depsgraph_get())
    return stats.warnings


class Textures(unittest.TestCase):
    def assert_cells(self, rendered, expected, what):
        np.testing.assert_allclose(cell_means(rendered), expected, rtol=RTOL, atol=ATOL, err_msg=what)

    def test_principled_base_color_texture_shows_each_cell_colour(self):
        for kind in ("SRGB", "NON_COLOR", "FLOAT"):
            with self.subTest(kind=kind):
                _, plane = new_scene()
                material, _, _ = textured_material(make_image("Checker", kind))
                plane.data.materials.append(material)
                self.assertEqual(sync_warnings(), [])
                rendered = st.render_to_array(f"texture_principled_{kind.lower()}")
                linear = srgb_to_linear(cell_colours()) if kind == "SRGB" else cell_colours()
                self.assert_cells(rendered, linear * PRINCIPLED_V1_ALBEDO, kind)

    def test_diffuse_color_texture_reads_the_uv_map_the_material_names(self):
        # A second UV map mirrors u: through a UV Map node naming it, the checker's columns come out reversed;
        # through a Texture Coordinate node (the default, render-active map) they do not.
        for vector, mirrored in (("Mirrored", True), ("TEXCOORD", False), ("UVMap", False)):
            with self.subTest(vector=vector):
                _, plane = new_scene()
                mesh = plane.data
                layer = mesh.uv_layers.new(name="Mirrored")
                uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
                layer.data.foreach_get("uv", uv)
                uv[0::2] = 1.0 - uv[0::2]
                layer.data.foreach_set("uv", uv)
                mesh.uv_layers["UVMap"].active_render = True
                material, _, _ = textured_material(make_image("Checker", "NON_COLOR"), "DIFFUSE", vector)
                mesh.materials.append(material)
                self.assertEqual(sync_warnings(), [])
                expected = cell_colours()[:, ::-1] if mirrored else cell_colours()
                self.assert_cells(st.render_to_array(f"texture_diffuse_{vector.lower()}"), expected, vector)

    def test_mesh_without_uvs_warns_and_renders_the_texel_blend_at_uv_zero(self):
        _, plane = new_scene()
        while plane.data.uv_layers:
            plane.data.uv_layers.remove(plane.data.uv_layers[0])
        material, _, _ = textured_material(make_image("Checker", "SRGB"), "DIFFUSE")
        plane.data.materials.append(material)
        warnings = sync_warnings()
        self.assertTrue(any("no UV map" in w for w in warnings), warnings)
        rendered = st.render_to_array("texture_no_uvs")[..., :3]
        # UV (0, 0) is the corner shared (repeat wrapping) by the four corner cells: bilinear weights 1/4 each,
        # blended in sRGB and then decoded (Cycles' order for 8-bit sRGB images).
        cells = cell_colours()
        corner_mean = (cells[0, 0] + cells[0, -1] + cells[-1, 0] + cells[-1, -1]) / 4.0
        np.testing.assert_allclose(rendered.reshape(-1, 3).mean(axis=0), srgb_to_linear(corner_mean), rtol=1e-4)
        self.assertLess(np.ptp(rendered, axis=(0, 1)).max(), 1e-4, "the whole plane has one colour")

    def test_unsupported_links_warn_and_keep_the_unconnected_colour(self):
        _, plane = new_scene()
        material, tree, texture = textured_material(make_image("Checker", "SRGB"))
        mapping = tree.nodes.new("ShaderNodeMapping")
        tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
        plane.data.materials.append(material)
        warnings = sync_warnings()
        self.assertTrue(any("Mapping" in w and "UV maps are supported" in w for w in warnings), warnings)
        rendered = st.render_to_array("texture_unsupported_vector")[..., :3]
        unconnected = np.array([0.1, 0.2, 0.3]) * PRINCIPLED_V1_ALBEDO
        np.testing.assert_allclose(rendered.reshape(-1, 3).mean(axis=0), unconnected, rtol=RTOL)

        # A Noise Texture on Base Color: the same.
        tree.links.remove(texture.inputs["Vector"].links[0])
        noise = tree.nodes.new("ShaderNodeTexNoise")
        tree.links.new(noise.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
        warnings = sync_warnings()
        self.assertTrue(any("only an Image Texture" in w for w in warnings), warnings)
        rendered = st.render_to_array("texture_unsupported_node")[..., :3]
        np.testing.assert_allclose(rendered.reshape(-1, 3).mean(axis=0), unconnected, rtol=RTOL)

    def test_textured_and_plain_instances_of_one_mesh_both_render(self):
        # Two objects sharing one mesh, one textured through an object-level material slot: the textured one
        # gets per-corner arrays, the plain one the shared vertices; both must show their own material.
        scene, plane = new_scene()
        plane.scale = (0.5, 1.0, 1.0)
        plane.location.x = -0.5
        twin = plane.copy()
        scene.collection.objects.link(twin)
        twin.location.x = 0.5
        plain = bpy.data.materials.new("Plain")
        plain.use_nodes = True
        bsdf = plain.node_tree.nodes["Principled BSDF"]
        (bsdf.inputs.get("Specular") or bsdf.inputs.get("Specular IOR Level")).default_value = 0.0
        bsdf.inputs["Base Color"].default_value = (0.25, 0.5, 0.75, 1.0)
        plane.data.materials.append(plain)
        textured, _, _ = textured_material(make_image("Checker", "FLOAT"), "DIFFUSE")
        twin.material_slots[0].link = "OBJECT"
        twin.material_slots[0].material = textured
        self.assertEqual(sync_warnings(), [])
        rendered = st.render_to_array("texture_instances")[..., :3]
        left = rendered[:, 4:PIXELS // 2 - 4].reshape(-1, 3).mean(axis=0)
        np.testing.assert_allclose(left, np.array([0.25, 0.5, 0.75]) * PRINCIPLED_V1_ALBEDO, rtol=RTOL)
        # The right object is squeezed to half the width: its u runs 0..1 over 32 pixels (8 per cell column).
        right = rendered[:, PIXELS // 2:]
        cells = cell_colours()
        for r in range(CELLS):
            for c in range(CELLS):
                block = right[r * 16 + MARGIN:(r + 1) * 16 - MARGIN, c * 8 + 3:(c + 1) * 8 - 3]
                np.testing.assert_allclose(block.reshape(-1, 3).mean(axis=0), cells[r, c], rtol=RTOL, atol=ATOL,
                                           err_msg=f"cell {r}, {c}")
