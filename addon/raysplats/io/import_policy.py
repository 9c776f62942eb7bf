# The import policy: how a scene is held in Blender (polygons, pieces or compact points) and whether the machine has
# the memory for it, decided from the file's header before anything is read.
from ..blender import compat
from ..objects.creation import auto_vertices_per_polygon



class NotEnoughMemory(OSError):
    """The machine has too little memory for an import (a user-facing condition, not a bug: reported as such)."""


def memory_size_text(n):
    """Bytes for a message: "3.2 GB", or "650 MB" below a gigabyte."""
    return f"{n / 1e9:.1f} GB" if n >= 1e9 else f"{n / 1e6:.0f} MB"


# Import representations (objects/compact_points.py): AUTO picks polygons for scenes they suit, compact points beyond.
# Where compact points are Blender's own Gaussian-splat point cloud (5.3 on), they are called by its name.
POINTS_NAME = "Blender Gaussian Splats" if compat.SPLATS_AS_POINT_CLOUD else "Compact Points"
REPRESENTATION_ITEMS = (
    ("AUTO", "Automatic", "Editable polygons up to 3 million Gaussians when the memory allows them, compact points "
                          "beyond"),
    ("POLYGONS", "Editable Polygons", "One polygon per Gaussian, editable with every Blender tool (about 350-620 "
                                      "bytes per Gaussian as quadrilaterals, Auto's choice above a million, about "
                                      "twice that as octagons, and several KB in Edit Mode)"),
    ("POINTS", POINTS_NAME, "One point per Gaussian (about 60 bytes each, more with SH): renders, transforms and "
                            "exports exactly; edit a region as polygons with Edit Selected as Polygons"),
)
# Above this many Gaussians AUTO imports compact points: Blender's Edit Mode costs about 5 KB per polygon Gaussian
# (docs/benchmarks.md, Import), so bigger scenes are edited a region at a time.
AUTO_POLYGON_LIMIT = 3_000_000


# Objects "Auto": a scene whose polygons have more than AUTO_SINGLE_OBJECT_VERTICES vertices is split into spatially
# compact pieces of at most AUTO_PIECE_VERTICES vertices, one object each, under one empty, so that edits run at
# interactive speed. In Rendered view and Material Preview Blender re-evaluates an edited object whole after each
# edit: it converts the edit mesh to a mesh to add the original coordinates those shadings request
# (DerivedMesh.cc, editbmesh_calc_modifiers: "avoid the need to convert to mesh data just to add an orco layer"),
# twice per edit, in time proportional to the object's vertices (blender_tests/gui/viewport_rendered.py prints an
# edit's time; docs/benchmarks.md, Editing big scenes, has the figures). biker_v4.spz (152 k octagons, 1.2 M
# vertices) stays one object.
AUTO_SINGLE_OBJECT_VERTICES = 1_500_000
AUTO_PIECE_VERTICES = 400_000

OBJECTS_ITEMS = (
    ("AUTO", "Automatic", "One object while the polygons have at most 1.5 million vertices (biker_v4: 152 k "
                          "octagons), spatial pieces of 400 thousand vertices above, under one empty"),
    ("ONE", "One Object", "Always one object (editing a few splats of a big scene then updates the whole object: "
                          "seconds per edit in Rendered view)"),
    ("PIECES", "Pieces", "Spatially compact pieces of at most Piece Size Gaussians, one object each, under one empty "
                         "that carries the scene's transform"),
)


def gaussians_per_piece(objects, count, vertices_per_polygon, piece_size=0):
    """How many Gaussians each object of an import of `count` Gaussians at K = `vertices_per_polygon` holds at most:
    `count` for one object (objects "ONE", or "AUTO" up to AUTO_SINGLE_OBJECT_VERTICES), else `piece_size` ("PIECES"
    with piece_size > 0) or AUTO_PIECE_VERTICES / K."""
    if objects not in {item[0] for item in OBJECTS_ITEMS}:
        raise ValueError(f"unknown Objects choice '{objects}' (known: {', '.join(i[0] for i in OBJECTS_ITEMS)})")
    if objects == "ONE" or (objects == "AUTO" and count * vertices_per_polygon <= AUTO_SINGLE_OBJECT_VERTICES):
        return max(count, 1)
    if objects == "PIECES" and piece_size > 0:
        return piece_size
    return max(1, AUTO_PIECE_VERTICES // vertices_per_polygon)


def resolve_vertices_per_polygon(core, filepath, vertices_per_polygon, max_count=0):
    """`vertices_per_polygon`, or for 0 (Auto) auto_vertices_per_polygon() of the Gaussians the file declares (at most
    max_count), read from its header."""
    if vertices_per_polygon in (1, 2) or vertices_per_polygon < 0:
        raise ValueError(f"Polygon Vertices {vertices_per_polygon}: a polygon needs at least 3 (0: Auto)")
    if vertices_per_polygon > 0:
        return vertices_per_polygon
    count = core.probe_splat_file(filepath)["count"]
    return auto_vertices_per_polygon(min(count, max_count) if max_count > 0 else count)


def _not_enough(filepath, count, needed, available, advice):
    return NotEnoughMemory(f"'{filepath}': not enough memory to import {count:,} Gaussians (needs about "
                           f"{memory_size_text(needed)}, {memory_size_text(available)} available); {advice}")


def check_import_memory(core, filepath, vertices_per_polygon, max_count=0, representation="POLYGONS"):
    """Which representation the import uses ("POLYGONS" or "POINTS"; AUTO resolved) and its memory estimate in bytes,
    from the file's header alone. Raises NotEnoughMemory, before anything is read or allocated, when the Gaussians
    the file declares (at most max_count of them) need more memory than the machine has available; AUTO falls back
    to compact points when polygons would not fit. Returns (representation, bytes, note for the user or None)."""
    summary = core.probe_splat_file(filepath)
    count = min(summary["count"], max_count) if max_count > 0 else summary["count"]
    polygons = core.import_memory_bytes(count, summary["sh_degree"], vertices_per_polygon)
    points = core.compact_import_memory_bytes(count, summary["sh_degree"])
    available = core.available_memory_bytes() or float("inf")
    limit = "set Maximum Count or Minimum Opacity to import fewer"
    if representation == "POINTS":
        if points > available:
            raise _not_enough(filepath, count, points, available, limit)
        return "POINTS", points, None
    if representation == "AUTO" and (count > AUTO_POLYGON_LIMIT or polygons > available):
        if points > available:
            raise _not_enough(filepath, count, points, available, limit)
        why = (f"as polygons they would need about {memory_size_text(polygons)} "
               f"({memory_size_text(available)} available)" if polygons > available
               else f"more than {AUTO_POLYGON_LIMIT:,} Gaussians are edited a region at a time")
        return "POINTS", points, (f"imported as {POINTS_NAME.lower()} ({why}); select a region in Edit Mode and use "
                                  "Edit Selected as Polygons to edit it")
    if polygons > available:
        raise _not_enough(filepath, count, polygons, available,
                          f"{limit}, use fewer Polygon Vertices, or import as {POINTS_NAME} (about "
                          f"{memory_size_text(points)})")
    return "POLYGONS", polygons, None
