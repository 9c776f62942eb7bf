# Settings stored on every imported Gaussian object; the render engine and the exporters read them.
import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from .axes import UP_AXIS_ITEMS


class RaySplatsObjectSettings(bpy.types.PropertyGroup):
    is_gaussian: BoolProperty(
        name="Gaussian Splats",
        description="This mesh holds one Gaussian per face; RaySplats renders and exports it as splats",
        default=False,
    )
    vertices_per_polygon: IntProperty(
        name="Polygon Vertices", description="K: vertices of the polygon each Gaussian was imported as",
        default=8, min=3, max=64,
    )
    radius: FloatProperty(
        name="Polygon Radius", description="rho: Mahalanobis radius of the polygons (3 = the 3-sigma ellipse)",
        default=3.0, min=0.1, max=10.0,
    )
    sh_degree: IntProperty(name="SH Degree", description="Spherical-harmonics degree of the colours",
                           default=0, min=0, max=3)
    source_file: StringProperty(name="Source File", description="The splat file this object was imported from",
                                subtype="FILE_PATH")
    up_axis: EnumProperty(name="File Up Axis", items=UP_AXIS_ITEMS, default="-Y",
                          description="Up direction of the source file, undone again on export")
    # Colour adjustments (color_adjustment.py): applied to the SH wherever Gaussians are rendered or exported, and to
    # the colour attribute the viewport shows (tools/handlers.py and the message bus: no update= callbacks here, which
    # make Blender 4.2 as a Python module crash at exit); the stored SH stay as imported.
    exposure: FloatProperty(name="Exposure", description="Brightness in stops (each +1 doubles the colours)",
                            default=0.0, soft_min=-4.0, soft_max=4.0)
    brightness: FloatProperty(name="Brightness", description="Added to the display colours", default=0.0,
                              soft_min=-1.0, soft_max=1.0)
    saturation: FloatProperty(name="Saturation", description="1 keeps the colours, 0 makes them grey", default=1.0,
                              min=0.0, soft_max=2.0)
    hue: FloatProperty(name="Hue", description="Rotation of the hues, in turns", default=0.0, soft_min=-0.5,
                       soft_max=0.5)
    temperature: FloatProperty(name="Temperature", description="Warmer (positive) or cooler (negative) colours",
                               default=0.0, min=-1.0, max=1.0)
    # How the RaySplats renderer produces this object's colours; SCENE follows Render Properties > Gaussians >
    # Shading (engine.sync passes None for it).
    gaussian_shading: EnumProperty(
        name="Shading", default="SCENE",
        items=(("SCENE", "Scene Default", "As Render Properties > Gaussians > Shading"),
               ("BAKED", "Baked", "The captured light, as trained: scene lights do not change it"),
               ("LIT", "Lit", "Each splat is a surface lit by the scene's lights and world, with shadows (its "
                              "colour, with the capture's light divided out, is its albedo)"),
               ("BAKED_SHADOWED", "Baked + Shadows", "The captured light, darkened where meshes and splats hide "
                                                     "the scene's lights")),
        description="How the RaySplats renderer colours this object's splats")


def register():
    bpy.utils.register_class(RaySplatsObjectSettings)
    bpy.types.Object.raysplats = PointerProperty(type=RaySplatsObjectSettings)


def unregister():
    del bpy.types.Object.raysplats
    bpy.utils.unregister_class(RaySplatsObjectSettings)
