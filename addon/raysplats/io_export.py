# File > Export > Gaussian Splats (.ply/.splat/.spz): Gaussians recovered from the evaluated objects
# (modifiers, object transform and SH rotation applied), written atomically by the native core.
import os

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from . import axes, gaussian_mesh, native
from .io_import import SPLAT_EXTENSIONS
from .progress import StageProgress


class NothingToExport(ValueError):
    pass


def gaussian_objects(context, use_selection):
    objects = context.selected_objects if use_selection else context.scene.objects
    return [obj for obj in objects if gaussian_mesh.is_gaussian_object(obj)]


def recover_scene_gaussians(context, objects, apply_modifiers=True, up_axis="AUTO"):
    """Gaussians of all given objects in the file convention (up_axis, or each object's own with "AUTO"),
    concatenated; SH padded to the highest degree. Returns (arrays dict, summed stats)."""
    core = native.core()
    depsgraph = context.evaluated_depsgraph_get()
    parts, stats = [], {}
    for obj in objects:
        axis = obj.raysplats.up_axis if up_axis == "AUTO" else up_axis
        mesh_to_output = axes.mesh_to_file(obj, axis)
        part = gaussian_mesh.recover_object_gaussians(core, obj, depsgraph, mesh_to_output, apply_modifiers)
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


def export_gaussian_splats(context, filepath, use_selection=False, apply_modifiers=True, up_axis="AUTO"):
    """Writes the scene's (or the selected) Gaussian objects to a splat file, format from the extension.
    Returns (number of Gaussians written, recovery stats, stage timings)."""
    extension = os.path.splitext(filepath)[1].lower()
    if extension not in SPLAT_EXTENSIONS:
        raise ValueError(f"'{filepath}': unknown splat format '{extension}'; use .ply, .splat or .spz")
    objects = gaussian_objects(context, use_selection)
    if not objects:
        raise NothingToExport("Nothing to export: no Gaussian splat objects" + (" selected" if use_selection else ""))
    core = native.core()
    with StageProgress(getattr(context, "window_manager", None), "RaySplats export", 2) as progress:
        progress.stage("recover Gaussians")
        arrays, stats = recover_scene_gaussians(context, objects, apply_modifiers, up_axis)
        progress.stage("write file")
        core.write_splats(filepath, arrays["positions"], arrays["rotations"], arrays["scales"],
                          arrays["opacities"], arrays["sh"])
    print(progress.summary())
    return len(arrays["opacities"]), stats, progress.times


class EXPORT_SCENE_OT_gaussian_splats(bpy.types.Operator, ExportHelper):
    """Export Gaussian splat objects, with every edit applied, to a 3DGS .ply, .splat or .spz file"""

    bl_idname = "export_scene.gaussian_splats"
    bl_label = "Export Gaussian Splats"
    bl_options = {"REGISTER", "PRESET"}

    filename_ext = ".ply"
    check_extension = None  # .ply, .splat and .spz are all accepted; the extension picks the format
    filter_glob: StringProperty(default="*.ply;*.splat;*.spz", options={"HIDDEN"})

    use_selection: BoolProperty(name="Selected Only", default=False,
                                description="Export only the selected Gaussian objects")
    apply_modifiers: BoolProperty(name="Apply Modifiers", default=True,
                                  description="Export the Gaussians as modifiers, shape keys and armatures leave them")
    up_axis: EnumProperty(
        name="Up Axis", default="AUTO",
        items=(("AUTO", "As Imported", "Undo the conversion each object was imported with"),) + axes.UP_AXIS_ITEMS,
        description="Up direction the written file uses")

    def execute(self, context):
        try:
            count, stats, _ = export_gaussian_splats(
                context, self.filepath, self.use_selection, self.apply_modifiers, self.up_axis)
        except (native.NativeModuleMissing, RuntimeError, ValueError, OSError) as error:
            self.report({"ERROR"}, f"Export failed: {error}")
            return {"CANCELLED"}
        if stats.get("degenerate"):
            self.report({"WARNING"}, f"{stats['degenerate']} degenerate polygons (collinear or collapsed vertices) "
                                     "were exported with clamped scales")
        if stats.get("dropped"):
            self.report({"WARNING"}, f"{stats['dropped']} polygons with invalid vertices were not exported")
        self.report({"INFO"}, f"Exported {count:,} Gaussians to {os.path.basename(self.filepath)}")
        return {"FINISHED"}


def menu_export(self, context):
    self.layout.operator(EXPORT_SCENE_OT_gaussian_splats.bl_idname, text="Gaussian Splats (.ply/.splat/.spz)")


def register():
    bpy.utils.register_class(EXPORT_SCENE_OT_gaussian_splats)
    bpy.types.TOPBAR_MT_file_export.append(menu_export)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(menu_export)
    bpy.utils.unregister_class(EXPORT_SCENE_OT_gaussian_splats)
