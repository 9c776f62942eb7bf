# Render Properties panels of the RaySplats engine, and the Blender panels it is compatible with.
import bpy

from ..blender import compat, denoiser
from . import color_management, motion_blur, passes

ENGINE = "RAYSPLATS"

# Blender's own panels that work unchanged with this engine (dimensions, output, camera, light, material).
_COMPATIBLE_PANELS = (
    "RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_color_management",
    "DATA_PT_camera", "DATA_PT_lens", "DATA_PT_camera_display", "DATA_PT_light",
    "DATA_PT_EEVEE_light", "DATA_PT_area", "DATA_PT_spot", "EEVEE_MATERIAL_PT_surface", "MATERIAL_PT_preview",
    "EEVEE_WORLD_PT_surface", "WORLD_PT_context_world", "VIEWLAYER_PT_layer_passes", "RENDER_PT_format_presets",
    # World > Mist Pass (start, depth, falloff), shown as Cycles shows its own once a view layer has the Mist pass.
    "EEVEE_WORLD_PT_mist",
    # Camera > Depth of Field and its Aperture subpanel: every Camera.dof setting the engine reads (focus distance or
    # object, f-stop, blades, rotation, ratio), where Cycles shows them.
    "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture",
    # View Layer > Passes > Cryptomatte: Object, Material, Asset and Levels, Blender's own settings that Cycles' panel
    # of the same name draws (EEVEE's Accurate Mode is drawn only for EEVEE).
    "VIEWLAYER_PT_layer_passes_cryptomatte",
    # Object > Visibility: Show In and Mask > Holdout (Object.is_holdout), which the engine renders as Cycles does;
    # a collection's Holdout is the Outliner's own toggle. draw_shadow_catcher adds Blender's Shadow Catcher there.
    "OBJECT_PT_visibility",
)


class RaySplatsPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class RAYSPLATS_RENDER_PT_sampling(RaySplatsPanel, bpy.types.Panel):
    bl_label = "Sampling"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.raysplats
        # As Cycles' Sampling > Render: the noise threshold with its check box on one row, then the samples (the
        # maximum once adaptive sampling is on) and the minimum.
        heading = layout.column(align=True, heading="Noise Threshold")
        row = heading.row(align=True)
        row.prop(settings, "use_adaptive_sampling", text="")
        sub = row.row()
        sub.active = settings.use_adaptive_sampling
        sub.prop(settings, "adaptive_threshold", text="")
        column = layout.column(align=True)
        column.prop(settings, "samples", text="Max Samples" if settings.use_adaptive_sampling else "Render")
        sub = column.row(align=True)
        sub.active = settings.use_adaptive_sampling
        sub.prop(settings, "adaptive_min_samples", text="Min Samples")
        layout.prop(settings, "viewport_samples", text="Viewport")
        row = layout.row(align=True)
        row.prop(settings, "seed")
        row.prop(settings, "use_animated_seed", text="", icon="TIME")


class RAYSPLATS_RENDER_PT_sampling_denoise(RaySplatsPanel, bpy.types.Panel):
    """As Cycles' Sampling > Render > Denoise: the final render's check box in the header, the viewport's below;
    greyed out, with the reason, where this Blender has no OpenImageDenoise."""
    bl_label = "Denoise"
    bl_parent_id = "RAYSPLATS_RENDER_PT_sampling"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.active = denoiser.available()
        self.layout.prop(context.scene.raysplats, "use_denoising", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.active = denoiser.available()
        layout.prop(context.scene.raysplats, "use_preview_denoising", text="Viewport")
        if not denoiser.available():
            layout.label(text="This Blender has no OpenImageDenoise", icon="INFO")


class RAYSPLATS_RENDER_PT_gaussians(RaySplatsPanel, bpy.types.Panel):
    bl_label = "Gaussians"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.raysplats
        layout.prop(settings, "gaussian_mode")
        layout.prop(settings, "compositing")
        layout.prop(settings, "blend_space")
        # Splatting draws only Baked splats (the core keeps camera rays traced when any object is relit). The check
        # boxes' long names are split into a heading and the box's text, as Cycles does, so that they fit the
        # properties editor's default width.
        row = layout.row(heading="Camera Rays")
        row.active = settings.gaussian_shading == "BAKED"
        row.prop(settings, "camera_ray_splatting", text="As Splats")
        layout.prop(settings, "transmittance_threshold")
        layout.prop(settings, "gaussian_shading")
        row = layout.row(heading="Shadows")
        row.active = settings.gaussian_shading == "BAKED"
        row.prop(settings, "meshes_shadow_gaussians", text="From Meshes")


class RAYSPLATS_RENDER_PT_film(RaySplatsPanel, bpy.types.Panel):
    """Film: transparent background and the pixel filter (EEVEE's Film panel has settings this engine does not
    use, so it has its own), and the note on the view transform."""
    bl_label = "Film"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        scene = context.scene
        layout.prop(scene.render, "film_transparent", text="Transparent")
        column = layout.column(align=True)
        column.prop(scene.raysplats, "pixel_filter")
        column.prop(scene.raysplats, "filter_width")
        color_management.draw_note(layout, scene)


class RAYSPLATS_RENDER_PT_light_paths(RaySplatsPanel, bpy.types.Panel):
    bl_label = "Light Paths"

    def draw(self, context):
        self.layout.use_property_split = True
        self.layout.prop(context.scene.raysplats, "max_bounces")
        column = self.layout.column(heading="Caustics", align=True)
        column.prop(context.scene.raysplats, "caustics_reflective", text="Reflective")
        column.prop(context.scene.raysplats, "caustics_refractive", text="Refractive")


class RAYSPLATS_RENDER_PT_motion_blur(RaySplatsPanel, bpy.types.Panel):
    """Blender's motion blur settings as Cycles' Motion Blur panel draws them (Cycles' own panel cannot be declared
    compatible: its engine set is shared by every Cycles panel). Final renders only, as in Cycles."""
    bl_label = "Motion Blur"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.render, "use_motion_blur", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        render = context.scene.render
        column = layout.column()
        column.active = render.use_motion_blur
        column.prop(motion_blur.position_settings(context.scene), "motion_blur_position", text="Position")
        column.prop(render, "motion_blur_shutter")


class RAYSPLATS_RENDER_PT_motion_blur_curve(RaySplatsPanel, bpy.types.Panel):
    """The shutter curve, as Cycles' Shutter Curve subpanel draws it."""
    bl_label = "Shutter Curve"
    bl_parent_id = "RAYSPLATS_RENDER_PT_motion_blur"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        render = context.scene.render
        self.layout.active = render.use_motion_blur
        self.layout.template_curve_mapping(render, "motion_blur_shutter_curve")


class RAYSPLATS_OBJECT_PT_motion_blur(RaySplatsPanel, bpy.types.Panel):
    """An object's motion blur switch, steps and Deformation switch (Object.cycles, the Cycles add-on's, which the
    engine reads as Cycles does), as Cycles' Object Properties > Motion Blur draws them. Deformation blurs meshes and
    polygon splat objects whose vertices move during the shutter; point splat objects keep their object's motion only
    (docs)."""
    bl_label = "Motion Blur"
    bl_context = "object"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        obj = context.object
        return super().poll(context) and obj is not None and hasattr(getattr(obj, "cycles", None), "motion_steps")

    def draw_header(self, context):
        self.layout.active = context.scene.render.use_motion_blur
        self.layout.prop(context.object.cycles, "use_motion_blur", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.object.cycles
        layout.active = context.scene.render.use_motion_blur and settings.use_motion_blur
        column = layout.column()
        column.prop(settings, "motion_steps", text="Steps")
        if context.object.type != "CAMERA":
            column.prop(settings, "use_deform_motion", text="Deformation")


class RAYSPLATS_RENDER_PT_performance(RaySplatsPanel, bpy.types.Panel):
    """Blender's own settings where Cycles shows them (Render Properties > Performance): the thread count of final
    renders and Persistent Data, which keeps the scene and its BVH from frame to frame (final.py)."""
    bl_label = "Performance"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        pass


class RAYSPLATS_RENDER_PT_performance_threads(RaySplatsPanel, bpy.types.Panel):
    bl_label = "Threads"
    bl_parent_id = "RAYSPLATS_RENDER_PT_performance"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        render = context.scene.render
        layout.prop(render, "threads_mode")
        sub = layout.column(align=True)
        sub.enabled = render.threads_mode == "FIXED"
        sub.prop(render, "threads")


class RAYSPLATS_RENDER_PT_performance_final_render(RaySplatsPanel, bpy.types.Panel):
    bl_label = "Final Render"
    bl_parent_id = "RAYSPLATS_RENDER_PT_performance"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.prop(context.scene.render, "use_persistent_data", text="Persistent Data")


# The Scene.raysplats settings the panels above lay out; any other (a render setting just added to the core and to
# render_properties.py) is shown by the Other Settings panel until it is given its place.
LAID_OUT_SETTINGS = frozenset({
    "use_adaptive_sampling", "adaptive_threshold", "samples", "adaptive_min_samples", "viewport_samples", "seed",
    "use_animated_seed", "use_denoising", "use_preview_denoising", "gaussian_mode", "compositing", "blend_space", "camera_ray_splatting",
    "transmittance_threshold", "gaussian_shading", "meshes_shadow_gaussians", "pixel_filter", "filter_width",
    "max_bounces", "caustics_reflective", "caustics_refractive"})


def other_settings(settings):
    """The names of the Scene.raysplats properties no panel above lays out, in their declaration order."""
    return [prop.identifier for prop in settings.bl_rna.properties
            if prop.identifier not in ("rna_type", "name") and prop.identifier not in LAID_OUT_SETTINGS]


class RAYSPLATS_RENDER_PT_other(RaySplatsPanel, bpy.types.Panel):
    """Render settings no other panel lays out yet, so that every setting can be seen and changed."""
    bl_label = "Other Settings"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return super().poll(context) and bool(other_settings(context.scene.raysplats))

    def draw(self, context):
        self.layout.use_property_split = True
        for name in other_settings(context.scene.raysplats):
            self.layout.prop(context.scene.raysplats, name)


class RAYSPLATS_CAMERA_PT_panorama(RaySplatsPanel, bpy.types.Panel):
    bl_label = "Panorama (RaySplats)"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        camera = context.camera
        return (super().poll(context) and camera is not None and camera.type == "PANO"
                and not compat.CAMERA_HAS_PANORAMA_SETTINGS)  # Blender 4 shows its own settings

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.camera.raysplats
        layout.prop(settings, "panorama_type")
        if settings.panorama_type == "EQUIRECTANGULAR":
            for key in ("latitude_min", "latitude_max", "longitude_min", "longitude_max"):
                layout.prop(settings, key)
        else:
            layout.prop(settings, "fisheye_fov")
            if settings.panorama_type == "FISHEYE_EQUISOLID":
                layout.prop(settings, "fisheye_lens")


class RAYSPLATS_VIEWLAYER_PT_passes(RaySplatsPanel, bpy.types.Panel):
    """View Layer > Passes: a check box per film channel of the core (engine/passes.py)."""
    bl_label = "Data"
    bl_context = "view_layer"
    bl_parent_id = "VIEWLAYER_PT_layer_passes"

    def draw(self, context):
        self.layout.use_property_split = True
        self.layout.use_property_decorate = False
        passes.draw_pass_toggles(self.layout, context.view_layer)


class RAYSPLATS_VIEWLAYER_PT_passes_light(RaySplatsPanel, bpy.types.Panel):
    """View Layer > Passes > Light: Blender's own light pass check boxes, as Cycles draws them (Cycles' own panel
    also draws Volume and Ambient Occlusion check boxes, passes this engine does not write, so it is not declared
    compatible; Environment and Shadow Catcher are in the Passes panel's list)."""
    bl_label = "Light"
    bl_context = "view_layer"
    bl_parent_id = "VIEWLAYER_PT_layer_passes"

    def draw(self, context):
        self.layout.use_property_split = True
        self.layout.use_property_decorate = False
        passes.draw_light_pass_toggles(self.layout, context.view_layer)


def draw_shadow_catcher(self, context):
    """Object > Visibility > Mask: Blender's Shadow Catcher (Object.is_shadow_catcher), which Cycles draws in its own
    Visibility panel (not shown for this engine) and this engine renders on meshes."""
    if context.engine == ENGINE:
        self.layout.prop(context.object, "is_shadow_catcher")


_CLASSES = (RAYSPLATS_RENDER_PT_sampling, RAYSPLATS_RENDER_PT_sampling_denoise, RAYSPLATS_RENDER_PT_gaussians,
            RAYSPLATS_RENDER_PT_film, RAYSPLATS_RENDER_PT_light_paths, RAYSPLATS_RENDER_PT_motion_blur,
            RAYSPLATS_RENDER_PT_motion_blur_curve, RAYSPLATS_OBJECT_PT_motion_blur, RAYSPLATS_RENDER_PT_performance,
            RAYSPLATS_RENDER_PT_performance_threads, RAYSPLATS_RENDER_PT_performance_final_render,
            RAYSPLATS_RENDER_PT_other,
            RAYSPLATS_CAMERA_PT_panorama, RAYSPLATS_VIEWLAYER_PT_passes, RAYSPLATS_VIEWLAYER_PT_passes_light)


def register():
    color_management.register()
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    for name in _COMPATIBLE_PANELS:
        panel = getattr(bpy.types, name, None)
        if panel is not None and hasattr(panel, "COMPAT_ENGINES"):
            panel.COMPAT_ENGINES.add(ENGINE)
    bpy.types.OBJECT_PT_visibility.append(draw_shadow_catcher)


def unregister():
    bpy.types.OBJECT_PT_visibility.remove(draw_shadow_catcher)
    for name in _COMPATIBLE_PANELS:
        panel = getattr(bpy.types, name, None)
        if panel is not None and hasattr(panel, "COMPAT_ENGINES"):
            panel.COMPAT_ENGINES.discard(ENGINE)
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    color_management.unregister()
