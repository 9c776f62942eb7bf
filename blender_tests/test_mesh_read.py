# Reading a Gaussian mesh back (polygon_mesh.mesh_arrays): the fast reads (attributes on 4.x, Blender's loop and face
# arrays in place) give exactly what Blender's own foreach_get gives, after edits of the positions and of the
# topology, on empty meshes, and through the foreach_get fallback when the loop or face layout is not the expected one.
import contextlib
import io
import os
import unittest
from unittest import mock

import bmesh
import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import blender_memory, compat, mesh_read
from raysplats.objects import polygon_mesh

SCENE = "donut_sh0.ply"
# How each Blender reads when nothing is wrong: positions are the "position" attribute from 3.5 on, corner vertices
# the ".corner_vert" attribute from 3.6 on; before, MLoop structs read in place.
POSITIONS_PATH = "attribute" if compat.MESH_POSITIONS_ARE_AN_ATTRIBUTE else "foreach_get"
CORNERS_PATH = "attribute" if compat.MESH_TOPOLOGY_IN_INT32_ARRAYS else "pointer"
FACES_PATH = "pointer"  # MPoly structs before 3.6, the face offsets from then on, in place


def foreach_get_arrays(mesh):
    """Positions, corner vertices, face starts and sizes of `mesh` as Blender's foreach_get gives them."""
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", positions)
    corners = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", corners)
    starts, counts = (np.empty(len(mesh.polygons), dtype=np.int64) for _ in range(2))
    mesh.polygons.foreach_get("loop_start", starts)
    mesh.polygons.foreach_get("loop_total", counts)
    return positions.reshape(-1, 3), corners, starts, counts


def edit_faces(obj, faces, operator):
    """Runs `operator` in Edit Mode with exactly `faces` selected, and returns to Object Mode."""
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    st.select_faces(obj, faces)
    operator()
    bpy.ops.object.mode_set(mode="OBJECT")


def evaluated_mesh(obj):
    """The mesh the render engine reads (the evaluated object's data), after the pending updates."""
    bpy.context.view_layer.update()
    return obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data


def move_faces(obj, faces, offset):
    """Moves the faces of obj (in Edit Mode) with Blender's own operator, as a user moves them."""
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    st.select_faces(obj, faces)
    bmesh.update_edit_mesh(obj.data)
    bpy.ops.transform.translate(value=offset)


class MeshRead(unittest.TestCase):
    def setUp(self):
        st.reset_scene()

    def tearDown(self):
        mesh_read._loop_layout_failed = False
        mesh_read._face_layout_failed = False
        mesh_read._bmesh_layout_failed = False
        mesh_read._bmesh_offsets = None
        mesh_read._bmesh_checked.clear()
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")

    def assert_reads_like_foreach_get(self, mesh, arrays, positions_path=POSITIONS_PATH, corners_path=CORNERS_PATH,
                                      faces_path=FACES_PATH):
        """`arrays` (of mesh_arrays) and each fast reader on its own equal foreach_get's arrays of `mesh`, and the
        readers took the expected paths."""
        expected = foreach_get_arrays(mesh)
        for name, actual, wanted in zip(("positions", "corner vertices", "face starts", "face sizes"), arrays,
                                        expected):
            self.assertEqual(actual.shape, wanted.shape, name)
            self.assertTrue(np.array_equal(actual, wanted), name)
        positions = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        self.assertEqual(mesh_read.read_vertex_positions(mesh, positions), positions_path)
        self.assertTrue(np.array_equal(positions, expected[0].ravel()))
        corners = np.empty(len(mesh.loops), dtype=compat.MESH_INDEX_DTYPE)
        self.assertEqual(mesh_read.read_corner_vertices(mesh, corners), corners_path)
        self.assertTrue(np.array_equal(corners, expected[1]))
        starts, sizes = (np.empty(len(mesh.polygons), dtype=np.int32) for _ in range(2))
        self.assertEqual(mesh_read.read_face_corners(mesh, sizes, starts), faces_path)
        self.assertTrue(np.array_equal(starts, expected[2]) and np.array_equal(sizes, expected[3]))
        return expected

    def test_fast_reads_equal_foreach_get_after_moving_flipping_and_deleting_faces(self):
        obj = st.import_file(SCENE)
        faces = len(obj.data.polygons)
        first = polygon_mesh.mesh_arrays(evaluated_mesh(obj))
        self.assert_reads_like_foreach_get(evaluated_mesh(obj), first)

        # Vertex positions change (the corners of face 10 move), read as the viewport does: into the arrays of an
        # older read (`spare`, overwritten), with the face starts taken over from the read before the edit.
        co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
        obj.data.vertices.foreach_get("co", co)
        co.reshape(-1, 3)[80:88] += (0.0, 0.0, 0.05)
        obj.data.vertices.foreach_set("co", co)
        obj.data.update()
        spare = tuple(np.copy(a) for a in first)
        moved = polygon_mesh.mesh_arrays(evaluated_mesh(obj), spare, first)
        self.assert_reads_like_foreach_get(evaluated_mesh(obj), moved)
        self.assertFalse(np.array_equal(moved[0], first[0]))
        self.assertTrue(all(np.shares_memory(new, old) for new, old in zip(moved[:2], spare[:2])))
        self.assertIs(moved[2], first[2])

        # Every 5th face's corners reversed: the corners are no longer 0, 1, 2, ... as after the import, so a read of
        # the wrong values or of the arrays from before the edit would show.
        edit_faces(obj, range(0, faces, 5), bpy.ops.mesh.flip_normals)
        flipped = polygon_mesh.mesh_arrays(evaluated_mesh(obj), first, moved)
        expected = self.assert_reads_like_foreach_get(evaluated_mesh(obj), flipped)
        self.assertFalse(np.array_equal(expected[1], moved[1]))
        self.assertTrue(np.array_equal(np.sort(expected[1][:8]), moved[1][:8]))

        # A face deleted: every array changes size.
        edit_faces(obj, [3], lambda: bpy.ops.mesh.delete(type="FACE"))
        deleted = polygon_mesh.mesh_arrays(evaluated_mesh(obj), moved, flipped)
        self.assert_reads_like_foreach_get(evaluated_mesh(obj), deleted)
        self.assertEqual(len(deleted[3]), faces - 1)

        # Faces 20 and 21 triangulated: faces of 3 corners among those of 8, so the starts no longer step by 8.
        edit_faces(obj, [20, 21], lambda: bpy.ops.mesh.quads_convert_to_tris(ngon_method="BEAUTY"))
        triangulated = polygon_mesh.mesh_arrays(evaluated_mesh(obj), flipped, deleted)
        expected = self.assert_reads_like_foreach_get(evaluated_mesh(obj), triangulated)
        self.assertEqual(len(triangulated[3]), faces - 1 + 2 * 5)
        self.assertEqual(set(expected[3].tolist()), {3, 8})

    def test_evaluated_geometry_is_read_from_the_datablock_only_where_evaluation_leaves_it_as_is(self):
        """mesh_read.evaluated_mesh: before 3.6 an object that evaluation leaves as it is reads from its
        evaluated Mesh datablock (no copy); one with shape keys, a modifier or a deforming parent from its evaluated
        mesh. Either way what is read is the evaluated mesh's geometry and attributes, also right after an edit."""
        shortcut = compat.EVALUATED_MESH_COPIES_ON_READ
        obj = st.import_file(SCENE)
        original = foreach_get_arrays(obj.data)[0]

        def read():
            """(read from the datablock?, positions, opacities) of `obj`, checked against the evaluated mesh's."""
            bpy.context.view_layer.update()
            depsgraph = bpy.context.evaluated_depsgraph_get()
            evaluated = obj.evaluated_get(depsgraph)
            mesh = mesh_read.evaluated_mesh(evaluated, depsgraph)
            arrays = polygon_mesh.mesh_arrays(mesh)
            attributes = polygon_mesh.face_attributes(mesh, 0)
            for actual, wanted in zip(arrays, foreach_get_arrays(evaluated.data)):
                self.assertTrue(np.array_equal(actual, wanted))
            opacities = np.empty(len(evaluated.data.polygons), dtype=np.float32)
            evaluated.data.attributes[polygon_mesh.ATTR_OPACITY].data.foreach_get("value", opacities)
            self.assertTrue(np.array_equal(attributes["opacity"], opacities))
            # (From 5.3 on an object that evaluation leaves as it is has its evaluated datablock as its evaluated
            # mesh: read from the evaluated mesh, that is the datablock too, and is no shortcut.)
            shortcut_taken = mesh == obj.data.evaluated_get(depsgraph) and mesh != evaluated.data
            return shortcut_taken, arrays[0], attributes["opacity"]

        from_datablock, positions, _ = read()
        self.assertEqual(from_datablock, shortcut)
        self.assertTrue(np.array_equal(positions, original))
        # Positions and an attribute edited in one update.
        co = original.copy()
        co[80:88] += (0.0, 0.0, 0.05)
        obj.data.vertices.foreach_set("co", co.ravel())
        obj.data.attributes[polygon_mesh.ATTR_OPACITY].data[7].value = 0.02
        obj.data.update()
        from_datablock, positions, opacities = read()
        self.assertEqual(from_datablock, shortcut)
        self.assertTrue(np.array_equal(positions, co))
        self.assertEqual(float(opacities[7]), np.float32(0.02))

        # Evaluation that moves the vertices: the datablock's positions would be stale.
        obj.shape_key_add(name="Basis")
        lift = obj.shape_key_add(name="Lift")
        lift.data.foreach_set("co", (co + (0.0, 0.0, 0.1)).ravel())
        lift.value = 1.0
        from_datablock, positions, _ = read()
        self.assertFalse(from_datablock)
        self.assertTrue(np.allclose(positions, co + (0.0, 0.0, 0.1)))
        obj.shape_key_clear()
        self.assertEqual(read()[0], shortcut)

        displace = obj.modifiers.new("Displace", "DISPLACE")
        from_datablock, positions, _ = read()
        self.assertFalse(from_datablock)
        self.assertFalse(np.allclose(positions, co))
        obj.modifiers.remove(displace)
        self.assertEqual(read()[0], shortcut)

        # Parenting with deformation (Blender's PARSKEL, as older files have it; the Parent operators add a modifier
        # instead) stands for a virtual deform modifier: the evaluated mesh is read.
        lattice = bpy.data.objects.new("Lattice", bpy.data.lattices.new("Lattice"))
        bpy.context.scene.collection.objects.link(lattice)
        obj.parent, obj.parent_type = lattice, "LATTICE"
        self.assertFalse(read()[0])
        obj.parent_type = "OBJECT"
        self.assertEqual(read()[0], shortcut)

    def test_empty_meshes(self):
        empty = bpy.data.meshes.new("empty")
        arrays = polygon_mesh.mesh_arrays(empty)
        self.assertEqual([a.shape for a in arrays], [(0, 3), (0,), (0,), (0,)])
        self.assert_reads_like_foreach_get(empty, arrays, "foreach_get", "foreach_get", "foreach_get")
        # One corner: too few to check the loop array's layout against (foreach_get reads it), which is no reason
        # to give up the fast path for the next mesh.
        single = bpy.data.meshes.new("single corner")
        single.vertices.add(1)
        single.loops.add(1)
        single.polygons.add(1)
        single.polygons[0].loop_start = 0
        if compat.FACE_CORNER_COUNT_IS_WRITABLE:
            single.polygons[0].loop_total = 1
        arrays = polygon_mesh.mesh_arrays(single)
        self.assertEqual([a.shape for a in arrays], [(1, 3), (1,), (1,), (1,)])
        self.assert_reads_like_foreach_get(single, arrays, POSITIONS_PATH,
                                           "attribute" if CORNERS_PATH == "attribute" else "foreach_get", "foreach_get")
        obj = st.import_file(SCENE)
        self.assert_reads_like_foreach_get(obj.data, polygon_mesh.mesh_arrays(obj.data))

    def test_foreach_get_reads_when_the_loop_layout_check_fails(self):
        obj = st.import_file(SCENE)
        # All faces reversed: now no corner's vertex index equals its edge index (both were the corner's own index
        # after the import), so reading the wrong field of 3.x's MLoop {v, e} gives wrong values.
        edit_faces(obj, range(len(obj.data.polygons)), bpy.ops.mesh.flip_normals)
        mesh = obj.data
        expected = foreach_get_arrays(mesh)[1]

        def read():
            corners = np.empty(len(mesh.loops), dtype=compat.MESH_INDEX_DTYPE)
            path = mesh_read.read_corner_vertices(mesh, corners)
            self.assertTrue(np.array_equal(corners, expected), path)
            return path

        # The loop array in place is also what 4.x reads when the attribute is missing.
        with mock.patch.object(compat, "MESH_CORNER_VERTEX_ATTRIBUTE", "no such attribute"):
            self.assertEqual(read(), "pointer")
            with mock.patch.object(compat, "LOOP_STRIDE", compat.LOOP_STRIDE + 4):
                self.assertEqual(read(), "foreach_get")
            self.assertEqual(read(), "foreach_get")  # this Blender's layout failed once: not tried again
            mesh_read._loop_layout_failed = False
            self.assertEqual(read(), "pointer")
            # The vertex index looked for 4 bytes into each element: 3.x's MLoop.e, which only the spot checks
            # catch (the stride is right); on 4.x past the 4-byte element.
            with mock.patch.object(compat, "LOOP_VERTEX_OFFSET", 4):
                self.assertEqual(read(), "foreach_get")
            self.assertTrue(mesh_read._loop_layout_failed)

    def test_foreach_get_reads_when_the_face_layout_check_fails(self):
        obj = st.import_file(SCENE)
        # Faces 20 and 21 triangulated, so that the face sizes are not all alike.
        edit_faces(obj, [20, 21], lambda: bpy.ops.mesh.quads_convert_to_tris(ngon_method="BEAUTY"))
        mesh = obj.data
        expected = foreach_get_arrays(mesh)[2:]

        def read():
            starts, sizes = (np.empty(len(mesh.polygons), dtype=np.int32) for _ in range(2))
            path = mesh_read.read_face_corners(mesh, sizes, starts)
            self.assertTrue(np.array_equal(starts, expected[0]) and np.array_equal(sizes, expected[1]), path)
            return path

        self.assertEqual(read(), "pointer")
        with mock.patch.object(compat, "FACE_STRIDE", compat.FACE_STRIDE + 4):
            self.assertEqual(read(), "foreach_get")
        self.assertEqual(read(), "foreach_get")  # this Blender's layout failed once: not tried again
        mesh_read._face_layout_failed = False
        self.assertEqual(read(), "pointer")
        # The face's size looked for in the wrong field: 3.x's MPoly.loopstart, which only the spot checks catch (the
        # stride is right); from 3.6 on the offsets themselves taken for sizes.
        with mock.patch.object(compat, "FACE_SIZE_OFFSET", 0):
            self.assertEqual(read(), "foreach_get")
        self.assertTrue(mesh_read._face_layout_failed)
        mesh_read._face_layout_failed = False
        # The first corner looked for 4 bytes in: 3.x's MPoly.totloop, past the 4-byte element from 3.6 on.
        with mock.patch.object(compat, "FACE_START_OFFSET", 4):
            self.assertEqual(read(), "foreach_get")

    def test_edit_mode_positions_are_read_from_the_bmesh_while_the_faces_stay_as_they_were(self):
        """mesh_read.read_edit_mode_positions reads Edit Mode positions in place from the BMesh: exactly what
        Blender's own conversion (to_mesh) gives after a move, "topology" once faces were reversed, deleted or added,
        and "unavailable" (never a wrong read) when the BMesh is not laid out as compat says."""
        obj = st.import_file(SCENE)
        topology = polygon_mesh.mesh_arrays(obj.data)[1:]
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")

        def read(arrays=topology):
            positions = np.full((len(bmesh.from_edit_mesh(obj.data).verts), 3), np.nan, dtype=np.float32)
            return mesh_read.read_edit_mode_positions(obj.data, positions, *arrays), positions

        def converted():
            """Positions and topology as Blender's conversion of the edit mesh gives them."""
            bpy.context.view_layer.update()
            evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
            try:
                return tuple(np.copy(a) for a in polygon_mesh.mesh_arrays(evaluated.to_mesh()))
            finally:
                evaluated.to_mesh_clear()

        path, positions = read()
        self.assertEqual(path, "read")
        self.assertTrue(np.array_equal(positions, converted()[0]))
        # A few faces moved by Blender's own operator (as a user moves them).
        move_faces(obj, (5, 6, 700), (0.0, 0.0, 0.05))
        path, moved = read()
        self.assertEqual(path, "read")
        expected = converted()
        self.assertTrue(np.array_equal(moved, expected[0]))
        self.assertEqual(int(np.any(moved != positions, axis=1).sum()), 3 * 8)
        # The layout checked wrongly (a BMVert's position looked for 4 bytes off): nothing is read, and the reader is
        # not tried again; the caller converts the mesh instead.
        mesh_read._bmesh_checked.clear()
        layout = dict(compat.BMESH_LAYOUT, vert_co=compat.BMESH_LAYOUT["vert_co"] + 4)
        with mock.patch.object(compat, "BMESH_LAYOUT", layout):
            self.assertEqual(read()[0], "unavailable")
        self.assertEqual(read()[0], "unavailable")
        mesh_read._bmesh_layout_failed = False
        self.assertEqual(read()[0], "read")
        # Corners reversed (same counts), a face deleted, faces added: the topology differs from the caller's.
        bpy.ops.mesh.flip_normals()
        self.assertEqual(read()[0], "topology")
        flipped = converted()
        path, positions = read(flipped[1:])
        self.assertEqual(path, "read")
        self.assertTrue(np.array_equal(positions, flipped[0]))
        bpy.ops.mesh.delete(type="FACE")
        self.assertEqual(read(flipped[1:])[0], "topology")
        bpy.ops.mesh.select_all(action="DESELECT")
        bpy.ops.mesh.primitive_plane_add()
        self.assertEqual(read(flipped[1:])[0], "topology")
        path, positions = read(converted()[1:])
        self.assertEqual(path, "read")
        self.assertTrue(np.array_equal(positions, converted()[0]))
        bpy.ops.object.mode_set(mode="OBJECT")
        positions = np.empty((len(obj.data.vertices), 3), dtype=np.float32)
        self.assertEqual(mesh_read.read_edit_mode_positions(obj.data, positions, *topology), "unavailable")

    def test_the_bmesh_probe_finds_the_offsets_of_the_table_and_searches_them_on_a_newer_blender(self):
        """The probe confirms compat's offsets of bmesh's Python objects on a known BMesh; with a wrong table it finds
        nothing on a tested Blender (the table is what it checks), and on a Blender newer than the ones tested it
        finds the right offsets among the candidates. Every candidate is read safely: no wrong one crashes Blender."""
        table = (compat.BPY_BMESH_POINTER_OFFSET, compat.BPY_BMELEM_POINTER_OFFSET)
        self.assertTrue(blender_memory.available())
        self.assertEqual(mesh_read.probe_bmesh_layout(), table)
        with mock.patch.object(compat, "BPY_BMESH_POINTER_OFFSET", 40), \
                mock.patch.object(compat, "BPY_BMELEM_POINTER_OFFSET", 48):
            self.assertIsNone(mesh_read.probe_bmesh_layout())
            with mock.patch.object(compat, "NEWER_THAN_TESTED", True):
                self.assertEqual(mesh_read.probe_bmesh_layout(), table)
        # A BMesh field off by 4 bytes is found wrong whatever the offsets.
        with mock.patch.object(compat, "BMESH_LAYOUT", dict(compat.BMESH_LAYOUT, loop_next=60)), \
                mock.patch.object(compat, "NEWER_THAN_TESTED", True):
            self.assertIsNone(mesh_read.probe_bmesh_layout())
        # Unmapped memory is an error, not a crash.
        with self.assertRaises(blender_memory.MemoryUnreadable):
            blender_memory.pointer_at(16)
        # Without /proc (Windows): nothing can be read safely, so the probe finds nothing and reads nothing.
        with mock.patch.object(blender_memory.sys, "platform", "win32"), \
                mock.patch.object(blender_memory, "_opened", False), mock.patch.object(blender_memory, "_mem_fd", None):
            self.assertFalse(blender_memory.available())
            self.assertIsNone(mesh_read.probe_bmesh_layout())
            with self.assertRaises(blender_memory.MemoryUnreadable):
                blender_memory.pointer_at(id(self))
        self.assertTrue(blender_memory.available())

    def test_a_failed_bmesh_probe_falls_back_to_the_python_api_with_one_warning_and_the_same_arrays(self):
        """The viewport's Edit Mode read (sync's _read) after a move gives the same arrays from the BMesh in place
        as through Blender's conversion, which it takes, with one warning, when the probe fails (a wrong offset in
        compat's table) or memory may not be read (RAYSPLATS_DISTRUST_BLENDER_MEMORY)."""
        from raysplats.engine import sync
        obj = st.import_file(SCENE)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        depsgraph = bpy.context.evaluated_depsgraph_get()
        scene_sync = sync.SceneSync(depsgraph, interactive=True)
        first = scene_sync._read(obj.evaluated_get(depsgraph), depsgraph)
        move_faces(obj, (3, 4, 500), (0.0, 0.04, 0.0))
        bpy.context.view_layer.update()
        reads = []
        reader = mesh_read.read_edit_mode_positions

        def counted_reader(*args):
            reads.append(reader(*args))
            return reads[-1]

        def read_arrays():
            mesh_read._bmesh_offsets = None
            mesh_read._bmesh_layout_failed = False
            mesh_read._bmesh_checked.clear()
            blender_memory._warned.clear()
            stderr = io.StringIO()
            with mock.patch.object(mesh_read, "read_edit_mode_positions", side_effect=counted_reader), \
                    contextlib.redirect_stderr(stderr):
                source = scene_sync._read(obj.evaluated_get(depsgraph), depsgraph, previous=first)
                scene_sync._read(obj.evaluated_get(depsgraph), depsgraph, previous=first)
            return [np.copy(a) for a in source.arrays], stderr.getvalue()

        fast, warnings = read_arrays()
        self.assertEqual(reads, ["read", "read"])
        self.assertEqual(warnings, "")
        self.assertFalse(np.array_equal(fast[0], first.arrays[0]))  # the move shows
        broken = (mock.patch.object(compat, "BPY_BMESH_POINTER_OFFSET", 40),
                  mock.patch.object(compat, "BPY_BMELEM_POINTER_OFFSET", 48))
        distrust = (mock.patch.dict(os.environ, {blender_memory.DISTRUST_VARIABLE: "1"}),)
        for patches in (broken, distrust):
            reads.clear()
            with contextlib.ExitStack() as stack:
                for patch in patches:
                    stack.enter_context(patch)
                slow, warnings = read_arrays()
            self.assertEqual(reads, ["unavailable", "unavailable"])
            self.assertEqual(warnings.count("warning"), 1, warnings)
            self.assertIn("Edit Mode" if patches is broken else blender_memory.DISTRUST_VARIABLE, warnings)
            self.assertEqual(len(slow), len(fast))
            for a, b in zip(slow, fast):
                self.assertTrue(np.array_equal(a, b))
