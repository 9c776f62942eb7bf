# Depsgraph -> native RenderScene: meshes (modifiers applied, instances included), Gaussian objects recovered
# from their evaluated meshes, materials (materials.py), lights in Blender units, the world and the camera.

import collections
from types import SimpleNamespace

import bpy
import numpy as np

from .. import errors, native, progress
from ..blender import compat, mesh_read
from ..objects import color_adjustment, compact_points, polygon_mesh, splat_object
from ..blender.material_reader import input_value
from . import motion_blur
from .material_table import MaterialTable
from .render_properties import RaySplatsRenderSettings


def _light_kwargs(light, matrix):
    scale = matrix.to_scale()
    common = {"color": tuple(light.color), "power": float(light.energy),
              "matrix": np.array(matrix.normalized(), dtype=np.float32)}
    if light.type == "SUN":
        return dict(common, type="SUN", sun_angle=float(light.angle))
    if light.type == "SPOT":
        return dict(common, type="SPOT", spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
    if light.type == "AREA":
        shape = "AREA_DISK" if light.shape in ("DISK", "ELLIPSE") else "AREA_RECTANGLE"
        size_y = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
        return dict(common, type=shape, power=float(light.energy) * compat.AREA_LIGHT_POWER_SCALE,
                    size_x=float(light.size * scale.x), size_y=float(size_y * scale.y))
    return dict(common, type="POINT")


# Blender's mist falloffs as the exponents Cycles gives them (intern/cycles/blender/sync.cpp, sync_film).
_MIST_FALLOFF = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}


def _world_mist(scene):
    """RenderScene.set_world's mist arguments from the World's Mist Pass settings (none without a World: the core's
    defaults, Cycles' own, which Cycles renders such a scene with)."""
    world = scene.world
    if world is None:
        return {}
    mist = world.mist_settings
    return {"mist_start": float(mist.start), "mist_depth": float(mist.depth),
            "mist_falloff": _MIST_FALLOFF[mist.falloff]}


def first_material(obj):
    """The material a Gaussian object's Gaussians count as in the Material Index and Cryptomatte Material passes: its
    first material (None without one), since Gaussians have no material of their own (docs/reference.md, Passes)."""
    return next((slot.material for slot in obj.material_slots if slot.material is not None), None)


def pass_indices(obj):
    """(object pass index, material pass index) of a Gaussian object for the Object and Material Index passes: its
    Object.pass_index, and its first material's pass_index (0 without one)."""
    material = first_material(obj)
    return int(obj.pass_index), int(material.pass_index) if material is not None else 0


def cryptomatte_asset(obj):
    """The Cryptomatte Asset name of an object: its top-level parent's name, or its own without a parent (Cycles,
    blender/object.cpp, sync_object)."""
    while obj.parent is not None:
        obj = obj.parent
    return obj.name


def masks(obj, view_layer, parent=None):
    """(holdout, shadow catcher) of an object drawn in the view layer, as Cycles reads them (blender/object.cpp): held
    out by its Holdout or a collection's in the view layer (Object.holdout_get), an instance by its instancer's; a
    shadow catcher by its own Shadow Catcher or its instancer's."""
    source = (parent or obj).original
    return (bool(source.holdout_get(view_layer=view_layer)),
            bool(obj.original.is_shadow_catcher or source.is_shadow_catcher))


def instance_masks(instance, view_layer):
    """masks() of a depsgraph object instance."""
    return masks(instance.object, view_layer, instance.parent if instance.is_instance else None)


def _world(scene):
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0), 0.0
    if world.use_nodes and world.node_tree is not None:
        output = next((n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"
                       and n.is_active_output), None)
        if output and output.inputs["Surface"].is_linked:
            node = output.inputs["Surface"].links[0].from_node
            if node.bl_idname == "ShaderNodeBackground":
                return input_value(node, (0.05, 0.05, 0.05), "Color"), input_value(node, 1.0, "Strength")
    return tuple(world.color), 1.0


def _object_shading(obj):
    """The object's own Gaussian shading for RenderScene.set_gaussian_shading (None: the scene's)."""
    shading = obj.raysplats.gaussian_shading
    return None if shading == "SCENE" else shading


def triangle_mesh_arrays(mesh):
    """Vertices, triangles and per-triangle material slots of any mesh (loop triangles, bulk reads)."""
    mesh.calc_loop_triangles()
    vertices = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", vertices)
    triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    slots = np.empty(len(mesh.loop_triangles), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("material_index", slots)
    return vertices.reshape(-1, 3), triangles.reshape(-1, 3), slots


def corner_mesh_arrays(mesh, uv_map):
    """Like triangle_mesh_arrays, with one vertex per loop-triangle corner so that each carries its own UV.

    Blender stores UVs per loop (face corner) while the renderer's UVs are per vertex: a vertex on a UV seam
    has several. Unsharing the vertices (3 per triangle) gives every corner its loop's UV. Returns
    (vertices, triangles, slots, uvs, uv_layer_name, corners), corners the mesh vertex of each vertex; uvs is None when
    the mesh has no such UV map."""
    vertices, corner_vertices, slots = triangle_mesh_arrays(mesh)
    layer = mesh.uv_layers.get(uv_map) if uv_map else None
    if layer is None:
        # The default UV map of a texture is the one marked for rendering (Cycles' ATTR_STD_UV).
        layer = next((uv for uv in mesh.uv_layers if uv.active_render), None) or mesh.uv_layers.active
    corners = corner_vertices.ravel()
    vertices = vertices[corners]
    triangles = np.arange(len(corners), dtype=np.uint32).reshape(-1, 3)
    if layer is None:
        return vertices, triangles, slots, None, None, corners
    loops = np.empty(len(corners), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("loops", loops)
    loop_uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    layer.data.foreach_get("uv", loop_uvs)
    return vertices, triangles, slots, loop_uvs.reshape(-1, 2)[loops], layer.name, corners


class SceneStats:
    def __init__(self):
        self.splats = 0
        self.triangles = 0
        self.lights = 0
        self.warnings = []


IDENTITY = np.identity(4, dtype=np.float64)

# An edit that changes at most this fraction of a Gaussian object's faces recovers only those faces; more, and the
# whole object is recovered (about as fast then, and simpler).
PARTIAL_RECOVERY_LIMIT = 0.5


class _CloudSource:
    """What a Gaussian object's cloud was recovered from: its mesh arrays, face attributes and settings. Kept in
    interactive scenes so that an edit recovers only the faces whose corners or attributes changed."""

    def __init__(self, arrays, attributes, settings_key):
        self.arrays, self.attributes, self.settings_key = arrays, attributes, settings_key

    def copy(self):
        return _CloudSource(tuple(np.copy(a) for a in self.arrays),
                            {k: None if v is None else np.copy(v) for k, v in self.attributes.items()},
                            self.settings_key)

    def unshared_with(self, other):
        """This source's arrays that `other` does not also hold (None in their place): what a later read may overwrite
        while `other` is still in use."""
        def shared(array, arrays):
            return any(array is a for a in arrays)
        arrays = tuple(None if a is None or shared(a, other.arrays) else a for a in self.arrays)
        attributes = {k: v for k, v in self.attributes.items()
                      if v is not None and not shared(v, other.attributes.values())}
        return _CloudSource(arrays, attributes, self.settings_key)

    def changed_faces(self, core, other):
        """Faces (ascending uint32) that differ in `other`, a later _CloudSource of the same object, or None when
        the topology, the settings or the set of stored attributes changed (then everything is recovered)."""
        if other.settings_key != self.settings_key or other.arrays[0].shape != self.arrays[0].shape:
            return None
        # Corner vertices, face starts, face sizes: any change of topology means faces are no longer rows. (When
        # mesh_arrays took the face starts from this source, it has compared the corners and sizes already.)
        if other.arrays[2] is not self.arrays[2] and \
                not all(np.array_equal(new, old) for new, old in zip(other.arrays[1:], self.arrays[1:])):
            return None
        changed = [core.faces_with_moved_vertices(self.arrays[0], *other.arrays)]
        for name, values in other.attributes.items():
            old = self.attributes[name]
            if (values is None) != (old is None):
                return None
            if values is not None and values is not old:  # (an Edit Mode read shares the attributes it did not read)
                changed.append(core.rows_that_differ(old, values))
        return np.unique(np.concatenate(changed))


class SceneSync:
    """The native RenderScene of everything visible in an evaluated depsgraph, and which native cloud or mesh each
    object became, so that the viewport can apply the depsgraph's later changes in place (`update`): an edited
    Gaussian object has only the faces whose corners or attributes changed recovered again and replaced (the whole
    object when its topology changed), and the renderer rebuilds only the chunks that hold them; a moved one only
    moves instances; an edited or moved mesh object replaces its mesh. Gaussian clouds are recovered in the
    object's own frame and placed by its world matrix, so moving an object costs no recovery."""

    def __init__(self, depsgraph, warn=None, interactive=False, clock=None):
        self.core = native.core()
        # CPU and wall seconds of reading Blender's data ("read"), recovering Gaussians ("convert") and handing
        # arrays to the core ("scene"), summed over objects.
        self.clock = clock if clock is not None else progress.StageClock()
        self.render_scene = self.core.RenderScene()
        if interactive:
            self.render_scene.set_interactive(True)
            # The viewport renders the scene again after every view change and edit: its camera-ray splatting
            # writes into the last render's storage instead of fresh pages.
            self.render_scene.set_keep_frame_buffers(True)
        self.stats = SceneStats()
        self._warn = warn
        self._seen_warnings = set()
        self.clouds = {}  # original object (as_pointer) drawn once (not an instance) -> (native cloud index, splats)
        self.shading = {}  # original object -> its Gaussian shading as last given to the native cloud
        self.interactive = interactive
        self.sources = {}  # interactive: original object -> _CloudSource of its cloud (absent: recover all next time)
        self.spare_sources = {}  # original object -> an older _CloudSource, whose arrays the next read reuses
        self.faces_recovered = 0  # by the last update() (diagnostics: an edit of a few splats recovers only them)
        # original object -> (native mesh index, (vertices, triangles, face_materials, uvs, vertex_map)), vertex_map as
        # _mesh_arrays gives it
        self.meshes = {}
        self.compact = {}  # original compact splat object (drawn once) -> (native cloud index, splats)
        self.pass_indices = {}  # original object (drawn once) -> pass_indices() as given to the native scene
        # Every native mesh and cloud as (motion_blur.instance_key, is a mesh, native index), and whether some have
        # motion (apply_motion).
        self.instances = []
        self.has_motion = False
        self.vertex_maps = {}  # native mesh index -> its vertex_map (_mesh_arrays)
        # Native cloud index of a polygon object that may deform during the shutter -> (its _CloudSource, its
        # Gaussian count, its name, its recovery settings), for apply_motion.
        self.deform_sources = {}

        # The names given to the core for the Cryptomatte passes, by kind: their manifests (passes.py).
        self.cryptomatte_names = {"object": set(), "material": set(), "asset": set()}

        self.view_layer = depsgraph.view_layer
        self.masks = {}  # original object (drawn once) -> masks() as given to the native scene
        self._build(depsgraph)

    @staticmethod
    def _compact_cloud(obj):
        """The Gaussians of an evaluated compact splat object in its own frame (its points' attributes; modifiers
        move the centres), or None when it has no points. In Edit Mode the evaluated mesh wraps the edit BMesh
        without filling its arrays: to_mesh() fills a copy."""
        if obj.original.mode == "EDIT" and obj.type == "MESH":
            try:
                return compact_points.object_cloud(obj, obj.to_mesh())
            finally:
                obj.to_mesh_clear()
        return compact_points.object_cloud(obj)

    def _warn_once(self, message):
        if message not in self._seen_warnings:
            self._seen_warnings.add(message)
            self.stats.warnings.append(message)
            if self._warn:
                self._warn(message)

    def _read(self, obj, depsgraph, reuse=None, previous=None):
        """The mesh arrays, face attributes and settings of an evaluated Gaussian object (a _CloudSource); `depsgraph`:
        the one it was evaluated in, None for an instance; `reuse`: an earlier _CloudSource whose arrays may be
        overwritten; `previous`: the object's last _CloudSource."""
        settings = obj.raysplats
        # (The colour adjustments are part of the key: changing them re-recovers the object with the new colours.)
        key = (settings.vertices_per_polygon, settings.radius, settings.sh_degree,
               color_adjustment.adjustment_key(settings))
        arrays, attributes = (reuse.arrays, reuse.attributes) if reuse else (None, None)

        def read(mesh):
            return _CloudSource(polygon_mesh.mesh_arrays(mesh, arrays, previous.arrays if previous else None),
                                polygon_mesh.face_attributes(mesh, key[2], attributes), key)

        if obj.original.mode == "EDIT":
            source = self._read_edit_mode_positions(obj, reuse, previous, key)
            if source is not None:
                return source
            # Else (the first read, a change of topology, modifiers, shape keys): the evaluated mesh wraps the edit
            # BMesh without filling its arrays; to_mesh() fills a copy of the whole mesh.
            try:
                return read(obj.to_mesh())
            finally:
                obj.to_mesh_clear()
        # (An instance's object is not necessarily the evaluated object of its datablock: read its own mesh.)
        return read(obj.data if depsgraph is None else mesh_read.evaluated_mesh(obj, depsgraph))

    @staticmethod
    def _read_edit_mode_positions(obj, reuse, previous, key):
        """In Edit Mode, when the evaluated mesh is the edit mesh itself (no modifiers, shape keys or deforming parent)
        and its faces are still those of `previous`: `previous` with the vertex positions read in place from the
        BMesh (mesh_read.read_edit_mode_positions; the face attributes are taken as they were). Else None."""
        original = obj.original
        if previous is None or previous.settings_key != key or len(original.modifiers) \
                or original.data.shape_keys is not None or not mesh_read.places_only(original):
            return None
        positions = mesh_read.flat_buffer(reuse.arrays[0] if reuse else None, previous.arrays[0].size,
                                               np.float32).reshape((-1, 3))
        if np.shares_memory(positions, previous.arrays[0]):  # (`previous` is compared with what is read)
            positions = np.empty_like(previous.arrays[0])
        if mesh_read.read_edit_mode_positions(original.data, positions, *previous.arrays[1:]) != "read":
            return None
        return _CloudSource((positions,) + tuple(previous.arrays[1:]), previous.attributes, key)

    def _recover(self, obj, source, faces=None):
        """Gaussians of an evaluated Gaussian object (all, or `faces`), in its own frame."""
        return polygon_mesh.recover_from_arrays(self.core, source.arrays, source.attributes, obj.raysplats,
                                                 IDENTITY, faces)

    def _keep_source(self, uid, source, cloud):
        # Rows are faces only while no face was dropped (a dropped face shifts the rows after it).
        if self.interactive and uid is not None and cloud["stats"]["dropped"] == 0:
            self.sources[uid] = source
            if uid not in self.spare_sources:
                # The arrays the first edit reads into, touched now: fresh ones would cost that edit their page
                # faults, which cost less here, while the scene is built (docs/benchmarks.md).
                self.spare_sources[uid] = source.copy()
        else:
            self.sources.pop(uid, None)

    def _update_cloud(self, uid, obj, matrix, depsgraph):
        """Applies an edit of a Gaussian object to its native cloud: only the changed faces when the topology is
        the same, else the whole object. False when the object has no Gaussians left (the caller rebuilds)."""
        index, count = self.clouds[uid]
        previous = self.sources.get(uid)
        # Read into the arrays of the source before `previous` (no longer needed), if there is one.
        source = self._read(obj, depsgraph, self.spare_sources.pop(uid, None), previous)
        faces = previous.changed_faces(self.core, source) if previous else None
        if faces is not None and len(faces) <= PARTIAL_RECOVERY_LIMIT * count:
            part = self._recover(obj, source, faces) if len(faces) else None
            self.faces_recovered += len(faces)
            if part is None or len(part["opacities"]) == len(faces):  # no changed face dropped (NaN vertices)
                if part is not None:
                    self.render_scene.update_gaussian_rows(index, faces, part["positions"], part["rotations"],
                                                           part["scales"], part["opacities"], part["sh"])
                self.render_scene.set_gaussians_matrix(index, matrix)
                self.sources[uid], self.spare_sources[uid] = source, previous.unshared_with(source)
                self._keep_deform_source(index, source, count)
                return True
        cloud = self._recover(obj, source)
        self.faces_recovered += len(source.arrays[2])
        if len(cloud["opacities"]) == 0:
            return False
        if previous is not None:
            self.spare_sources[uid] = previous.unshared_with(source)  # the next read reuses its arrays
        self.render_scene.update_gaussians(index, cloud["positions"], cloud["rotations"], cloud["scales"],
                                           cloud["opacities"], cloud["sh"], matrix)
        self.stats.splats += len(cloud["opacities"]) - count
        self.clouds[uid] = (index, len(cloud["opacities"]))
        self._keep_source(uid, source, cloud)
        self._keep_deform_source(index, source, len(cloud["opacities"]))
        return True

    def _keep_deform_source(self, index, source, count):
        """After an edit (Persistent Data's next frame): what native cloud `index`'s deformation is recovered from,
        when it may deform."""
        if index in self.deform_sources:
            self.deform_sources[index] = (source, count) + self.deform_sources[index][2:]

    def _build(self, depsgraph):
        render_scene, stats = self.render_scene, self.stats
        materials = MaterialTable(render_scene, self._warn_once)
        mesh_cache = {}
        self.membership = collections.Counter()
        for instance in depsgraph.object_instances:
            obj = instance.object
            object_masks = instance_masks(instance, depsgraph.view_layer)
            self.membership[(obj.original.as_pointer(), instance.is_instance, object_masks)] += 1
            matrix = instance.matrix_world
            uid = None if instance.is_instance else obj.original.as_pointer()
            kind = splat_object.kind_of(obj)
            holdout, shadow_catcher = object_masks
            if shadow_catcher and kind is not None:
                self._warn_once(f"Splat object '{obj.name}' is a Shadow Catcher, which Gaussians cannot be in "
                                "RaySplats: it is drawn as an ordinary object")
            if kind is not None:
                for message in splat_object.fidelity_warnings(obj.original, for_render=not self.interactive):
                    self._warn_once(message)
                if kind == splat_object.POLYGONS:
                    with self.clock.stage("read"):
                        source = self._read(obj, None if instance.is_instance else depsgraph)
                    with self.clock.stage("convert"):
                        cloud = self._recover(obj, source)
                    deforms = not self.interactive and depsgraph.scene.render.use_motion_blur \
                        and motion_blur.may_deform(obj.original, depsgraph.scene)
                else:
                    with self.clock.stage("read"):
                        source, cloud = None, self._compact_cloud(obj)
                if cloud is None or not len(cloud["opacities"]):
                    continue
                with self.clock.stage("scene"):
                    index = render_scene.add_gaussians(cloud["positions"], cloud["rotations"], cloud["scales"],
                                                       cloud["opacities"], cloud["sh"],
                                                       np.array(matrix, dtype=np.float32))
                stats.splats += len(cloud["opacities"])
                self.instances.append((motion_blur.instance_key(instance), False, index))
                if kind == splat_object.POLYGONS and deforms:
                    # What a deformation across the shutter is recovered from (apply_motion): the frame's faces and
                    # attributes with each step's vertices.
                    self.deform_sources[index] = (source, len(cloud["opacities"]), obj.name, SimpleNamespace(
                        vertices_per_polygon=obj.raysplats.vertices_per_polygon, radius=obj.raysplats.radius))
                render_scene.set_gaussian_shading(index, _object_shading(obj))
                render_scene.set_gaussian_pass_indices(index, *pass_indices(obj))
                material = first_material(obj)
                self._name_for_cryptomatte(index, obj, material.name if material is not None else "")
                if holdout:
                    render_scene.set_gaussian_holdout(index, True)
                if uid is None:
                    continue
                self.pass_indices[uid] = pass_indices(obj)
                self.masks[uid] = object_masks
                if kind == splat_object.POLYGONS:
                    self.shading[uid] = _object_shading(obj)
                    self.clouds[uid] = (index, len(cloud["opacities"]))
                    self._keep_source(uid, source, cloud)
                else:
                    self.compact[uid] = (index, len(cloud["opacities"]))
            elif obj.type in ("MESH", "CURVE", "SURFACE", "META", "FONT"):
                with self.clock.stage("read"):
                    arrays = self._mesh_arrays(obj, materials, mesh_cache)
                if arrays is None:
                    continue
                vertices, triangles, face_materials, uvs, vertex_map = arrays
                with self.clock.stage("scene"):
                    index = render_scene.add_mesh(vertices, triangles, np.array(matrix, dtype=np.float32),
                                                  face_materials=face_materials, uvs=uvs, pass_index=obj.pass_index,
                                                  holdout=holdout, shadow_catcher=shadow_catcher)
                stats.triangles += len(triangles)
                self.instances.append((motion_blur.instance_key(instance), True, index))
                self.vertex_maps[index] = vertex_map
                self._name_for_cryptomatte(index, obj)
                if uid is not None:
                    self.meshes[uid] = (index, arrays)
                    self.pass_indices[uid] = pass_indices(obj)
                    self.masks[uid] = object_masks
            elif obj.type == "LIGHT":
                render_scene.add_light(**_light_kwargs(obj.data, matrix))
                stats.lights += 1
        self.materials = materials
        self.cryptomatte_names["material"].update(materials.names)
        color, strength = _world(depsgraph.scene)
        render_scene.set_world(color, strength, **_world_mist(depsgraph.scene))

    def apply_motion(self, motion):
        """Gives each native mesh and cloud its object's motion across the shutter (a motion_blur.ShutterMotion, or
        None), and each native mesh its deformation, and takes back the motion an earlier frame gave. Nothing to do
        for a still scene that had none."""
        objects = motion.objects if motion is not None else {}
        deformation = motion.deformation if motion is not None else {}
        for message in motion.warnings if motion is not None else ():
            self._warn_once(message)
        if not objects and not deformation and not self.has_motion:
            return
        for key, is_mesh, index in self.instances:
            matrices = objects.get(key)
            if is_mesh:
                self.render_scene.set_mesh_motion(index, matrices)
                self.render_scene.set_mesh_deformation(index, self._mesh_steps(index, deformation.get(key)))
            else:
                self.render_scene.set_gaussians_motion(index, matrices)
                self._deform_cloud(index, deformation.get(key))
        self.has_motion = bool(objects or deformation)

    def _deform_cloud(self, index, positions):
        """Gives native cloud `index` the Gaussians recovered from its polygon object's vertices at each step of a
        deformation (positions: the mesh's vertices at each step, or None: none), with the frame's faces and
        attributes. Left out, with a warning, when a step does not give the frame's Gaussians one for one (a
        polygon that degenerates at some step is dropped there)."""
        source = self.deform_sources.get(index)
        if source is None or positions is None:
            self.render_scene.set_gaussians_deformation(index)
            return
        source, count, name, settings = source
        steps = []
        if positions.shape[1] == len(source.arrays[0]):
            with self.clock.stage("convert"):
                for step in positions:
                    steps.append(polygon_mesh.recover_from_arrays(self.core, (step,) + tuple(source.arrays[1:]),
                                                                  source.attributes, settings, IDENTITY,
                                                                  adjust_colors=False))
        if len(steps) != len(positions) or any(len(step["opacities"]) != count for step in steps):
            self._warn_once(f"Object '{name}': its Gaussians change in number during the shutter; its deformation "
                            "is not blurred")
            self.render_scene.set_gaussians_deformation(index)
            return
        self.render_scene.set_gaussians_deformation(
            index, *(np.stack([step[field] for step in steps]) for field in ("positions", "rotations", "scales")))

    def _mesh_steps(self, index, positions):
        """The vertices the core holds for native mesh `index` at each step of a mesh's deformation (positions: the
        mesh's vertices at each step, or None), or None when they cannot be (the mesh read at the frame had another
        vertex count)."""
        count, corners = self.vertex_maps[index]
        if positions is None or positions.shape[1] != count:
            return None
        return positions if corners is None else np.ascontiguousarray(positions[:, corners])

    def apply_frame_motion(self, motion):
        """Gives each native mesh and cloud its object's matrices at the previous and next frames (a
        motion_blur.ShutterMotion of motion_blur.frame_motion), and a deforming mesh its vertices there, for the Vector
        pass."""
        for key, is_mesh, index in self.instances:
            matrices = motion.objects.get(key)
            if is_mesh:
                if matrices is not None:
                    self.render_scene.set_mesh_frame_motion(index, matrices[0], matrices[1])
                vertices = self._mesh_steps(index, motion.deformation.get(key))
                self.render_scene.set_mesh_frame_deformation(index, *(() if vertices is None else vertices))
            elif matrices is not None:
                self.render_scene.set_gaussians_frame_motion(index, matrices[0], matrices[1])

    def _name_for_cryptomatte(self, index, obj, gaussian_material=None):
        """Gives the core the Cryptomatte names of Gaussian cloud `index` (with `gaussian_material`: the name of the
        material its Gaussians count as, "" for none) or of mesh `index` (its materials have theirs): the object's name
        and its asset's, as Cycles names them (the object of an instance is the instanced object)."""
        asset = cryptomatte_asset(obj)
        if gaussian_material is None:
            self.render_scene.set_mesh_cryptomatte_names(index, obj.name, asset)
        else:
            self.render_scene.set_gaussian_cryptomatte_names(index, obj.name, gaussian_material, asset)
        self.cryptomatte_names["object"].add(obj.name)
        self.cryptomatte_names["asset"].add(asset)
        if gaussian_material:
            self.cryptomatte_names["material"].add(gaussian_material)

    def _mesh_arrays(self, obj, materials, mesh_cache):
        """(vertices, triangles, face_materials, uvs, vertex_map) of a mesh-like object, or None when it has no
        triangles. vertex_map: (the mesh's vertex count, the mesh vertex of each vertex given to the core, or None when
        they are the mesh's own), which maps the mesh's deformation (motion_blur.ShutterMotion) to the core's
        vertices."""
        slot_materials = [slot.material for slot in obj.material_slots]
        material_indices = np.array([materials.index(m) for m in slot_materials] or [materials.default],
                                    dtype=np.uint32)
        # A mesh with a textured material needs per-corner UVs (corner_mesh_arrays); the others keep the
        # shared vertices, which are cheaper. The first textured slot chooses the UV map.
        uv_map = next((m for m in map(materials.uv_map, slot_materials) if m is not None), None)
        # Instances of one mesh (collection, particle, Geometry Nodes instances) share its arrays.
        key = (obj.data.as_pointer(), uv_map) if obj.type == "MESH" and mesh_cache is not None else None
        arrays = mesh_cache.get(key) if key else None
        if arrays is None:
            mesh = obj.data if obj.type == "MESH" else obj.to_mesh()
            try:
                if uv_map is None:
                    arrays = triangle_mesh_arrays(mesh) + (None, (len(mesh.vertices), None))
                else:
                    vertices, triangles, slots, uvs, layer, corners = corner_mesh_arrays(mesh, uv_map)
                    arrays = vertices, triangles, slots, uvs, (len(mesh.vertices), corners)
                    if layer is None:
                        self._warn_once(f"Mesh '{mesh.name}' has no UV map but a textured material; the texture "
                                        "is looked up at UV (0, 0)")
                    elif uv_map and layer != uv_map:
                        self._warn_once(f"Mesh '{mesh.name}' has no UV map '{uv_map}'; '{layer}' is used")
            finally:
                if obj.type != "MESH":
                    obj.to_mesh_clear()
            if key:
                mesh_cache[key] = arrays
        vertices, triangles, slots, uvs, vertex_map = arrays
        if not len(triangles):
            return None
        face_materials = material_indices[np.minimum(slots, len(material_indices) - 1)]
        return vertices, triangles, face_materials, uvs, vertex_map

    @staticmethod
    def _membership(depsgraph):
        """The objects the depsgraph draws (original pointers, their masks()) and how many times each, as `membership`
        records them when the scene is built: a collection update that leaves them as they were changes nothing of the
        scene (a collection's Holdout does)."""
        return collections.Counter((instance.object.original.as_pointer(), instance.is_instance,
                                    instance_masks(instance, depsgraph.view_layer))
                                   for instance in depsgraph.object_instances)

    # Datablocks whose changes the in-place update cannot express: the scene is built again.
    _REBUILD_TYPES = (bpy.types.Material, bpy.types.World, bpy.types.Light, bpy.types.Image, bpy.types.NodeTree,
                      bpy.types.Collection)

    def changes_scene(self, update):
        """True when a depsgraph update (an item of depsgraph.updates) changes the native scene, so that update()
        would apply it: the viewport stops its render only for these (the core refuses changes during a render)."""
        data = update.id
        if isinstance(data, self._REBUILD_TYPES):
            return True
        if not isinstance(data, bpy.types.Object):
            return False  # the scene, meshes (their objects report the change), ...
        uid = data.original.as_pointer()
        if uid in self.clouds and _object_shading(data) != self.shading.get(uid):
            return True  # the object's Gaussian Shading (a property: neither geometry nor transform)
        if uid in self.pass_indices and pass_indices(data) != self.pass_indices[uid]:
            return True  # its pass index, or its first material's (neither geometry nor transform either)
        if uid in self.masks and masks(data, self.view_layer) != self.masks[uid]:
            return True  # its Holdout or Shadow Catcher
        if not (update.is_updated_geometry or update.is_updated_transform):
            return False  # selection, active object
        # Objects the scene holds nothing of: the camera (not part of the scene), and those whose changes reach it
        # through the objects they move or deform, which report their own updates (the empty a split import's
        # pieces hang from, an armature, a lattice), unless they instance a collection.
        if data.type == "EMPTY":
            return data.instance_type != "NONE"
        return data.type not in self._UNDRAWN_TYPES

    _UNDRAWN_TYPES = frozenset({"CAMERA", "ARMATURE", "LATTICE", "SPEAKER", "LIGHT_PROBE", "LIGHTPROBE"})

    def update(self, depsgraph):
        """Applies the depsgraph's changes in place. Returns "none", "updated" or "rebuild" (the caller makes a new
        SceneSync: objects were added or removed, or materials, lights or the world changed)."""
        result = "none"
        self.faces_recovered = 0
        for update in depsgraph.updates:
            if not self.changes_scene(update):
                continue
            data = update.id
            if isinstance(data, bpy.types.Collection) and self._membership(depsgraph) == self.membership:
                continue  # (Blender 4+ reports the scene's collection at every frame change)
            if isinstance(data, self._REBUILD_TYPES):
                return "rebuild"
            uid = data.original.as_pointer()
            matrix = np.array(data.matrix_world, dtype=np.float32)
            if uid in self.pass_indices and pass_indices(data) != self.pass_indices[uid]:
                return "rebuild"  # (rare: an animated pass index)
            if uid in self.masks and masks(data, self.view_layer) != self.masks[uid]:
                return "rebuild"  # its Holdout or Shadow Catcher
            if uid in self.clouds:
                shading = _object_shading(data)
                if shading != self.shading.get(uid):
                    self.render_scene.set_gaussian_shading(self.clouds[uid][0], shading)
                    self.shading[uid] = shading
                if not (update.is_updated_geometry or update.is_updated_transform):
                    pass  # only the shading changed
                elif not update.is_updated_geometry:
                    self.render_scene.set_gaussians_matrix(self.clouds[uid][0], matrix)
                elif not self._update_cloud(uid, data, matrix, depsgraph):
                    return "rebuild"
                result = "updated"
            elif uid in self.compact:
                index, count = self.compact[uid]
                if update.is_updated_geometry:
                    cloud = self._compact_cloud(data)
                    if cloud is None:
                        return "rebuild"
                    self.render_scene.update_gaussians(index, cloud["positions"], cloud["rotations"], cloud["scales"],
                                                       cloud["opacities"], cloud["sh"], matrix)
                    self.stats.splats += len(cloud["opacities"]) - count
                    self.compact[uid] = (index, len(cloud["opacities"]))
                else:
                    self.render_scene.set_gaussians_matrix(index, matrix)
                result = "updated"
            elif uid in self.meshes:
                index, arrays = self.meshes[uid]
                if update.is_updated_geometry:
                    arrays = self._mesh_arrays(data, self.materials, None)
                    if arrays is None:
                        return "rebuild"
                    self.stats.triangles += len(arrays[1]) - len(self.meshes[uid][1][1])
                    self.meshes[uid] = (index, arrays)
                vertices, triangles, face_materials, uvs, self.vertex_maps[index] = arrays
                self.render_scene.update_mesh(index, vertices, triangles, matrix, face_materials=face_materials,
                                              uvs=uvs, pass_index=data.pass_index, holdout=self.masks[uid][0],
                                              shadow_catcher=self.masks[uid][1])
                result = "updated"
            else:
                return "rebuild"  # a new object, an instancer, a light
        return result


def build_render_scene(depsgraph, warn=None):
    """A native RenderScene of everything visible in the evaluated depsgraph. Returns (scene, stats)."""
    scene_sync = SceneSync(depsgraph, warn)
    return scene_sync.render_scene, scene_sync.stats


def camera_settings(scene, camera_object, width, height):
    """The native camera description of a Blender camera object: a dict of the core's camera parameters
    (_native.camera_parameters(); Blender's names and units, angles in radians)."""
    cam = camera_object.data
    camera = {
        "matrix": np.array(camera_object.matrix_world.normalized(), dtype=np.float32),
        "lens": cam.lens, "sensor_width": cam.sensor_width, "sensor_height": cam.sensor_height,
        "sensor_fit": cam.sensor_fit, "shift_x": cam.shift_x, "shift_y": cam.shift_y,
        "clip_start": cam.clip_start, "clip_end": cam.clip_end, "ortho_scale": cam.ortho_scale,
    }
    if cam.type == "PANO":
        # Blender 4 keeps panoramic settings on the camera; Blender 3 in Cycles' properties (ours here).
        source = cam if compat.CAMERA_HAS_PANORAMA_SETTINGS else cam.raysplats
        panorama = source.panorama_type
        # The core spells its camera models as Blender spells camera and panorama types.
        supported = [model["name"] for model in native.core().camera_models()]
        if panorama not in supported:
            raise ValueError(f"Camera '{camera_object.name}': panorama type {panorama} is not supported "
                             f"(the renderer's camera models: {', '.join(supported)})")
        camera["type"] = panorama
        for key in ("fisheye_fov", "fisheye_lens", "latitude_min", "latitude_max", "longitude_min",
                    "longitude_max"):
            camera[key] = float(getattr(source, key))
    else:
        camera["type"] = cam.type  # PERSP or ORTHO
    camera.update(depth_of_field(camera_object))
    return camera


def focus_distance(camera_object):
    """Camera.dof's focus distance in scene units, as Cycles takes it (blender/camera.cpp,
    blender_camera_focal_distance): with a Focus Object (and a bone of it, Focus Bone), that point's distance from the
    camera along the camera's view axis, else the Focus Distance."""
    dof = camera_object.data.dof
    target = dof.focus_object
    if target is None:
        return float(dof.focus_distance)
    matrix = target.matrix_world
    bone = target.pose.bones.get(dof.focus_subtarget) if target.pose and dof.focus_subtarget else None
    if bone is not None:
        matrix = matrix @ bone.matrix
    view_axis = camera_object.matrix_world.col[2].xyz.normalized()
    return abs(view_axis.dot(camera_object.matrix_world.translation - matrix.translation))


def depth_of_field(camera_object, lens=None):
    """The core's depth-of-field parameters of a camera object (Camera Properties > Depth of Field): empty when it
    has none (use_dof off, or an object other than a camera). `lens`: the focal length (mm) the core is given when it
    is not the camera's own (the viewport's, which includes its zoom): the f-stop is scaled so that the aperture keeps
    its size, lens / (2 f-stop) of the camera's own lens, as Cycles' viewport keeps it."""
    cam = camera_object.data
    if not isinstance(cam, bpy.types.Camera) or not cam.dof.use_dof:
        return {}
    dof = cam.dof
    fstop = float(dof.aperture_fstop)
    if lens is not None and cam.type != "ORTHO":
        fstop *= lens / cam.lens
    return {"use_dof": True, "focus_distance": focus_distance(camera_object), "aperture_fstop": fstop,
            "aperture_blades": int(dof.aperture_blades), "aperture_rotation": float(dof.aperture_rotation),
            "aperture_ratio": float(dof.aperture_ratio)}


def _hash_uint2(kx, ky):
    """Bob Jenkins' lookup3 hash of two 32-bit words (its final() mix), as Cycles' hash_uint2 (util/hash.h)."""
    mask = 0xFFFFFFFF

    def rot(x, k):
        return ((x << k) | (x >> (32 - k))) & mask

    a = b = c = (0xDEADBEEF + (2 << 2) + 13) & mask
    b = (b + (ky & mask)) & mask
    a = (a + (kx & mask)) & mask
    c ^= b; c = (c - rot(b, 14)) & mask
    a ^= c; a = (a - rot(c, 11)) & mask
    b ^= a; b = (b - rot(a, 25)) & mask
    c ^= b; c = (c - rot(b, 16)) & mask
    a ^= c; a = (a - rot(c, 4)) & mask
    b ^= a; b = (b - rot(a, 14)) & mask
    c ^= b; c = (c - rot(b, 24)) & mask
    return c


def frame_seed(scene):
    """The sampling seed of the scene's current frame: the scene's seed, or with Animate Seed Cycles' per-frame seed
    (intern/cycles/blender/sync.cpp, sync_integrator): hash_uint2(frame, seed), plus hash_uint2(subframe * INT_MAX,
    seed) on a subframe; 32 bits, as the core's seed is. A function of the frame alone, so that any worker of a farm
    renders a frame with the same seed."""
    settings = scene.raysplats
    if not settings.use_animated_seed:
        return settings.seed
    seed = _hash_uint2(scene.frame_current, settings.seed)
    if scene.frame_subframe != 0.0:
        seed += _hash_uint2(int(scene.frame_subframe * 2147483647.0), settings.seed)
    return seed & 0xFFFFFFFF


# The core's render settings (its table, core.render_settings()) reach it from Scene.raysplats by name: each is the
# property of the same name, except those below. So a new core setting is its property in render_properties.py, and
# this sync copies it; a core setting with neither a property nor a place below is an error here and in the tests.
# Settings made from Blender's own scene data (image size, samples per render kind, the frame's seed, Film >
# Transparent) or that apply only to the final render (adaptive sampling).
# denoising_data: on when the render denoises or writes the denoising passes (the callers say which).
# mist_pass, light_passes, shadow_catcher_pass and the Cryptomatte settings: from the view layer's passes
# (passes.core_settings), in final renders.
DERIVED_SETTINGS = frozenset({"width", "height", "samples", "seed", "transparent_background", "adaptive_sampling",
                              "adaptive_threshold", "adaptive_min_samples", "denoising_data", "mist_pass",
                              "light_passes", "shadow_catcher_pass", "cryptomatte_object", "cryptomatte_material",
                              "cryptomatte_asset", "cryptomatte_levels"})
# Settings the add-on leaves at the core's defaults: tuning and test switches that do not change the image, and the
# render region, which final.py sets from the render border.
CORE_ONLY_SETTINGS = frozenset({"tile_size", "gather_buffer_size", "jitter", "speculative_ends", "region_x",
                                "region_y", "region_width", "region_height"})


def copied_settings(core):
    """The names of the core's render settings copied from Scene.raysplats properties of the same name."""
    names = [s["name"] for s in core.render_settings()
             if s["name"] not in DERIVED_SETTINGS and s["name"] not in CORE_ONLY_SETTINGS]
    missing = [name for name in names if name not in RaySplatsRenderSettings.bl_rna.properties]
    if missing:
        raise errors.InternalError(f"render settings of the core without a Scene.raysplats property: "
                                   f"{', '.join(missing)} (add one in engine/render_properties.py)")
    return names


def render_settings(scene, width, height, samples, seed_offset=0, adaptive=False, denoising_data=False,
                    shadow_catcher_pass=False):
    """The core's render settings of the scene. `adaptive`: the final render's adaptive sampling settings apply (the
    viewport refines in passes of its own and leaves it off). `denoising_data`: the core fills the denoiser's guide
    channels (Denoising Albedo and Normal). `shadow_catcher_pass`: the render writes the Shadow Catcher pass (Combined
    then leaves shadow catchers transparent, as Cycles)."""
    settings = scene.raysplats
    values = {name: getattr(settings, name) for name in copied_settings(native.core())}
    values.update(width=width, height=height, samples=samples, seed=(frame_seed(scene) + seed_offset) & 0xFFFFFFFF,
                  transparent_background=bool(scene.render.film_transparent), denoising_data=bool(denoising_data),
                  shadow_catcher_pass=bool(shadow_catcher_pass))
    if adaptive and settings.use_adaptive_sampling:
        values.update(adaptive_sampling=True, adaptive_threshold=settings.adaptive_threshold,
                      adaptive_min_samples=settings.adaptive_min_samples)
    return values


def resolution(scene):
    scale = scene.render.resolution_percentage / 100.0
    return max(1, int(scene.render.resolution_x * scale)), max(1, int(scene.render.resolution_y * scale))


