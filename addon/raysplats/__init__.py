# RaySplats: editable, ray-traced 3D Gaussian Splatting scenes in Blender.
# The add-on is glue (docs/design.md §2): it moves Blender data in bulk to the native core (raysplats._native) and
# back. Packages by concept: blender/ (Blender access), objects/ (what a splat object is), io/ (files), tools/
# (operators), ui/ (panels), engine/ (the render engine); docs/architecture.md has a paragraph on each.

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

# The modules in dependency order (each after those it imports), so that "Reload Scripts" reloads them in place.
_MODULE_NAMES = (
    "native", "errors", "progress",
    "blender.compat", "blender.mesh_read", "blender.mesh_memory", "blender.material_reader", "blender.denoiser",
    "objects.axes", "objects.color_adjustment", "objects.object_settings", "objects.polygon_mesh",
    "objects.falloff_material", "objects.blender_splats", "objects.compact_points", "objects.modifier_checks",
    "objects.splat_object", "objects.creation",
    "io.format_table", "io.import_policy", "io.gltf_mesh_import", "io.export_scope",
    "blender.viewport_shading", "io.import_splats", "io.export_splats", "io.export_mesh",
    "tools.select_splats", "tools.upkeep", "tools.exact_apply", "tools.region_editing", "tools.convert_splats",
    "tools.handlers", "ui.panels",
    "engine.render_properties", "engine.color_management", "engine.material_table", "engine.passes", "engine.sync",
    "engine.final", "engine.viewport", "engine.ui", "engine",
)
# The modules with register()/unregister(), in registration order.
_REGISTERED_NAMES = ("objects.object_settings", "io.import_splats", "io.export_splats", "io.export_mesh",
                     "tools.convert_splats", "tools.region_editing", "tools.select_splats", "tools.upkeep",
                     "tools.exact_apply", "tools.handlers", "ui.panels", "engine")

import importlib  # noqa: E402
import sys  # noqa: E402

_reloading = f"{__name__}.engine" in sys.modules
_modules = {}
for _name in _MODULE_NAMES:
    _module = importlib.import_module(f".{_name}", __name__)
    _modules[_name] = importlib.reload(_module) if _reloading else _module


def register():
    # All or nothing: a module that fails to register (a clash with another add-on's names, a newer Blender's API)
    # takes back the modules registered before it, so Blender is left as it was and enabling again can work.
    registered = []
    try:
        for module in (_modules[name] for name in _REGISTERED_NAMES):
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
    for module in (_modules[name] for name in reversed(_REGISTERED_NAMES)):
        module.unregister()
