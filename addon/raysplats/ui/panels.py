# Where a splat object's settings and tools are shown: the Object Properties panel "Gaussian Splats"
# (Object.raysplats), the 3D view's sidebar tab "Splats", and the entries in Edit Mode's Select and Mesh menus and in
# Object > Apply (and Ctrl+A). The tools themselves are in select_splats.py, upkeep.py and exact_apply.py.
import bpy

from ..io import import_policy
from ..objects import polygon_mesh, splat_object
from ..tools import exact_apply, region_editing, select_splats, upkeep

SIDEBAR_CATEGORY = "Splats"


def _draw_compact_settings(layout, obj):
    """A compact splat object (one point per Gaussian): what it is, and the way to edit a region of it."""
    column = layout.column()
    column.label(text=f"{splat_object.shown_count(obj):,} Gaussians as {import_policy.POINTS_NAME.lower()}")
    column.label(text=f"Up axis in the file: {splat_object.up_axis_of(obj)}")
    layout.operator(region_editing.OBJECT_OT_raysplats_edit_region.bl_idname, icon="MESH_DATA")
    # A region's Gaussians are out of the compact object (not rendered, not exported) until merged back; a region
    # deleted without merging keeps them out until restored.
    # (Short lines: the sidebar is narrow, and a long label is cut in its middle.)
    regions = region_editing.open_regions(obj)
    if regions:
        layout.label(text="Out in regions:")  # (their Gaussians render and export from there)
    for region_id, name in regions.items():
        region = region_editing.region_object(obj, region_id)
        if region is not None:
            layout.label(text=region.name, icon="MESH_DATA")
        else:
            layout.label(text=f"{name} (deleted)", icon="ERROR")
    if region_editing.orphaned_regions(obj):
        layout.operator(region_editing.OBJECT_OT_raysplats_restore_regions.bl_idname, icon="LOOP_BACK")
    if obj.mode != "EDIT":
        layout.label(text="Select a region's points in Edit Mode first", icon="INFO")


def _draw_settings(layout, obj):
    settings = obj.raysplats
    layout.use_property_split = True
    layout.use_property_decorate = False
    if splat_object.kind_of(obj) == splat_object.POINTS:
        _draw_compact_settings(layout, obj)
        return
    if not settings.is_gaussian:
        # Marking reads K, rho and the SH degree back from the splat data, which a bare check box would not.
        if obj.type == "MESH" and obj.data.attributes.get(polygon_mesh.ATTR_REST_SCALE) is not None:
            layout.label(text="This mesh carries splat data", icon="INFO")
            layout.operator(upkeep.OBJECT_OT_raysplats_mark_splats.bl_idname)
        else:
            layout.label(text="Not a Gaussian splat object")
        return
    layout.prop(settings, "is_gaussian", text="Gaussian Splats")
    column = layout.column()
    column.label(text=f"{len(obj.data.polygons):,} Gaussians")
    pieces = polygon_mesh.scene_pieces(obj.parent)
    if obj in pieces:  # a piece of a split import (creation.add_gaussian_pieces)
        total = sum(len(piece.data.polygons) for piece in pieces)
        # (Short: the sidebar and the properties editor are narrow; the scene's empty is the parent in the outliner.)
        column.label(text=f"Piece {pieces.index(obj) + 1} of {len(pieces)}, {total:,} in all")
    # K and rho are what the polygons were built with: changing them would re-read every polygon wrongly, so they
    # are shown, not edited.
    column = layout.column()
    column.enabled = False
    column.prop(settings, "vertices_per_polygon")
    column.prop(settings, "radius")
    column.prop(settings, "sh_degree")
    layout.prop(settings, "source_file")
    layout.prop(settings, "up_axis")
    layout.prop(settings, "gaussian_shading")
    target = region_editing.region_target(obj)
    if target is not None:
        layout.operator(region_editing.OBJECT_OT_raysplats_merge_region.bl_idname,
                        text=f"Merge Back into '{target.name}'", icon="POINTCLOUD_DATA")


def _draw_colors(layout, obj):
    settings = obj.raysplats
    layout.use_property_split = True
    layout.use_property_decorate = False
    column = layout.column()
    # In Edit Mode the colour attribute the viewport shows is the edit mesh's and would be overwritten on leaving it.
    column.enabled = obj.mode != "EDIT"
    for name in ("exposure", "brightness", "saturation", "hue", "temperature"):
        column.prop(settings, name)


class OBJECT_PT_raysplats(bpy.types.Panel):
    bl_label = "Gaussian Splats"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type in {"MESH", "POINTCLOUD"}

    def draw(self, context):
        _draw_settings(self.layout, context.object)


class OBJECT_PT_raysplats_colors(bpy.types.Panel):
    bl_label = "Color"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"
    bl_parent_id = "OBJECT_PT_raysplats"

    @classmethod
    def poll(cls, context):
        return polygon_mesh.is_gaussian_object(context.object)

    def draw(self, context):
        _draw_colors(self.layout, context.object)


class _SidebarPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = SIDEBAR_CATEGORY

    @classmethod
    def poll(cls, context):
        return polygon_mesh.is_gaussian_object(context.active_object)


class VIEW3D_PT_raysplats(_SidebarPanel, bpy.types.Panel):
    bl_label = "Gaussian Splats"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type in {"MESH", "POINTCLOUD"}

    def draw(self, context):
        _draw_settings(self.layout, context.active_object)


class VIEW3D_PT_raysplats_select(_SidebarPanel, bpy.types.Panel):
    bl_label = "Select"
    bl_parent_id = "VIEW3D_PT_raysplats"

    def draw(self, context):
        layout = self.layout
        column = layout.column(align=True)
        for cls in (select_splats.MESH_OT_raysplats_select_opacity, select_splats.MESH_OT_raysplats_select_size,
                    select_splats.MESH_OT_raysplats_select_color, select_splats.MESH_OT_raysplats_select_floaters):
            column.operator(cls.bl_idname)
        box = layout.box()
        box.prop(context.scene.raysplats_tools, "crop_object")
        row = box.row(align=True)
        row.operator(select_splats.MESH_OT_raysplats_select_crop_box.bl_idname, text="Inside").inside = True
        row.operator(select_splats.MESH_OT_raysplats_select_crop_box.bl_idname, text="Outside").inside = False


class VIEW3D_PT_raysplats_clean_up(_SidebarPanel, bpy.types.Panel):
    bl_label = "Clean Up"
    bl_parent_id = "VIEW3D_PT_raysplats"

    def draw(self, context):
        column = self.layout.column(align=True)
        column.operator(select_splats.MESH_OT_raysplats_delete_selected.bl_idname, icon="X")
        column.operator(upkeep.OBJECT_OT_raysplats_reduce_sh_degree.bl_idname)
        column.operator(exact_apply.OBJECT_OT_raysplats_apply_transform.bl_idname)


class VIEW3D_PT_raysplats_colors(_SidebarPanel, bpy.types.Panel):
    bl_label = "Color"
    bl_parent_id = "VIEW3D_PT_raysplats"

    def draw(self, context):
        _draw_colors(self.layout, context.active_object)


class VIEW3D_MT_raysplats_select(bpy.types.Menu):
    bl_label = "Gaussian Splats"

    def draw(self, context):
        layout = self.layout
        for cls in (select_splats.MESH_OT_raysplats_select_opacity, select_splats.MESH_OT_raysplats_select_size,
                    select_splats.MESH_OT_raysplats_select_color, select_splats.MESH_OT_raysplats_select_floaters):
            layout.operator(cls.bl_idname)
        crop_box = select_splats.MESH_OT_raysplats_select_crop_box.bl_idname
        layout.operator(crop_box, text="Inside Crop Box").inside = True
        layout.operator(crop_box, text="Outside Crop Box").inside = False


class VIEW3D_MT_raysplats_mesh(bpy.types.Menu):
    bl_label = "Gaussian Splats"

    def draw(self, context):
        layout = self.layout
        layout.operator(select_splats.MESH_OT_raysplats_delete_selected.bl_idname)
        layout.operator(upkeep.OBJECT_OT_raysplats_reduce_sh_degree.bl_idname)


def _draw_select_menu(self, context):
    if polygon_mesh.is_gaussian_object(context.edit_object):
        self.layout.separator()
        self.layout.menu(VIEW3D_MT_raysplats_select.__name__)


def _draw_mesh_menu(self, context):
    kind = splat_object.kind_of(context.edit_object)
    if kind == splat_object.POLYGONS:
        self.layout.separator()
        self.layout.menu(VIEW3D_MT_raysplats_mesh.__name__)
    elif kind == splat_object.POINTS:
        self.layout.separator()
        self.layout.operator(region_editing.OBJECT_OT_raysplats_edit_region.bl_idname)


def _draw_exact_apply(layout):
    operator = exact_apply.OBJECT_OT_raysplats_apply_transform.bl_idname
    for text, flags in (("Location", (True, False, False)), ("Rotation", (False, True, False)),
                        ("Scale", (False, False, True)), ("All Transforms", (True, True, True)),
                        ("Rotation & Scale", (False, True, True))):
        props = layout.operator(operator, text=text)
        props.location, props.rotation, props.scale = flags


def _draw_apply_menu(self, context):
    # Object > Apply: Blender's own Apply moves only the polygons' corners (the centres of points), which loses a
    # Gaussian's thickness and its exact shape under a non-uniform scale; for splat objects the exact entries come
    # first.
    if splat_object.is_splat_object(context.active_object) and not getattr(context, "raysplats_exact_shown", False):
        self.layout.label(text="Gaussian Splats (exact)")
        _draw_exact_apply(self.layout)
        self.layout.separator()


class VIEW3D_MT_raysplats_apply(bpy.types.Menu):
    """Ctrl+A in Object Mode (the add-on's key map): for a splat object its Apply entries are the Gaussian-exact ones,
    Blender's own (which move only the corners) one level down; for anything else exactly Blender's Apply menu."""

    bl_label = "Apply"

    def draw(self, context):
        layout = self.layout
        if not splat_object.is_splat_object(context.active_object):
            layout.menu_contents("VIEW3D_MT_object_apply")
            return
        _draw_exact_apply(layout)
        layout.separator()
        layout.context_pointer_set("raysplats_exact_shown", context.active_object)
        layout.menu("VIEW3D_MT_object_apply", text="Blender's Apply (corners and centres only)")


# Key map items the add-on added (key map, item), removed again on unregister.
_keymap_items = []


def _register_keymap():
    key_configs = bpy.context.window_manager.keyconfigs
    addon = key_configs.addon if key_configs is not None else None
    if addon is None:  # background: there is no key configuration
        return
    keymap = addon.keymaps.new(name="Object Mode", space_type="EMPTY")
    item = keymap.keymap_items.new("wm.call_menu", "A", "PRESS", ctrl=True)
    item.properties.name = VIEW3D_MT_raysplats_apply.__name__
    _keymap_items.append((keymap, item))


CLASSES = (OBJECT_PT_raysplats, OBJECT_PT_raysplats_colors, VIEW3D_PT_raysplats, VIEW3D_PT_raysplats_select,
           VIEW3D_PT_raysplats_clean_up, VIEW3D_PT_raysplats_colors, VIEW3D_MT_raysplats_select,
           VIEW3D_MT_raysplats_mesh, VIEW3D_MT_raysplats_apply)
MENU_HOOKS = (("VIEW3D_MT_select_edit_mesh", "append", _draw_select_menu),
              ("VIEW3D_MT_edit_mesh", "append", _draw_mesh_menu),
              ("VIEW3D_MT_object_apply", "prepend", _draw_apply_menu))


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for menu, how, draw in MENU_HOOKS:
        getattr(getattr(bpy.types, menu), how)(draw)
    _register_keymap()


def unregister():
    for keymap, item in _keymap_items:
        keymap.keymap_items.remove(item)
    _keymap_items.clear()
    for menu, _, draw in MENU_HOOKS:
        getattr(bpy.types, menu).remove(draw)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
