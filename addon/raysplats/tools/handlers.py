# What runs when Blender's data changes, for splat objects: after every depsgraph update, a joined mesh that
# is mostly splats becomes a splat object again, changed colour adjustments reach the viewport's colour attribute,
# and Blender's own Apply Transform is noticed; after a file is loaded, the message-bus subscriptions are renewed.
import bpy
from bpy.app.handlers import persistent

from . import exact_apply, upkeep


@persistent
def on_depsgraph_update(scene, depsgraph):
    """depsgraph_update_post: claim_joined_splats for unmarked meshes, show_color_adjustments and
    notice_corner_only_apply for the updated objects."""
    updates = [(update.id.original, update.is_updated_geometry) for update in depsgraph.updates
               if isinstance(update.id, bpy.types.Object)]
    if updates:
        objects = [obj for obj, _ in updates]
        upkeep.claim_joined_splats([obj for obj in objects
                                         if obj.type == "MESH" and not obj.raysplats.is_gaussian])
        upkeep.show_color_adjustments(objects)
        exact_apply.notice_corner_only_apply(objects, {obj.as_pointer() for obj, geometry in updates if geometry})


@persistent
def after_load(*args):
    """load_post: what was remembered about the previous file's objects is forgotten, the subscriptions renewed."""
    exact_apply.forget_placements()
    upkeep.forget_objects()
    upkeep.subscribe_to_adjustments()


HANDLERS = ((bpy.app.handlers.depsgraph_update_post, on_depsgraph_update), (bpy.app.handlers.load_post, after_load))


def register():
    for handlers, handler in HANDLERS:
        handlers.append(handler)


def unregister():
    for handlers, handler in HANDLERS:
        if handler in handlers:
            handlers.remove(handler)
