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
