# Relightable splats in Blender: Render Properties > Gaussians > Shading and the object's own Shading (Object
# Properties > Gaussian Splats), on a real splat scene under a sun: baked splats ignore the sun, lit ones scale with
# it, an object's setting overrides the scene's, baked + shadows darkens where a mesh hides the sun, and the
# viewport's scene sync applies a changed object shading in place.
import math
import unittest

import bpy
import mathutils
import numpy as np

import splat_testing as st

DONUT = "donut_sh0.ply"


def new_scene():
    st.reset_scene()
    scene = bpy.context.scene
    scene.render.engine = "RAYSPLATS"
    scene.render.resolution_x, scene.render.resolution_y = 96, 72
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = 4
    scene.raysplats.max_bounces = 0
    # Baked references composited linearly, as lit and shadowed splats are (the display blend is tested elsewhere).
    scene.raysplats.blend_space = "LINEAR"
    # Traced camera rays in every mode: a scene with relit objects is traced whole, and the baked references are
    # compared with relit images pixel by pixel (camera-ray splatting is tested in test_camera_ray_splatting.py).
    scene.raysplats.camera_ray_splatting = False
    scene.view_settings.view_transform = "Standard"
    scene.render.film_transparent = True  # alpha = coverage: the donut's pixels
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (0.0, 0.0, 0.0))
    scene.world = world
    donut = st.import_file(DONUT, up_axis="Z")
    centres = st.native().read_splats(st.data_file(DONUT))["positions"].astype(np.float64)
    donut.location = -mathutils.Vector(centres.mean(axis=0))
    data = bpy.data.cameras.new("Camera")
    data.clip_start = 0.01
    camera = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(camera)
    direction = mathutils.Vector((0.0, 0.6, -0.8))
    camera.location = -0.7 * direction
    camera.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.camera = camera
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(30), 0.0, 0.0))
    sun = bpy.context.object
    return scene, donut, sun


class Relighting(unittest.TestCase):
    def test_settings_are_registered_with_baked_defaults(self):
        scene, donut, _ = new_scene()
        self.assertEqual(scene.raysplats.gaussian_shading, "BAKED")
        self.assertEqual(donut.raysplats.gaussian_shading, "SCENE")
        self.assertEqual([item.identifier for item in
                          donut.raysplats.bl_rna.properties["gaussian_shading"].enum_items],
                         ["SCENE", "BAKED", "LIT", "BAKED_SHADOWED"])
        # The scene's items are the core's names (the render setting table).
        names = next(s for s in st.native().render_settings() if s["name"] == "gaussian_shading")["choices"]
        self.assertEqual([item.identifier for item in
                          scene.raysplats.bl_rna.properties["gaussian_shading"].enum_items], list(names))

    def test_baked_ignores_the_sun_lit_follows_it_and_the_object_overrides_the_scene(self):
        scene, donut, sun = new_scene()
        covered = None

        def render(strength, name):
            nonlocal covered
            sun.data.energy = strength
            image = st.render_to_array(name)
            if covered is None:
                covered = image[..., 3] > 0.99
            return image[..., :3][covered]

        baked_1, baked_2 = render(1.0, "baked_1"), render(2.0, "baked_2")
        self.assertGreater(covered.sum(), 500)
        np.testing.assert_array_equal(baked_1, baked_2)  # the captured light only
        donut.raysplats.gaussian_shading = "LIT"
        lit_1, lit_2 = render(1.0, "lit_1"), render(2.0, "lit_2")
        # Direct light only and a black world: the image is linear in the sun's strength (same seed, same samples).
        self.assertAlmostEqual(float(lit_2.sum() / lit_1.sum()), 2.0, places=3)
        self.assertGreater(float(np.abs(lit_1 - baked_1).mean()), 0.01)
        # The scene says LIT, the object says BAKED: baked, exactly as before.
        scene.raysplats.gaussian_shading = "LIT"
        donut.raysplats.gaussian_shading = "BAKED"
        np.testing.assert_array_equal(render(1.0, "override_baked"), baked_1)
        # The object follows the scene's LIT.
        donut.raysplats.gaussian_shading = "SCENE"
        np.testing.assert_allclose(render(1.0, "scene_lit"), lit_1, rtol=1e-6, atol=1e-7)

    def test_baked_shadowed_darkens_only_where_a_mesh_hides_the_sun(self):
        scene, donut, sun = new_scene()
        sun.rotation_euler = (0.0, 0.0, 0.0)  # straight down
        baked = st.render_to_array("shadow_baked")
        covered = baked[..., 3] > 0.99
        # A slab over the half y > 0 of the donut.
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 1.5, 1.0), scale=(3.0, 3.0, 0.05))
        donut.raysplats.gaussian_shading = "BAKED_SHADOWED"
        camera = scene.camera
        shadowed = st.render_to_array("shadow_shadowed")
        ratio = shadowed[..., :3].sum(axis=-1)[covered] / np.maximum(baked[..., :3].sum(axis=-1)[covered], 1e-6)
        self.assertLessEqual(float(ratio.max()), 1.0 + 1e-5)  # visibility never adds light
        self.assertGreater(float((ratio < 0.05).mean()), 0.2)   # a part lies in full shadow
        self.assertGreater(float((ratio > 0.95).mean()), 0.2)   # a part keeps its baked light
        self.assertIs(scene.camera, camera)

    def test_viewport_sync_applies_an_objects_shading_in_place(self):
        from raysplats.engine import sync
        scene, donut, _ = new_scene()
        bpy.context.view_layer.update()
        live = sync.SceneSync(bpy.context.evaluated_depsgraph_get(), interactive=True)
        live.render_scene.build("FLAT")
        uid = donut.as_pointer()
        self.assertIsNone(live.shading[uid])
        core = st.native()

        def image():
            settings = sync.render_settings(scene, 48, 36, 2)
            camera = sync.camera_settings(scene, scene.camera, 48, 36)
            return core.RenderJob(live.render_scene, camera, settings).result()["rgba"]

        before = image()
        changes = []

        def handler(scene_, depsgraph_):
            changes.append(live.update(depsgraph_))

        bpy.app.handlers.depsgraph_update_post.append(handler)
        try:
            donut.raysplats.gaussian_shading = "LIT"
            # In the UI the message bus reports the edit and tags the object (upkeep._shading_edited); headless
            # it is never delivered.
            donut.update_tag()
            bpy.context.view_layer.update()
        finally:
            bpy.app.handlers.depsgraph_update_post.remove(handler)
        self.assertEqual(changes, ["updated"])
        self.assertEqual(live.shading[uid], "LIT")
        self.assertGreater(float(np.abs(image() - before).max()), 1e-2)  # the sun now lights the splats

if __name__ == "__main__":
    unittest.main()
