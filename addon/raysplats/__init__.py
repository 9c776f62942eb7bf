# RaySplats: editable, ray-traced 3D Gaussian Splatting scenes in Blender.
# The add-on is glue (docs/design.md §2): it moves Blender data in bulk to the native core (raysplats._native) and
# back. Module import order is fixed (utils -> properties -> io -> engine) so that "Reload Scripts" works.

bl_info = {
    "name": "RaySplats",
    "author": "RaySplats developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "File > Import/Export > Gaussian Splats; Add > Gaussian Splats; Object Properties and 3D View "
                "sidebar > Splats; File > Export > RaySplats Mesh; Object > Convert",
    "description": "Import, edit and export 3D Gaussian Splatting scenes as editable meshes",
    "category": "Import-Export",
}

if "bpy" in locals():
    import importlib

    for _module in (native, blender_compat, errors, axes, progress, color_adjustment, properties,  # noqa: F821
                    mesh_fast_read, gaussian_mesh, material, material_reader, export_scope, modifier_checks,
                    io_import, native_splats, compact_splats, io_export, io_mesh_export, splat_selection, splat_tools,
                    splat_transform, splat_handlers, splat_ui, engine):  # noqa: F821
        importlib.reload(_module)
else:
    from . import (native, blender_compat, errors, axes, progress, color_adjustment, properties, mesh_fast_read,
                   gaussian_mesh, material, material_reader, export_scope, modifier_checks, io_import, native_splats,
                   compact_splats, io_export, io_mesh_export, splat_selection, splat_tools, splat_transform,
                   splat_handlers, splat_ui, engine)

import bpy  # noqa: E402

_modules = (properties, io_import, io_export, io_mesh_export, native_splats, compact_splats, splat_selection,
            splat_tools, splat_transform, splat_handlers, splat_ui, engine)


def register():
    # All or nothing: a module that fails to register (a clash with another add-on's names, a newer Blender's API)
    # takes back the modules registered before it, so Blender is left as it was and enabling again can work.
    registered = []
    try:
        for module in _modules:
            module.register()
            registered.append(module)
    except BaseException:
        for module in reversed(registered):
            try:
                module.unregister()
            except Exception as error:  # the first failure is the one to report
                print(f"RaySplats: while undoing a failed registration, {module.__name__}: {error}")
        raise


def unregister():
    for module in reversed(_modules):
        module.unregister()
