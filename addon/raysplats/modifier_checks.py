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


def corner_only_apply_warnings(obj):
    """A message when Blender's own Apply Transform changed the object's Gaussians (splat_transform records it)."""
    from .splat_transform import CORNER_ONLY_APPLY_PROPERTY
    if not obj.get(CORNER_ONLY_APPLY_PROPERTY):
        return []
    return [f"'{obj.name}': Blender's Apply Transform moved only the splat polygons' corners (or the splat points' "
            "centres) under a non-uniform scale or shear, which changes the Gaussians' shapes; undo it and use Object "
            "> Apply (Ctrl+A) > Gaussian Splats (exact)"]


def fidelity_warnings(obj, for_render):
    """Everything that keeps a Gaussian object from rendering and exporting exactly as imported and edited."""
    return topology_warnings(obj, for_render) + corner_only_apply_warnings(obj)


def compact_warnings(obj, for_render):
    """One message per enabled modifier of a compact splat object (compact_splats.py): a modifier moves its points,
    the Gaussians' centres, and leaves their shapes and orientations as they are in the object, which a bend, a
    non-uniform scale or a shape key does not mean."""
    return [f"'{obj.name}': modifier '{modifier.name}' moves only the centres of its compact splats; their shapes "
            "and orientations stay as they are (to deform them, edit the region as polygons: Edit Selected as "
            "Polygons)"
            for modifier in getattr(obj, "modifiers", ())
            if (modifier.show_render if for_render else modifier.show_viewport)]


def export_warnings(objects, apply_modifiers):
    """fidelity_warnings() of the Gaussian objects among `objects` an export writes (modifiers only when applied)."""
    from .compact_splats import is_compact_object
    from .gaussian_mesh import is_gaussian_object
    messages = []
    for obj in objects:
        if is_gaussian_object(obj):
            messages += (topology_warnings(obj, for_render=False) if apply_modifiers else []) \
                + corner_only_apply_warnings(obj)
        elif is_compact_object(obj):
            messages += (compact_warnings(obj, for_render=False) if apply_modifiers else []) \
                + corner_only_apply_warnings(obj)
    return messages
