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


def register():
    bpy.utils.register_class(RaySplatsObjectSettings)
    bpy.types.Object.raysplats = PointerProperty(type=RaySplatsObjectSettings)


def unregister():
    del bpy.types.Object.raysplats
    bpy.utils.unregister_class(RaySplatsObjectSettings)
