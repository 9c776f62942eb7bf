# Render settings of the RaySplats engine: scene.raysplats (stable names, scripts rely on them; a property named as
# one of the core's render settings is copied into it by sync.render_settings) and the
# panoramic camera settings Blender 3.x keeps in Cycles' properties (camera.data.raysplats).
import math

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty


class RaySplatsRenderSettings(bpy.types.PropertyGroup):
    samples: IntProperty(name="Samples", default=16, min=1, max=1 << 16,
                         description="Samples per pixel of the final render")
    # Cycles' names, ranges and defaults (Sampling > Render > Noise Threshold), so that settings read the same.
    use_adaptive_sampling: BoolProperty(
        name="Noise Threshold", default=True,
        description="Automatically reduce the number of samples per pixel based on estimated noise level")
    adaptive_threshold: FloatProperty(
        name="Noise Threshold", default=0.01, min=0.0, max=1.0, soft_min=0.001, step=0.1, precision=4,
        description="Noise level step to stop sampling at, lower values reduce noise at the cost of render time. "
                    "Zero for automatic setting based on number of AA samples")
    adaptive_min_samples: IntProperty(
        name="Min Samples", default=0, min=0, max=4096,
        description="Minimum AA samples for adaptive sampling, to discover noisy features before stopping "
                    "sampling. Zero for automatic setting based on noise threshold")
    viewport_samples: IntProperty(name="Viewport Samples", default=16, min=1, max=1 << 12,
                                  description="Samples the viewport accumulates before it stops refining")
    # Cycles' names (Sampling > Render > Denoise, Sampling > Viewport > Denoise).
    use_denoising: BoolProperty(
        name="Denoise", default=False,
        description="Denoise the final render with OpenImageDenoise once its samples are done (official Blender "
                    "builds have it; where Blender has none, the render says so and is not denoised)")
    use_preview_denoising: BoolProperty(
        name="Denoise Viewport", default=False,
        description="Denoise the viewport's image with OpenImageDenoise once it has all its samples (where Blender "
                    "has it)")
    max_bounces: IntProperty(name="Max Bounces", default=4, min=0, max=1024,
                             description="Reflections and refractions followed per path (0: direct light only)")
    caustics_reflective: BoolProperty(
        name="Reflective Caustics", default=True,
        description="Let diffuse paths continue through glossy and mirror reflections (as Cycles' Caustics > "
                    "Reflective; off removes the noise of reflective caustics)")
    caustics_refractive: BoolProperty(
        name="Refractive Caustics", default=True,
        description="Let diffuse paths continue through refraction (as Cycles' Caustics > Refractive)")
    compositing: EnumProperty(
        name="Compositing", default="SORTED",
        items=(("SORTED", "Sorted", "Gaussians composited in exact depth order (the reference)"),
               ("STOCHASTIC", "Stochastic", "Each Gaussian accepted with probability alpha: no sorting, faster "
                                           "per sample, converges to the sorted image with more samples")),
        description="How Gaussians along a ray are combined")
    blend_space: EnumProperty(
        name="Blend Space", default="DISPLAY",
        items=(("DISPLAY", "As Trained", "Gaussian colours composited as the scene was trained and as splat viewers "
                                         "draw them (in sRGB display values), then made linear: with the Standard "
                                         "view transform an unedited scene looks as in its viewer"),
               ("LINEAR", "Linear", "Gaussian colours made linear, then composited: physically additive light, but "
                                    "haze, floaters and soft edges come out brighter than trained (a grey halo)")),
        description="Colour space in which Gaussians along a ray are composited; meshes, lights and the film are "
                    "linear either way")
    transmittance_threshold: FloatProperty(
        name="Transmittance Threshold", default=1e-3, min=0.0, max=0.5, precision=4,
        description="Stop compositing Gaussians once less than this fraction of light gets through")
    gaussian_mode: EnumProperty(
        name="Gaussians", default="FLAT",
        items=(("FLAT", "Flat", "Each Gaussian is a flat disk evaluated exactly where the ray meets its plane"),
               ("VOLUMETRIC", "Volumetric", "Each Gaussian is an ellipsoid (uses the stored thickness)")),
        description="Geometry the Gaussians are traced as")
    gaussian_shading: EnumProperty(
        name="Shading", default="BAKED",
        items=(("BAKED", "Baked", "The captured light, as trained: scene lights do not change the splats"),
               ("LIT", "Lit", "Each splat is a surface lit by the scene's lights and world, with shadows from meshes "
                              "and splats (its colour, with the capture's light divided out, is its albedo)"),
               ("BAKED_SHADOWED", "Baked + Shadows", "The captured light, darkened where meshes and splats hide the "
                                                     "scene's lights")),
        description="How splats' colours are produced (objects can override it in their Gaussian Splats panel)")
    # On by default: splatted, an unedited scene shows what its viewer shows (62-80 dB against the EWA rasterizer, traced
    # 26-36 dB), and a sample costs less than a traced sorted one in every view measured but the farthest (a whole big
    # scene a few dozen pixels wide, as blender_gui.viewport_rendered_showroom's F12 camera sees showroom_1.5M);
    # docs/benchmarks.md, Rendering, has the figures.
    camera_ray_splatting: BoolProperty(
        name="Camera Rays as Splats", default=True,
        description="Draw the splats that camera rays see as splat viewers draw them (each Gaussian's projected "
                    "footprint, in the order of centre depth), so an unedited scene looks exactly as in its viewer; "
                    "meshes, reflections, refraction and shadows are ray traced as before. Perspective cameras and "
                    "Baked splats only: with Lit or Baked + Shadows objects camera rays stay traced")
    meshes_shadow_gaussians: BoolProperty(
        name="Meshes Shadow Gaussians", default=False,
        description="Baked splats: darken Gaussians whose centres meshes hide from the lights (Baked + Shadows "
                    "shadows each point seen, by meshes and splats)")
    seed: IntProperty(name="Seed", default=0, min=0, description="Seed of the sampling pattern")
    # Cycles' name, default and text (Sampling > Advanced > Seed, the clock button beside it); the seed of a frame is
    # then sync.frame_seed's hash of the frame and this seed, as Cycles computes it.
    use_animated_seed: BoolProperty(
        name="Animate Seed", default=False,
        description="Use different seed values (and hence noise patterns) at different frames")
    # Cycles' defaults (Blackman-Harris, 1.5 px), so that renders compare with Cycles'; Box at 1 px is the plain
    # in-pixel jitter of RaySplats before filters.
    pixel_filter: EnumProperty(
        name="Pixel Filter", default="BLACKMAN_HARRIS",
        items=(("BOX", "Box", "Samples spread evenly over the filter width (1 px: the pixel's own square)"),
               ("GAUSSIAN", "Gaussian", "Gaussian weights, sigma = width / 4"),
               ("BLACKMAN_HARRIS", "Blackman-Harris", "Blackman-Harris window over twice the width (Cycles' "
                                                      "default): sharper than the Gaussian, few ringing artefacts")),
        description="How samples are spread around each pixel and weighted (Film > Pixel Filter)")
    filter_width: FloatProperty(
        name="Width", default=1.5, min=0.01, max=10.0, subtype="PIXEL",
        description="Width of the pixel filter, in pixels (smaller: sharper and more aliased)")


class RaySplatsCameraSettings(bpy.types.PropertyGroup):
    panorama_type: EnumProperty(
        name="Panorama Type", default="EQUIRECTANGULAR",
        items=(("EQUIRECTANGULAR", "Equirectangular", "Longitude/latitude projection"),
               ("FISHEYE_EQUIDISTANT", "Fisheye Equidistant", "Image radius proportional to the angle"),
               ("FISHEYE_EQUISOLID", "Fisheye Equisolid", "Real fisheye lens model")),
        description="Projection of a panoramic camera (Blender 4 has these on the camera itself)")
    fisheye_fov: FloatProperty(name="Field of View", default=math.pi, min=0.1, max=2 * math.pi, subtype="ANGLE")
    fisheye_lens: FloatProperty(name="Fisheye Lens", default=10.5, min=0.01, max=100.0, unit="CAMERA")
    latitude_min: FloatProperty(name="Min Latitude", default=-math.pi / 2, min=-math.pi / 2, max=math.pi / 2,
                                subtype="ANGLE")
    latitude_max: FloatProperty(name="Max Latitude", default=math.pi / 2, min=-math.pi / 2, max=math.pi / 2,
                                subtype="ANGLE")
    longitude_min: FloatProperty(name="Min Longitude", default=-math.pi, min=-math.pi, max=math.pi, subtype="ANGLE")
    longitude_max: FloatProperty(name="Max Longitude", default=math.pi, min=-math.pi, max=math.pi, subtype="ANGLE")


def register():
    bpy.utils.register_class(RaySplatsRenderSettings)
    bpy.utils.register_class(RaySplatsCameraSettings)
    bpy.types.Scene.raysplats = PointerProperty(type=RaySplatsRenderSettings)
    bpy.types.Camera.raysplats = PointerProperty(type=RaySplatsCameraSettings)


def unregister():
    del bpy.types.Camera.raysplats
    del bpy.types.Scene.raysplats
    bpy.utils.unregister_class(RaySplatsCameraSettings)
    bpy.utils.unregister_class(RaySplatsRenderSettings)
