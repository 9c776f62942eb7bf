# Render Properties > Film of the RaySplats engine (engine/ui.py): Transparent and the pixel filter, and the note on
# the view transform with its one-click switch (engine/color_management.py); the settings reach the core.
import unittest

import bpy

import splat_testing as st
from raysplats.engine import color_management, sync, ui


class _RecordingLayout:
    """Stands in for a panel's UILayout: records every prop (owner type, property) and operator drawn."""

    def __init__(self, log=None):
        self.log = [] if log is None else log
        self.use_property_split = self.use_property_decorate = False

    def prop(self, owner, name, **kwargs):
        self.log.append(("prop", type(owner).__name__, name))

    def operator(self, idname, **kwargs):
        self.log.append(("operator", idname))

    def label(self, **kwargs):
        self.log.append(("label", kwargs.get("text", "")))

    def column(self, **kwargs):
        return _RecordingLayout(self.log)

    row = box = column


def draw_film_panel(context):
    panel = type("Panel", (), {"layout": _RecordingLayout()})()
    ui.RAYSPLATS_RENDER_PT_film.draw(panel, context)
    return panel.layout.log


def drawn_settings(panel_class, context):
    """The Scene.raysplats properties a render panel draws."""
    panel = type("Panel", (), {"layout": _RecordingLayout()})()
    panel_class.draw(panel, context)
    if hasattr(panel_class, "draw_header"):
        panel_class.draw_header(panel, context)
    return {entry[2] for entry in panel.layout.log if entry[:2] == ("prop", "RaySplatsRenderSettings")}


class FilmSettings(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        bpy.context.scene.render.engine = "RAYSPLATS"

    def test_film_panel_shows_transparent_and_the_pixel_filter(self):
        self.assertTrue(ui.RAYSPLATS_RENDER_PT_film.poll(bpy.context))
        log = draw_film_panel(bpy.context)
        self.assertIn(("prop", "RenderSettings", "film_transparent"), log)
        self.assertIn(("prop", "RaySplatsRenderSettings", "pixel_filter"), log)
        self.assertIn(("prop", "RaySplatsRenderSettings", "filter_width"), log)

    def test_every_render_setting_is_shown_in_a_panel(self):
        context = bpy.context
        panels = (ui.RAYSPLATS_RENDER_PT_sampling, ui.RAYSPLATS_RENDER_PT_sampling_denoise,
                  ui.RAYSPLATS_RENDER_PT_gaussians, ui.RAYSPLATS_RENDER_PT_film, ui.RAYSPLATS_RENDER_PT_light_paths)
        laid_out = set().union(*(drawn_settings(panel, context) for panel in panels))
        self.assertEqual(laid_out, set(ui.LAID_OUT_SETTINGS))
        properties = {p.identifier for p in context.scene.raysplats.bl_rna.properties} - {"rna_type", "name"}
        self.assertEqual(laid_out, properties)
        self.assertFalse(ui.RAYSPLATS_RENDER_PT_other.poll(context))
        # A setting no panel lays out yet (here: one taken out of the list) is shown by Other Settings.
        original = ui.LAID_OUT_SETTINGS
        ui.LAID_OUT_SETTINGS = original - {"blend_space"}
        try:
            self.assertTrue(ui.RAYSPLATS_RENDER_PT_other.poll(context))
            self.assertEqual(drawn_settings(ui.RAYSPLATS_RENDER_PT_other, context), {"blend_space"})
        finally:
            ui.LAID_OUT_SETTINGS = original

    def test_a_view_transform_other_than_standard_gets_a_note_and_a_switch(self):
        scene = bpy.context.scene
        scene.view_settings.view_transform = "Filmic"  # 3.x's default (4.x defaults to AgX)
        self.assertFalse(color_management.shows_trained_colors(scene))
        self.assertIn(("operator", "raysplats.use_standard_view_transform"), draw_film_panel(bpy.context))
        self.assertEqual(bpy.ops.raysplats.use_standard_view_transform(), {"FINISHED"})
        self.assertEqual(scene.view_settings.view_transform, "Standard")
        self.assertTrue(color_management.shows_trained_colors(scene))
        self.assertNotIn(("operator", "raysplats.use_standard_view_transform"), draw_film_panel(bpy.context))
        # A look on top of Standard still alters the colours.
        scene.view_settings.look = "High Contrast"  # one of Standard's looks in 3.4 and 4.2
        self.assertFalse(color_management.shows_trained_colors(scene))

    def test_the_pixel_filter_reaches_the_core(self):
        scene = bpy.context.scene
        settings = sync.render_settings(scene, 8, 8, 1)
        self.assertEqual((settings["pixel_filter"], settings["filter_width"]), ("BLACKMAN_HARRIS", 1.5))
        scene.raysplats.pixel_filter, scene.raysplats.filter_width = "GAUSSIAN", 3.0
        settings = sync.render_settings(scene, 8, 8, 1)
        self.assertEqual((settings["pixel_filter"], settings["filter_width"]), ("GAUSSIAN", 3.0))
        names = {s["name"]: s for s in st.native().render_settings()}
        self.assertEqual(sorted(names["pixel_filter"]["choices"]),
                         sorted(item.identifier for item in scene.raysplats.bl_rna.properties["pixel_filter"].enum_items))


if __name__ == "__main__":
    unittest.main()
