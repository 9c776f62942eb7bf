# Render passes come from the core's film channel table: each channel can be switched on in View Layer > Passes,
# F12 fills it, and Blender writes it to a multilayer EXR with the values the geometry predicts (depth of a plane
# at a known distance, its normal, its coverage).
import unittest

import bpy
import numpy as np

import splat_testing as st


class RenderPasses(unittest.TestCase):
    def setUp(self):
        scene = st.reset_render_scene(40, 30, samples=2)
        world = bpy.data.worlds.new("World")
        world.use_nodes = False
        st.set_world_color(world, (0.1, 0.1, 0.1))
        scene.world = world
        # An orthographic camera 3 units above a plane z = 0 that covers the left half of the view.
        bpy.ops.mesh.primitive_plane_add(size=1.0)
        plane = bpy.context.active_object
        plane.scale = (2.0, 4.0, 1.0)
        plane.location = (-1.0, 0.0, 0.0)
        data = bpy.data.cameras.new("Camera")
        data.type, data.ortho_scale = "ORTHO", 4.0
        camera = bpy.data.objects.new("Camera", data)
        scene.collection.objects.link(camera)
        camera.location = (0.0, 0.0, 3.0)
        scene.camera = camera

    def render_exr(self, name):
        return st.render_multilayer_exr(name)

    def test_every_film_channel_has_a_pass_check_box(self):
        view_layer = bpy.context.view_layer
        keys = [channel["key"] for channel in st.native().film_channels()]
        self.assertEqual(keys[:4], ["rgba", "depth", "normal", "alpha"])
        # Alpha has no Blender check box: the add-on made one from the table.
        self.assertFalse(view_layer.raysplats_passes.use_pass_alpha)
        self.assertIn("use_pass_alpha", view_layer.raysplats_passes.bl_rna.properties.keys())

    def test_pass_check_boxes_have_blenders_labels(self):
        # Blender's own labels on every Blender, not the passes' names (IndexOB and IndexMA before 5.0).
        from raysplats.engine import passes
        layout = st.RecordingLayout()
        passes.draw_pass_toggles(layout, bpy.context.view_layer)
        labels = {name: text for _, name, text in layout.log}
        self.assertEqual(labels["use_pass_object_index"], "Object Index")
        self.assertEqual(labels["use_pass_material_index"], "Material Index")
        self.assertEqual(labels["use_pass_environment"], "Environment")
        self.assertEqual(labels["use_pass_mist"], "Mist")

    def test_the_mist_pass_alone_asks_the_core_for_mist(self):
        # The core computes the Mist pass's sums only when the view layer has the pass (render setting mist_pass).
        from raysplats.engine import passes
        view_layer = bpy.context.view_layer
        self.assertFalse(passes.core_settings(view_layer)["mist_pass"])
        view_layer.use_pass_mist = True
        self.assertTrue(passes.core_settings(view_layer)["mist_pass"])
        exr = self.render_exr("passes_mist_flag")
        layer = next(name.split(".")[0] for name in exr)
        # The plane (3 units away, within the default mist's 100) has mist below 1; the world's is 1.
        mist = exr[f"{layer}.Mist.Z"]
        self.assertLess(float(mist[15, 5]), 0.1)
        self.assertEqual(float(mist[15, 35]), 1.0)

    def test_only_enabled_passes_are_written(self):
        # Blender's own check boxes of the data passes are off in a new scene.
        view_layer = bpy.context.view_layer
        for name in ("use_pass_mist", "use_pass_position", "use_pass_object_index", "use_pass_material_index"):
            self.assertFalse(getattr(view_layer, name), name)
        exr = self.render_exr("passes_default")
        layers = {name.split(".")[1] for name in exr}
        self.assertEqual(layers, {"Combined"})

    def test_depth_normal_and_alpha_passes_hold_the_plane(self):
        view_layer = bpy.context.view_layer
        view_layer.use_pass_z = True
        view_layer.use_pass_normal = True
        view_layer.raysplats_passes.use_pass_alpha = True
        exr = self.render_exr("passes_all")
        layer = next(name.split(".")[0] for name in exr)
        depth = exr[f"{layer}.Depth.Z"]
        alpha = exr[f"{layer}.Alpha.A"]
        normal = np.stack([exr[f"{layer}.Normal.{c}"] for c in "XYZ"], axis=-1)
        left, right = np.s_[:, 2:18], np.s_[:, 22:]  # the plane's half and the background's (away from the edge)
        np.testing.assert_allclose(depth[left], 3.0, rtol=1e-5)
        self.assertTrue(np.all(depth[right] == 1e10))  # nothing there: Blender's far value
        np.testing.assert_allclose(normal[left], np.broadcast_to((0.0, 0.0, 1.0), normal[left].shape), atol=1e-6)
        self.assertTrue(np.all(normal[right] == 0.0))
        self.assertTrue(np.all(alpha[left] == 1.0))
        self.assertTrue(np.all(alpha[right] == 0.0))
        combined_alpha = exr[f"{layer}.Combined.A"]
        self.assertTrue(np.all(combined_alpha == 1.0))  # no Film > Transparent: opaque

    def test_denoising_passes_hold_the_base_colour_and_normal_only_when_checked(self):
        # The plane's base colour (linear) is its Denoising Albedo, the world's colour the background's (as Cycles'
        # background adds its colour); the normal is the plane's, 0 for the world.
        base_color = (0.2, 0.5, 0.7)
        material = bpy.data.materials.new("Base")
        material.use_nodes = True
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*base_color, 1.0)
        bpy.data.objects["Plane"].data.materials.append(material)
        scene, view_layer = bpy.context.scene, bpy.context.view_layer
        self.assertFalse(view_layer.raysplats_passes.use_pass_denoising_albedo)
        self.assertFalse(view_layer.raysplats_passes.use_pass_denoising_normal)
        # Denoising on (where Blender has a denoiser) computes the guides but writes no pass unless checked.
        scene.raysplats.use_denoising = True
        exr = self.render_exr("passes_denoise_unchecked")
        self.assertEqual({name.split(".")[1] for name in exr}, {"Combined"})
        scene.raysplats.use_denoising = False
        view_layer.raysplats_passes.use_pass_denoising_albedo = True
        view_layer.raysplats_passes.use_pass_denoising_normal = True
        exr = self.render_exr("passes_denoising")
        layer = next(name.split(".")[0] for name in exr)
        albedo = np.stack([exr[f"{layer}.Denoising Albedo.{c}"] for c in "RGB"], axis=-1)
        normal = np.stack([exr[f"{layer}.Denoising Normal.{c}"] for c in "XYZ"], axis=-1)
        left, right = np.s_[:, 2:18], np.s_[:, 22:]
        np.testing.assert_allclose(albedo[left], np.broadcast_to(base_color, albedo[left].shape), atol=1e-6)
        np.testing.assert_allclose(albedo[right], 0.1, atol=1e-6)
        np.testing.assert_allclose(normal[left], np.broadcast_to((0.0, 0.0, 1.0), normal[left].shape), atol=1e-6)
        self.assertTrue(np.all(normal[right] == 0.0))

    def test_film_transparent_makes_the_background_transparent(self):
        bpy.context.scene.render.film_transparent = True  # RaySplats' Film panel draws this check box
        exr = self.render_exr("passes_transparent")
        layer = next(name.split(".")[0] for name in exr)
        combined_alpha = exr[f"{layer}.Combined.A"]
        self.assertTrue(np.all(combined_alpha[:, 2:18] == 1.0))
        self.assertTrue(np.all(combined_alpha[:, 22:] == 0.0))

    def test_gaussian_count_pass_counts_the_splats_each_pixel_composites(self):
        scene = bpy.context.scene
        donut = st.import_file("donut_sh0.ply")
        # The camera 1 unit above the donut's origin (its splats' centroid), seeing it whole.
        scene.camera.location = (donut.location.x, donut.location.y, donut.location.z + 1.0)
        scene.camera.data.ortho_scale = 0.5
        bpy.data.objects.remove(bpy.data.objects["Plane"])
        view_layer = bpy.context.view_layer
        view_layer.raysplats_passes.use_pass_gaussian_count = True
        view_layer.raysplats_passes.use_pass_alpha = True
        exr = self.render_exr("passes_gaussian_count")
        layer = next(name.split(".")[0] for name in exr)
        count = exr[f"{layer}.Gaussian Count.X"]
        alpha = exr[f"{layer}.Alpha.A"]
        self.assertGreater(np.sum(alpha > 0.5), 20)
        # Opaque pixels took several splats (sorted compositing composites every one before the cut-off); where
        # nothing is there, none.
        self.assertGreater(np.mean(count[alpha > 0.5]), 2.0)
        self.assertTrue(np.all(count[alpha == 0.0] == 0.0))
        self.assertTrue(np.all(count == np.round(count * 2) / 2))  # a mean of 2 samples' whole counts


if __name__ == "__main__":
    unittest.main()
