# What an import sets up for Blender's own viewport: the material draws its falloff alpha with
# stochastic transparency, which needs no sorting (Alpha Hashed on 3.x, Dithered on 4.2+; alpha Blend drew the
# back of a splat object over its front); EEVEE's viewport samples are raised so that it converges; the 3D views
# that show the new object colour Solid shading (also Edit Mode's) by the splat colour attribute. All on by
# default; imports without a screen must still work.
# How close Material Preview then comes to the render is measured by gui/material_preview_agreement.py.
import types
import unittest

import bpy

import splat_testing as st
from raysplats.blender import compat
from raysplats.objects import falloff_material, polygon_mesh
from raysplats.blender import viewport_shading

SCENE = "small_sh3_inria.ply"


def view3d_spaces():
    return [space for window in bpy.context.window_manager.windows for area in window.screen.areas
            if area.type == "VIEW_3D" for space in area.spaces if space.type == "VIEW_3D"]


class ImportViewportShading(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        # Factory settings have a 3D view even in --background and in the bpy module; the tests need one.
        self.assertTrue(view3d_spaces(), "the factory startup has no 3D view")
        for space in view3d_spaces():
            space.shading.color_type = "MATERIAL"

    def test_material_needs_no_sorting(self):
        obj = st.import_file(SCENE)
        gaussian_material = obj.data.materials[0]
        self.assertEqual(gaussian_material.name, falloff_material.MATERIAL_NAME)
        if bpy.app.version >= (4, 2, 0):
            self.assertEqual(gaussian_material.surface_render_method, "DITHERED")
            self.assertTrue(gaussian_material.use_transparent_shadow)
        else:
            self.assertEqual(gaussian_material.blend_method, "HASHED")
            self.assertEqual(gaussian_material.shadow_method, "HASHED")

    def test_material_preview_samples_are_raised_not_lowered(self):
        eevee = bpy.context.scene.eevee
        eevee.taa_samples = 16  # EEVEE's default: too few for hashed transparency to converge
        st.import_file(SCENE)
        self.assertEqual(eevee.taa_samples, 64)
        eevee.taa_samples = 128
        st.import_file(SCENE)
        self.assertEqual(eevee.taa_samples, 128)
        eevee.taa_samples = 16
        st.import_file(SCENE, preview_samples=0)
        self.assertEqual(eevee.taa_samples, 16)

    def test_solid_views_show_the_splat_colour(self):
        obj = st.import_file(SCENE)
        # Solid's "Attribute" colour draws the active colour attribute: it must be the splat colour.
        self.assertEqual(obj.data.color_attributes.active_color.name, polygon_mesh.ATTR_COLOR)
        for space in view3d_spaces():
            self.assertEqual(space.shading.color_type, compat.SOLID_COLOR_TYPE_ATTRIBUTE)

    def test_option_off_keeps_the_solid_colour(self):
        st.import_file(SCENE, color_solid_views=False)
        for space in view3d_spaces():
            self.assertEqual(space.shading.color_type, "MATERIAL")

    def test_views_of_another_scene_keep_their_solid_colour(self):
        obj = st.import_file(SCENE, color_solid_views=False)
        # As if the object had been imported into a scene that no window shows.
        other_scene = types.SimpleNamespace(scene=bpy.data.scenes.new("Other"),
                                            window_manager=bpy.context.window_manager)
        self.assertEqual(viewport_shading.show_splat_colors_in_solid_views(other_scene, obj), 0)
        for space in view3d_spaces():
            self.assertEqual(space.shading.color_type, "MATERIAL")
        self.assertEqual(viewport_shading.show_splat_colors_in_solid_views(bpy.context, obj), len(view3d_spaces()))

    def test_import_without_a_screen(self):
        # No window, hence no screen (overriding screen=None as well crashes bpy 4.2 itself).
        with bpy.context.temp_override(window=None):
            self.assertIsNone(bpy.context.screen)
            obj = st.import_file(SCENE)
        self.assertEqual(len(obj.data.polygons), 9080)
        # A script's own context may have no window manager at all: nothing to switch, no error.
        headless = types.SimpleNamespace(scene=bpy.context.scene, window_manager=None)
        self.assertEqual(viewport_shading.show_splat_colors_in_solid_views(headless, obj), 0)
