# Axis conventions of splat files and their exact conversion to Blender's Z-up world.
# Rotation matrices are written out with exact 0/±1 entries (Blender's own matrices are float32), so that an
# untouched scene exports the same Gaussians it imported.
import math

import numpy as np

UP_AXIS_ITEMS = (
    ("-Y", "-Y up (COLMAP/OpenCV)",
     "The file's up direction is -Y, as in scenes trained from COLMAP reconstructions (most 3DGS scenes)"),
    ("Y", "Y up (OpenGL)", "The file's up direction is +Y"),
    ("Z", "Z up (Blender)", "The file is already Z up: no conversion"),
    ("-Z", "-Z up", "The file's up direction is -Z"),
    ("X", "X up", "The file's up direction is +X"),
    ("-X", "-X up", "The file's up direction is -X"),
)

# Import choices besides the explicit axes:
# - DETECT (the default): the scene's own up, found by the core from its Gaussians (raysplats/up_axis.h: the
#   supporting plane, ground or floor or table, drawn by flat Gaussians). Which way is up is a property of the scene,
#   not of its file format (docs/design.md §4): of the real test scenes, a drone-style interior and an object made in
#   Blender are Z up although their files follow COLMAP's -Y habit, and imported on their side with the format's
#   convention.
#   Where the data shows no clear supporting plane, the format's convention is kept; formats whose specification
#   fixes up (glTF: +Y) are taken at their word.
# - AUTO: the format's convention, from the core's format table (splat_formats()' up_axis): -Y for every format, as
#   the readers return COLMAP's convention (x right, y down, z forward), converting SPZ's RUB and glTF's +Y up.
IMPORT_UP_AXIS_ITEMS = (
    ("DETECT", "Automatic (from the data)",
     "Find which way is up from the Gaussians (the ground, floor or table under the scene); where the data shows no "
     "clear ground, and for glTF (+Y up by specification), the format's convention"),
    ("AUTO", "Format Convention", "-Y (COLMAP), the convention of 3DGS scenes, for every format (.spz and glTF are "
                                  "converted from their own axes on reading)"),
) + UP_AXIS_ITEMS


def resolve_import_up_axis(up_axis, splat_format, estimate=None):
    """`up_axis`; for "AUTO" the up axis of `splat_format` (an entry of the core's splat_formats(); None for an
    unknown format, taken as the COLMAP convention of most scenes); for "DETECT" the decided axis of `estimate` (the
    core's estimate_up_axis() of the scene, or None) unless the format's specification fixes up, else as "AUTO"."""
    if up_axis not in ("AUTO", "DETECT"):
        return up_axis
    convention = splat_format["up_axis"] if splat_format else "-Y"
    if up_axis == "DETECT" and estimate is not None and estimate["decided"] and not (
            splat_format and splat_format.get("up_axis_by_specification")):
        return estimate["axis"]
    return convention


def detection_wanted(up_axis, splat_format):
    """Whether resolve_import_up_axis() would use an estimate (so it is worth computing)."""
    return up_axis == "DETECT" and not (splat_format and splat_format.get("up_axis_by_specification"))


# file coordinates -> Blender coordinates (a rotation taking the file's up to +Z), and the object's Euler XYZ
# rotation that performs it.
_FILE_TO_BLENDER = {
    "-Y": (np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=np.float64), (-math.pi / 2, 0.0, 0.0)),
    "Y": (np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float64), (math.pi / 2, 0.0, 0.0)),
    "Z": (np.eye(3, dtype=np.float64), (0.0, 0.0, 0.0)),
    "-Z": (np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=np.float64), (math.pi, 0.0, 0.0)),
    "X": (np.array([[0, 0, -1], [0, 1, 0], [1, 0, 0]], dtype=np.float64), (0.0, -math.pi / 2, 0.0)),
    "-X": (np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=np.float64), (0.0, math.pi / 2, 0.0)),
}


def object_rotation_euler(up_axis):
    """Euler XYZ angles the imported object gets so the file's up direction points along Blender's +Z."""
    return _FILE_TO_BLENDER[up_axis][1]


def blender_to_file(up_axis):
    """4x4 (float64) map from Blender world coordinates back to the file's convention."""
    m = np.eye(4, dtype=np.float64)
    m[:3, :3] = _FILE_TO_BLENDER[up_axis][0].T  # rotation: inverse = transpose
    return m


def world_matrix(obj):
    """The object's world matrix as float64 4x4."""
    return np.array(obj.matrix_world, dtype=np.float64)


def mesh_to_file(obj, up_axis):
    """Map from the object's mesh coordinates to the file's convention: blender_to_file(up_axis) @ world.

    Blender keeps matrices in float32, so a -90° import rotation carries cos(-π/2) ≈ -4.4e-8 terms; composed
    with the exact inverse conversion they leave entries far below float32 resolution, which would move
    every Gaussian of an untouched scene by ~1e-7 of its distance from the origin. Entries smaller than
    float32 epsilon times the matrix's scale are below what the stored matrix can express, so they are
    snapped to zero; the untouched scene then maps by the exact identity."""
    m = blender_to_file(up_axis) @ world_matrix(obj)
    linear = m[:3, :3]
    linear[np.abs(linear) < np.finfo(np.float32).eps * np.abs(linear).max()] = 0.0
    return m
