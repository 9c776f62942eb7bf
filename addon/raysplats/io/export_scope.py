# Which objects an export writes: glTF's "Limit to" choice (io_scene_gltf2's Selected / Visible / Renderable /
# Active Collection) as one drop-down shared by the splat and the mesh exporters. Visible is the default: an export
# writes what the user sees, and an object the user hid is never exported unless asked for.

from ..objects import polygon_mesh

LIMIT_TO_ITEMS = (
    ("VISIBLE", "Visible Objects", "Objects visible in the viewport (hidden objects and excluded collections are "
                                   "left out)"),
    ("SELECTED", "Selected Objects", "Only the selected objects"),
    ("RENDERABLE", "Render-enabled Objects", "Objects that render (Disable in Renders off for the object and its "
                                             "collections), whether or not they are shown in the viewport"),
    ("ACTIVE_COLLECTION", "Active Collection", "The visible objects of the active collection and its children"),
)
DEFAULT_LIMIT_TO = "VISIBLE"


def _renders(obj, view_layer):
    """True when `obj` is in the view layer (not in an excluded collection) and neither it nor every collection
    holding it is disabled in renders."""
    if obj.hide_render or obj.name not in view_layer.objects:
        return False
    collections = obj.users_collection
    return not collections or any(not collection.hide_render for collection in collections)


def objects_in_scope(context, limit_to=DEFAULT_LIMIT_TO):
    """The scene objects an export limited to `limit_to` (an identifier of LIMIT_TO_ITEMS) writes, in scene order."""
    view_layer = context.view_layer
    if limit_to == "SELECTED":
        # A selected empty of a split scene (creation.add_gaussian_pieces) stands for its pieces.
        selected = list(context.selected_objects)
        chosen = set(selected)
        for obj in selected:
            if obj.type == "EMPTY":
                selected += [child for child in obj.children
                             if child not in chosen and polygon_mesh.is_gaussian_object(child)]
                chosen.update(obj.children)
        return selected
    if limit_to == "VISIBLE":
        return [obj for obj in view_layer.objects if obj.visible_get(view_layer=view_layer)]
    if limit_to == "RENDERABLE":
        return [obj for obj in context.scene.objects if _renders(obj, view_layer)]
    if limit_to == "ACTIVE_COLLECTION":
        members = set(view_layer.active_layer_collection.collection.all_objects)
        return [obj for obj in view_layer.objects if obj in members and obj.visible_get(view_layer=view_layer)]
    raise ValueError(f"unknown export limit '{limit_to}' (known: {', '.join(item[0] for item in LIMIT_TO_ITEMS)})")


def describe(limit_to):
    """The words for what `limit_to` leaves, in "Nothing to export: no Gaussian splat objects are <...>"."""
    return {"VISIBLE": "visible", "SELECTED": "selected", "RENDERABLE": "render-enabled",
            "ACTIVE_COLLECTION": "visible in the active collection"}.get(limit_to, limit_to)


def limit_of(limit_to, use_selection=False):
    """The Limit to of an export operator: `use_selection`, the keyword of scripts written before Limit to (and the
    stable interface, docs/reference.md), still means the selection."""
    return "SELECTED" if use_selection else limit_to
