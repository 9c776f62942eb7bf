# The light passes, Emission and Diffuse, Glossy and Transmission Direct, Indirect and Color, switched on with Blender's
# own View Layer check boxes:
# - on a mesh-only scene (a diffuse floor and box, a glossy metal sphere, an emissive mesh, a point light and the
#   world's light) each pass's image mean agrees with Cycles';
# - in a scene mixing meshes and Gaussians (polygon and compact splat objects), in each Gaussian shading, they
#   recombine to Combined as Blender's compositor recombines Cycles' passes, sum over lobes of (Direct + Indirect)
#   Color + Emission (Film > Transparent: the world seen directly is in none of them, as Cycles' Environment);
# - Emission is a Baked splat object's colour where it is opaque and 0 where only a non-emissive mesh is seen.
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import passes as engine_passes
from raysplats.objects import creation

WIDTH, HEIGHT, SAMPLES = 64, 48, 256
LIGHT_PASSES = ("Emit", "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol", "TransDir", "TransInd",
                "TransCol")
LOBES = (("DiffDir", "DiffInd", "DiffCol"), ("GlossDir", "GlossInd", "GlossCol"),
         ("TransDir", "TransInd", "TransCol"))
TOGGLES = ("use_pass_emit", "use_pass_diffuse_direct", "use_pass_diffuse_indirect", "use_pass_diffuse_color",
           "use_pass_glossy_direct", "use_pass_glossy_indirect", "use_pass_glossy_color",
           "use_pass_transmission_direct", "use_pass_transmission_indirect", "use_pass_transmission_color")
SPLAT_COLOR = (0.8, 0.35, 0.2)  # display colour, as trained


def emission(name, color, strength):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    nodes = material.node_tree.nodes
    node = nodes.new("ShaderNodeEmission")
    node.inputs["Color"].default_value = (*color, 1.0)
    node.inputs["Strength"].default_value = strength
    output = next(n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    material.node_tree.links.new(node.outputs["Emission"], output.inputs["Surface"])
    return material


def mesh_scene():
    """A diffuse floor and box, a glossy gold sphere, an emissive slab, a point light, the world's grey light; a camera
    looking down at them; every light pass on."""
    scene = st.reset_render_scene(WIDTH, HEIGHT, SAMPLES)
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (0.1, 0.12, 0.15))
    scene.world = world
    add, mesh = st.add_with_material, bpy.ops.mesh
    add(mesh.primitive_plane_add, st.principled("Floor", (0.7, 0.6, 0.5)), size=8.0)
    add(mesh.primitive_cube_add, st.principled("Red", (0.8, 0.1, 0.1)), size=0.8, location=(-1.2, 0.5, 0.4))
    add(mesh.primitive_uv_sphere_add, st.principled("Gold", (0.9, 0.7, 0.3), metallic=1.0, roughness=0.3),
        radius=0.6, location=(0.4, 0.4, 0.6))
    add(mesh.primitive_cube_add, emission("Lamp", (1.0, 0.6, 0.3), 3.0), size=0.5, location=(1.4, -0.6, 0.25))
    bpy.ops.object.light_add(type="POINT", location=(1.5, -1.0, 3.0))
    bpy.context.object.data.energy = 300.0
    bpy.context.object.data.shadow_soft_size = 0.0
    st.add_camera_looking_at(scene, (0.0, -4.0, 3.5), (0.0, 0.3, 0.3))
    for name in TOGGLES:
        setattr(bpy.context.view_layer, name, True)
    return scene


def render(scene, engine, name):
    """{pass: (H, W, 3) array} of the light passes and Combined (RGBA) of an F12 render by `engine`."""
    scene.render.engine = engine
    if engine == "CYCLES":
        cycles = st.use_cycles_on_cpu(scene, SAMPLES, pixel_filter=("BOX", 1.0), seed=1)
        st.cycles_paths_as_compared(cycles, bounces=4)
    else:
        st.raysplats_paths_as_compared(scene, bounces=4)
        scene.raysplats.pixel_filter, scene.raysplats.filter_width = "BOX", 1.0
    exr = st.render_multilayer_exr(name)
    layer = next(key.split(".")[0] for key in exr)
    result = {"Combined": np.stack([exr[f"{layer}.Combined.{c}"] for c in "RGBA"], axis=-1)}
    for name in LIGHT_PASSES:
        result[name] = np.stack([exr[f"{layer}.{compat.render_pass_name(name)}.{c}"] for c in "RGB"], axis=-1)
    return result


def recombined(out):
    """What Blender's compositor makes of the passes: sum over lobes of (Direct + Indirect) Color, plus Emission."""
    total = out["Emit"].astype(np.float64)
    for direct, indirect, color in LOBES:
        total = total + (out[direct].astype(np.float64) + out[indirect]) * out[color]
    return total


class MeshLightPassesAgreeWithCycles(unittest.TestCase):
    def test_each_pass_mean_agrees_with_cycles(self):
        scene = mesh_scene()
        ours = render(scene, "RAYSPLATS", "light_passes_raysplats")
        cycles = render(scene, "CYCLES", "light_passes_cycles")
        scale = cycles["Combined"][..., :3].mean()
        report = []
        for name in ("Combined",) + LIGHT_PASSES:
            a, b = ours[name][..., :3].mean(), cycles[name][..., :3].mean()
            report.append(f"{name} {a:.4f}/{b:.4f}")
            # Each pass's mean within 2 % of the image's mean brightness (Combined), or 3 % of its own mean.
            with self.subTest(name=name):
                self.assertLessEqual(abs(a - b), max(0.02 * scale, 0.03 * abs(b)), name)
        print(f"\nLight passes against Cycles, Blender {bpy.app.version_string} ({WIDTH}x{HEIGHT}, {SAMPLES} spp), "
              f"RaySplats/Cycles means: " + ", ".join(report))
        # The scene has every pass but transmission.
        for name in ("Emit", "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol"):
            self.assertGreater(cycles[name].mean(), 1e-3, name)
            self.assertGreater(ours[name].mean(), 1e-3, name)
        # Both engines' passes recombine to their Combined up to the world seen directly, where Combined is opaque.
        sky = cycles["DiffCol"].sum(axis=-1) + cycles["GlossCol"].sum(axis=-1) + cycles["Emit"].sum(axis=-1) == 0.0
        for out in (ours, cycles):
            difference = np.abs(recombined(out) - out["Combined"][..., :3])[~sky]
            self.assertLess(np.mean(difference), 0.01 * scale)


def mixed_scene():
    """The mesh scene with glass added, a polygon splat object of semi-transparent Gaussians over the floor and the
    sphere, and a compact one over the box; Film > Transparent."""
    scene = mesh_scene()
    scene.raysplats.samples = 16
    scene.render.film_transparent = True
    glass = st.principled("Glass", (1.0, 1.0, 1.0), roughness=0.0, transmission=1.0)
    st.add_with_material(bpy.ops.mesh.primitive_uv_sphere_add, glass, radius=0.4, location=(-0.3, -1.0, 0.4))
    polygons, _ = creation.add_gaussian_object(
        bpy.context, "Splats", st.flat_gaussian_cloud([(0.4, 0.0, 1.5), (-0.6, -0.6, 1.2)], 0.4, 0.7, SPLAT_COLOR), 8,
        3.0, "Z")
    compact = creation.add_compact_object(
        bpy.context, "Compact", st.flat_gaussian_cloud([(-1.2, 0.5, 1.2)], 0.3, 0.8, SPLAT_COLOR), "Z")
    return scene, polygons, compact


class LightPassesRecombine(unittest.TestCase):
    def test_in_each_gaussian_shading(self):
        for shading in ("BAKED", "LIT", "BAKED_SHADOWED"):
            with self.subTest(shading=shading):
                scene, _, _ = mixed_scene()
                scene.raysplats.gaussian_shading = shading
                out = render(scene, "RAYSPLATS", f"light_passes_mixed_{shading}")
                combined = out["Combined"][..., :3].astype(np.float64)
                error = np.abs(recombined(out) - combined) / np.maximum(1.0, np.abs(combined))
                print(f"\nLight passes recombined, {shading}, Blender {bpy.app.version_string}: largest error "
                      f"{error.max():.2e} (limit 1e-5)")
                self.assertLess(error.max(), 1e-5)
                # The Gaussians are seen, and their light is in the passes their shading gives them.
                self.assertGreater(out["Emit"].mean() if shading == "BAKED" else out["DiffDir"].mean(), 1e-3)
                self.assertGreater(out["TransCol"].mean(), 1e-3)


class BakedSplatEmission(unittest.TestCase):
    def test_emission_is_the_splat_colour_where_opaque_and_zero_on_a_plain_mesh(self):
        # An orthographic camera looking down at three coincident opaque Gaussians (sigma 2, alpha 0.99 at their
        # centre: within a quarter sigma of it, where the pixel filter takes the samples of the pixels checked, their
        # transmittance is below 1e-4, the threshold 1e-3 ends compositing) over a diffuse floor lit by a point light.
        scene = st.reset_render_scene(32, 24, samples=4)
        world = bpy.data.worlds.new("World")
        world.use_nodes = False
        st.set_world_color(world, (0.1, 0.1, 0.1))
        scene.world = world
        st.add_with_material(bpy.ops.mesh.primitive_plane_add, st.principled("Floor", (0.7, 0.6, 0.5)), size=20.0)
        bpy.ops.object.light_add(type="POINT", location=(0.0, 0.0, 6.0))
        bpy.context.object.data.energy = 500.0
        centre = (-3.875, 0.125)  # a pixel's centre
        creation.add_gaussian_object(
            bpy.context, "Splats", st.flat_gaussian_cloud([(*centre, 2.0)] * 3, 2.0, 1.0, SPLAT_COLOR), 8, 3.0, "Z")
        data = bpy.data.cameras.new("Camera")
        data.type, data.ortho_scale = "ORTHO", 8.0
        camera = bpy.data.objects.new("Camera", data)
        scene.collection.objects.link(camera)
        camera.location = (0.0, 0.0, 10.0)
        scene.camera = camera
        bpy.context.view_layer.use_pass_emit = True
        for blend in ("DISPLAY", "LINEAR"):
            with self.subTest(blend_space=blend):
                scene.raysplats.blend_space = blend
                exr = st.render_multilayer_exr(f"light_passes_emission_{blend}")
                layer = next(key.split(".")[0] for key in exr)
                emit = np.stack([exr[f"{layer}.{compat.render_pass_name('Emit')}.{c}"] for c in "RGB"], axis=-1)
                # Pixel centres: 8 / 32 = 0.25 units apart.
                i, j = np.meshgrid(np.arange(32) + 0.5, np.arange(24) + 0.5)
                x, y = (i - 16.0) * 0.25, (12.0 - j) * 0.25
                distance = np.hypot(x - centre[0], y - centre[1])
                linear = np.array([c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in SPLAT_COLOR])
                opaque = distance < 0.3  # the samples within 0.3 + 0.19 (the filter's reach) < sigma / 4
                self.assertEqual(np.sum(opaque), 4)  # the centre pixel (in the first column) and three neighbours
                np.testing.assert_allclose(emit[opaque], np.broadcast_to(linear, emit[opaque].shape), atol=1e-3)
                floor_only = distance > 6.5  # beyond the splats' 3-sigma disks and the filter's reach
                self.assertGreater(np.sum(floor_only), 50)
                self.assertTrue(np.all(emit[floor_only] == 0.0))


class LightPassCheckBoxes(unittest.TestCase):
    def test_blender_check_boxes_switch_the_passes_and_the_split(self):
        scene = mesh_scene()
        view_layer = bpy.context.view_layer
        for name in TOGGLES:
            setattr(view_layer, name, False)
        self.assertFalse(engine_passes.light_passes_enabled(view_layer))
        scene.raysplats.samples = 2
        self.assertEqual({name.split(".")[1] for name in st.render_multilayer_exr("light_passes_none")},
                         {"Combined"})
        view_layer.use_pass_emit = view_layer.use_pass_glossy_color = True
        self.assertTrue(engine_passes.light_passes_enabled(view_layer))
        self.assertEqual({name.split(".")[1] for name in st.render_multilayer_exr("light_passes_two")},
                         {"Combined", compat.render_pass_name("Emit"), compat.render_pass_name("GlossCol")})

    def test_the_light_panel_draws_every_light_pass_with_blenders_own_property(self):
        keys = [key for _, rows in engine_passes.LIGHT_PASS_LAYOUT for key, _ in rows]
        channels = {channel["key"]: channel for channel in st.native().film_channels()}
        self.assertEqual(sorted(channels[key]["pass_name"] for key in keys), sorted(LIGHT_PASSES))
        for key in keys:
            owner, prop = engine_passes._toggle(bpy.context.view_layer, channels[key])
            self.assertEqual(owner, bpy.context.view_layer)
            self.assertIn(prop, TOGGLES)
        self.assertTrue(hasattr(bpy.types, "RAYSPLATS_VIEWLAYER_PT_passes_light"))


if __name__ == "__main__":
    unittest.main()
