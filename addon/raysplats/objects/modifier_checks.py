# Modifiers that a Gaussian object's polygons do not survive exactly. The polygon bridge (docs/design.md §5) is exact
# under any affine map and any deformation that moves a face's corners together (armature, lattice, mirror, array), but
# a modifier that changes the faces themselves (re-meshing, subdividing, merging, splitting) hands recovery polygons
# that were never splats: their Gaussians are re-fitted from distorted shapes. That is sometimes wanted, never silent:
# the render and the exporters report it once per modifier, by name.

# Blender modifier types (Modifier.type) that change a mesh's faces rather than move its corners.
TOPOLOGY_CHANGING_MODIFIERS = {
    "DECIMATE", "REMESH", "SUBSURF", "MULTIRES", "TRIANGULATE", "WELD", "BEVEL", "SOLIDIFY", "WIREFRAME", "SKIN",
    "SCREW", "BOOLEAN", "EXPLODE",
    "NODES",  # geometry nodes may do anything to the faces
}


def topology_warnings(obj, for_render):
    """One message per enabled topology-changing modifier of a Gaussian object: enabled in renders (for_render) or in
    the viewport (interactive views and exports, which read the viewport's evaluation)."""
    messages = []
    for modifier in getattr(obj, "modifiers", ()):
        enabled = modifier.show_render if for_render else modifier.show_viewport
        if enabled and modifier.type in TOPOLOGY_CHANGING_MODIFIERS:
            messages.append(f"'{obj.name}': modifier '{modifier.name}' ({modifier.type.replace('_', ' ').title()}) "
                            "changes the splat polygons' topology; their Gaussians are re-fitted from the new "
                            "polygons, not kept")
    return messages


# Blender's own Apply Transform (object.transform_apply) moves only a splat object's polygon corners (or points'
# centres): exact for rotations and uniform scales, but a non-uniform scale or a shear changes the Gaussians' thickness
# (median x1.53 for a (1, 2, 1) scale on a real scene). It cannot be replaced for scripts, so where it happened
# tools/exact_apply.py records it on the object in this property, and the render and export reports name it.
CORNER_ONLY_APPLY_PROPERTY = "raysplats_corner_only_apply"


def corner_only_apply_warnings(obj):
    """A message when Blender's own Apply Transform changed the object's Gaussians (CORNER_ONLY_APPLY_PROPERTY)."""
    if not obj.get(CORNER_ONLY_APPLY_PROPERTY):
        return []
    return [f"'{obj.name}': Blender's Apply Transform moved only the splat polygons' corners (or the splat points' "
            "centres) under a non-uniform scale or shear, which changes the Gaussians' shapes; undo it and use Object "
            "> Apply (Ctrl+A) > Gaussian Splats (exact)"]


def compact_warnings(obj, for_render):
    """One message per enabled modifier of a compact splat object (objects/compact_points.py): a modifier moves its
    points, the Gaussians' centres, and leaves their shapes and orientations as they are in the object, which a bend,
    a non-uniform scale or a shape key does not mean."""
    return [f"'{obj.name}': modifier '{modifier.name}' moves only the centres of its compact splats; their shapes "
            "and orientations stay as they are (to deform them, edit the region as polygons: Edit Selected as "
            "Polygons)"
            for modifier in getattr(obj, "modifiers", ())
            if (modifier.show_render if for_render else modifier.show_viewport)]
