# File > Export > Gaussian Splats (the formats the core writes): Gaussians recovered from the evaluated objects
# (modifiers, object transform and SH rotation applied), written atomically by the native core.
import os

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from .. import errors, native
from ..objects import axes, splat_object
from . import export_scope
from .format_table import (open_splat_file_browser, splat_extensions, splat_format_of, splat_formats, splat_menu_text,
                           with_splat_extension)
from ..progress import StageProgress


class NothingToExport(ValueError):
    pass


def gaussian_objects(context, limit_to=export_scope.DEFAULT_LIMIT_TO):
    """The splat objects in scope, of every kind (splat_object.py)."""
    return [obj for obj in export_scope.objects_in_scope(context, limit_to) if splat_object.is_splat_object(obj)]


def recover_scene_gaussians(context, objects, apply_modifiers=True, up_axis="AUTO"):
    """Gaussians of all given objects in the file convention (up_axis, or each object's own with "AUTO"),
    concatenated; SH padded to the highest degree. Returns (arrays dict, summed stats)."""
    depsgraph = context.evaluated_depsgraph_get()
    parts, stats = [], {}
    for obj in objects:
        axis = splat_object.up_axis_of(obj) if up_axis == "AUTO" else up_axis
        # (each object's own coordinates -> the file's)
        part = splat_object.gaussians_of(obj, depsgraph, axes.mesh_to_file(obj, axis), apply_modifiers)
        for key, value in part["stats"].items():
            stats[key] = stats.get(key, 0) + value
        parts.append(part)
    coeffs = max(part["sh"].shape[1] for part in parts)

    def padded(sh):
        if sh.shape[1] == coeffs:
            return sh
        out = np.zeros((sh.shape[0], coeffs, 3), dtype=np.float32)
        out[:, :sh.shape[1], :] = sh
        return out

    arrays = {key: np.concatenate([part[key] for part in parts]) if len(parts) > 1 else parts[0][key]
              for key in ("positions", "rotations", "scales", "opacities")}
    arrays["sh"] = np.concatenate([padded(part["sh"]) for part in parts]) if len(parts) > 1 else parts[0]["sh"]
    return arrays, stats


def export_gaussian_splats(context, filepath, limit_to=export_scope.DEFAULT_LIMIT_TO, apply_modifiers=True,
                           up_axis="AUTO"):
    """Writes the Gaussian objects export_scope.objects_in_scope(limit_to) gives to a splat file, format from the
    extension.
    Returns (number of Gaussians written, recovery stats and "warnings" (messages), stage timings)."""
    extension = os.path.splitext(filepath)[1].lower()
    splat_format = splat_format_of(filepath)
    if splat_format is None or not splat_format.get("writable", True):
        known = ", ".join(splat_extensions(writable_only=True))
        if splat_format is not None and splat_format["name"] == "gltf":  # the mesh export writes glTF splats
            raise ValueError(f"'{filepath}': {extension} splats are written by File > Export > RaySplats Mesh with "
                             f"KHR_gaussian_splatting; this export writes {known}")
        what = f"{splat_format['name'].upper()} is read only" if splat_format else f"unknown splat format '{extension}'"
        raise ValueError(f"'{filepath}': {what}; use {known}")
    objects = gaussian_objects(context, limit_to)
    if not objects:
        raise NothingToExport(f"Nothing to export: no Gaussian splat objects are {export_scope.describe(limit_to)}")
    core = native.core()
    with StageProgress(getattr(context, "window_manager", None), "RaySplats export", 2) as progress:
        progress.stage("recover Gaussians")
        arrays, stats = recover_scene_gaussians(context, objects, apply_modifiers, up_axis)
        progress.stage("write file")
        core.write_splats(filepath, arrays["positions"], arrays["rotations"], arrays["scales"],
                          arrays["opacities"], arrays["sh"])
    print(progress.summary())
    stats["warnings"] = splat_object.export_warnings(objects, apply_modifiers)
    return len(arrays["opacities"]), stats, progress.times


_format_items = []  # Blender needs the strings of dynamic enum items kept alive by Python


def splat_format_items(self, context):
    """The Format drop-down: one entry per format the core writes, labelled with its extension."""
    try:
        formats = splat_formats(writable_only=True)
    except native.NativeModuleMissing:
        formats = []
    _format_items[:] = [(f["name"].upper(), f"{f['name'].upper()} ({f['extensions'][0]})", f["description"])
                        for f in formats] or [("PLY", "PLY (.ply)", "3DGS .ply")]
    return _format_items


def format_extension(format_name):
    """The extension the core writes for a Format drop-down entry."""
    return next(f["extensions"][0] for f in splat_formats(writable_only=True) if f["name"].upper() == format_name)


class EXPORT_SCENE_OT_gaussian_splats(bpy.types.Operator, ExportHelper):
    """Export Gaussian splat objects, with every edit applied, to a splat file (the formats of the Format drop-down)"""

    bl_idname = "export_scene.gaussian_splats"
    bl_label = "Export Gaussian Splats"
    bl_options = {"REGISTER", "PRESET"}

    filename_ext = ".ply"
    check_extension = None  # every splat extension is accepted; the extension picks the format
    filter_glob: StringProperty(default="", options={"HIDDEN"})  # set from the core's formats in invoke()

    limit_to: EnumProperty(name="Limit to", items=export_scope.LIMIT_TO_ITEMS, default=export_scope.DEFAULT_LIMIT_TO,
                           description="Which Gaussian objects are exported")
    use_selection: BoolProperty(name="Selected Only", default=False, options={"HIDDEN"},
                                description="Kept for scripts written before Limit to: True exports the selection")
    export_format: EnumProperty(name="Format", items=splat_format_items,
                                description="File format; the file name's extension follows it")
    apply_modifiers: BoolProperty(name="Apply Modifiers", default=True,
                                  description="Export the Gaussians as modifiers, shape keys and armatures leave them")
    up_axis: EnumProperty(
        name="Up Axis", default="AUTO",
        items=(("AUTO", "As Imported", "Undo the conversion each object was imported with"),) + axes.UP_AXIS_ITEMS,
        description="Up direction the written file uses")

    def invoke(self, context, event):
        current = splat_format_of(self.filepath) if self.filepath else None
        if current is not None and current.get("writable", True):
            self.export_format = current["name"].upper()
        return open_splat_file_browser(self, ExportHelper, context, event, writable_only=True)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        for name in ("export_format", "limit_to", "apply_modifiers", "up_axis"):
            layout.prop(self, name)
        if self.export_format == "SPLAT":
            # The format's own limit, said where it is chosen rather than discovered in a viewer.
            layout.label(text=".splat keeps no view-dependent colour (SH bands)", icon="INFO")
        elif self.export_format == "COMPRESSED_PLY":
            layout.label(text="Quantised: 11-bit positions per 256 splats,", icon="INFO")
            layout.label(text="8-bit colour, opacity and SH bands")

    def check(self, context):
        # The extension follows the Format drop-down; True redraws the file browser.
        filepath = with_splat_extension(self.filepath, format_extension(self.export_format))
        changed = filepath != self.filepath
        self.filepath = filepath
        return changed

    @errors.reports_failures("Export failed: ")
    def execute(self, context):
        count, stats, _ = export_gaussian_splats(
            context, self.filepath, export_scope.limit_of(self.limit_to, self.use_selection), self.apply_modifiers,
            self.up_axis)
        for warning in stats["warnings"]:
            self.report({"WARNING"}, warning)
        if stats.get("degenerate"):
            self.report({"WARNING"}, f"{stats['degenerate']} degenerate polygons (collinear or collapsed vertices) "
                                     "were exported with clamped scales")
        if stats.get("invalid_rest_rotation"):
            self.report({"WARNING"}, f"{stats['invalid_rest_rotation']} polygons had a stored rotation that is not a "
                                     "rotation (NaN or zero): their Gaussians were recovered from the polygon shape")
        if stats.get("invalid_rest_scale"):
            self.report({"WARNING"}, f"{stats['invalid_rest_scale']} polygons had a stored scale that is not a scale "
                                     "(negative, NaN or infinite): their Gaussians were recovered from the polygon shape")
        if stats.get("dropped"):
            self.report({"WARNING"}, f"{stats['dropped']} polygons with invalid vertices or a Gaussian beyond float "
                                     "range were not exported")
        self.report({"INFO"}, f"Exported {count:,} Gaussians to {os.path.basename(self.filepath)}")
        return {"FINISHED"}


def menu_export(self, context):
    self.layout.operator(EXPORT_SCENE_OT_gaussian_splats.bl_idname, text=splat_menu_text(writable_only=True))


def register():
    bpy.utils.register_class(EXPORT_SCENE_OT_gaussian_splats)
    bpy.types.TOPBAR_MT_file_export.append(menu_export)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(menu_export)
    bpy.utils.unregister_class(EXPORT_SCENE_OT_gaussian_splats)
