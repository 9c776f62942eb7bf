# RaySplats: editable, ray-traced 3D Gaussian Splatting scenes in Blender.
# The add-on is glue (DESIGN §2): it moves Blender data in bulk to the native core (raysplats._native) and
# back. Module import order is fixed (utils -> properties -> io -> engine) so that "Reload Scripts" works.

bl_info = {
    "name": "RaySplats",
    "author": "RaySplats developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "File > Import/Export > Gaussian Splats; File > Export > RaySplats Mesh",
    "description": "Import, edit and export 3D Gaussian Splatting scenes as editable meshes",
    "category": "Import-Export",
}

if "bpy" in locals():
    import importlib

    for _module in (native, axes, progress, properties, gaussian_mesh, material, io_import, io_export,
                    io_mesh_export, engine):  # noqa: F821
        importlib.reload(_module)
else:
    from . import (native, axes, progress, properties, gaussian_mesh, material, io_import, io_export,
                   io_mesh_export, engine)

import bpy  # noqa: E402

_modules = (properties, io_import, io_export, io_mesh_export, engine)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
