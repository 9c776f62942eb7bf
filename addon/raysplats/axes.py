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
)

# Import default: the core's format table (splat_formats()' up_axis), which is -Y for every format: the readers
# return COLMAP's convention (x right, y down, z forward), converting SPZ's RUB (x right, y up, z back) on reading.
# Which way is up is a property of the scene, not of its file format (DESIGN §4).
IMPORT_UP_AXIS_ITEMS = (("AUTO", "Automatic", "-Y (COLMAP), the convention of 3DGS scenes, for every format "
                                              "(.spz is converted from its RUB on reading)"),) + UP_AXIS_ITEMS


def resolve_import_up_axis(up_axis, splat_format):
    """`up_axis`, or for "AUTO" the up axis of `splat_format` (an entry of the core's splat_formats(); None for
    an unknown format, taken as the COLMAP convention of most scenes)."""
    if up_axis != "AUTO":
        return up_axis
    return splat_format["up_axis"] if splat_format else "-Y"


# file coordinates -> Blender coordinates, and the object's Euler X rotation that performs it.
_FILE_TO_BLENDER = {
    "-Y": (np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=np.float64), -math.pi / 2),
    "Y": (np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float64), math.pi / 2),
    "Z": (np.eye(3, dtype=np.float64), 0.0),
}


def object_rotation_x(up_axis):
    """Euler X angle the imported object gets so the file's up direction points along Blender's +Z."""
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
