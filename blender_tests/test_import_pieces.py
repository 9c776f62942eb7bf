# A scene imported in spatial pieces (creation.add_gaussian_pieces): one Gaussian object per piece under
# one empty that carries the scene's transform. The pieces together are the file (the same Gaussians as a one-object
# import, exported and rendered alike), each piece is a compact box of space, the empty moves them all, Tab edits them
# all, Export Selected with only the empty selected writes them all, and a failed import leaves nothing behind.
import unittest
from unittest import mock

import bpy
import numpy as np

import splat_testing as st
from raysplats.io import export_scope, import_policy, import_splats
from raysplats.objects import creation, polygon_mesh

SCENE = "unicorn_sh3_reordered.ply"  # 49,602 Gaussians, SH degree 3
PIECE = 10_000  # -> 5 pieces
KEYS = ("positions", "rotations", "scales", "opacities", "sh")


def rows_by_position(cloud):
    """The cloud's arrays with rows sorted by position (x, then y, then z): an order-free comparison."""
    order = np.lexsort(cloud["positions"].T[::-1])
    return {key: np.asarray(cloud[key])[order] for key in KEYS}


def import_pieces(**options):
    st.import_file(SCENE, up_axis="-Y", objects="PIECES", piece_size=PIECE, **options)
    root = bpy.context.view_layer.objects.active.parent
    return root, polygon_mesh.scene_pieces(root)


class ImportPieces(unittest.TestCase):
    def setUp(self):
        st.reset_scene()

    def test_auto_splits_only_meshes_above_one_and_a_half_million_vertices(self):
        self.assertEqual(import_policy.gaussians_per_piece("AUTO", 152_746, 8), 152_746)  # biker_v4: one object
        self.assertEqual(import_policy.gaussians_per_piece("AUTO", 187_500, 8), 187_500)  # 1.5 M vertices
        self.assertEqual(import_policy.gaussians_per_piece("AUTO", 187_501, 8), 50_000)
        self.assertEqual(import_policy.gaussians_per_piece("AUTO", 1_495_636, 4), 100_000)  # showroom: 15 pieces
        self.assertEqual(import_policy.gaussians_per_piece("ONE", 1_495_636, 4), 1_495_636)
        self.assertEqual(import_policy.gaussians_per_piece("PIECES", 49_602, 8), 50_000)
        self.assertEqual(import_policy.gaussians_per_piece("PIECES", 49_602, 8, piece_size=7), 7)
        with self.assertRaisesRegex(ValueError, "unknown Objects choice 'HALF'"):
            import_policy.gaussians_per_piece("HALF", 10, 8)
        self.assertEqual(bpy.ops.import_scene.gaussian_splats.get_rna_type().properties["objects"].default, "AUTO")

    def test_pieces_hold_the_file_under_one_empty_and_are_boxes_of_space(self):
        root, pieces = import_pieces()
        self.assertEqual(root.type, "EMPTY")
        self.assertEqual(root.name, "unicorn_sh3_reordered")
        self.assertEqual([p.name for p in pieces], [f"unicorn_sh3_reordered_{i}" for i in range(1, 6)])
        counts = [len(p.data.polygons) for p in pieces]
        self.assertTrue(all(9_000 <= n <= PIECE for n in counts), counts)
        visible = st.native().read_splats(st.data_file(SCENE))["opacities"] >= np.float32(1.0 / 255.0)
        self.assertEqual(sum(counts), int(np.count_nonzero(visible)))  # (invisible Gaussians get no polygon)
        for piece in pieces:
            self.assertIs(piece.parent, root)
            self.assertEqual(piece.matrix_parent_inverse, root.matrix_parent_inverse)  # identity: no hidden offset
            self.assertEqual(tuple(piece.location), (0.0, 0.0, 0.0))
            self.assertEqual(piece.raysplats.sh_degree, 3)
        # Boxes of space: the bounding boxes of the pieces' polygon centres overlap little (the polygons themselves
        # reach past their Gaussians' centres, so the boxes of the k-d split are checked on the centres).
        boxes = []
        for piece in pieces:
            c = np.empty(3 * len(piece.data.polygons), np.float32)
            piece.data.polygons.foreach_get("center", c)
            c = c.reshape(-1, 3)
            boxes.append((c.min(axis=0), c.max(axis=0)))
        volume = lambda lo, hi: float(np.prod(np.maximum(hi - lo, 0.0)))  # noqa: E731
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                overlap = volume(np.maximum(boxes[i][0], boxes[j][0]), np.minimum(boxes[i][1], boxes[j][1]))
                self.assertLess(overlap, 0.05 * min(volume(*boxes[i]), volume(*boxes[j])), (i, j))

    def test_selection_after_the_import_moves_the_whole_scene_and_tab_edits_every_piece(self):
        root, pieces = import_pieces()
        self.assertTrue(root.select_get())
        self.assertTrue(all(p.select_get() for p in pieces))
        self.assertIs(bpy.context.view_layer.objects.active, pieces[0])
        bpy.ops.object.mode_set(mode="EDIT")
        self.assertEqual(set(bpy.context.objects_in_mode), set(pieces))
        bpy.ops.object.mode_set(mode="OBJECT")

    def test_the_pieces_export_and_render_as_the_one_object_import(self):
        st.import_file(SCENE, up_axis="-Y", objects="ONE")
        one = rows_by_position(st.export_file("pieces_one.ply"))
        image_one = self._render("pieces_one")
        st.reset_scene()
        root, pieces = import_pieces()
        split = rows_by_position(st.export_file("pieces_split.ply"))
        for key in KEYS:
            np.testing.assert_array_equal(split[key], one[key], err_msg=key)
        image_split = self._render("pieces_split")
        mse = float(np.mean((image_split[..., :3] - image_one[..., :3]) ** 2))
        psnr = 10 * np.log10(float(np.max(image_one[..., :3])) ** 2 / max(mse, 1e-30))
        print(f"\n  {SCENE} in {len(pieces)} pieces against one object: PSNR {psnr:.1f} dB")
        self.assertGreater(psnr, 60.0)

    def _render(self, name):
        scene = bpy.context.scene
        scene.render.engine = "RAYSPLATS"
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 96, 72, 100
        scene.raysplats.samples = 4
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        camera.location = (0.0, -2.5, 0.4)
        camera.rotation_euler = (1.45, 0.0, 0.0)
        scene.camera = camera
        return st.render_to_array(name)

    def test_moving_the_empty_moves_every_piece_in_the_export(self):
        root, pieces = import_pieces()
        before = rows_by_position(st.export_file("pieces_before.ply"))
        root.location = (1.0, 2.0, 3.0)  # Blender +Z is the file's -Y (up axis -Y)
        bpy.context.view_layer.update()
        after = rows_by_position(st.export_file("pieces_after.ply"))
        np.testing.assert_allclose(after["positions"], before["positions"] + np.array([1.0, -3.0, 2.0]),
                                   atol=2e-5)

    def test_export_selected_with_only_the_empty_selected_writes_every_piece(self):
        root, pieces = import_pieces()
        for obj in bpy.context.view_layer.objects:
            obj.select_set(obj is root)
        self.assertEqual(set(export_scope.objects_in_scope(bpy.context, "SELECTED")), {root, *pieces})
        cloud = st.export_file("pieces_selected.ply", limit_to="SELECTED")
        self.assertEqual(len(cloud["opacities"]), sum(len(p.data.polygons) for p in pieces))

    def test_a_failed_import_leaves_no_piece_no_empty_and_no_mesh(self):
        fill = polygon_mesh.fill_mesh
        calls = []

        def fill_then_fail(mesh, polygons):
            calls.append(mesh.name)
            if len(calls) == 3:
                raise MemoryError("simulated: out of memory in the third piece")
            fill(mesh, polygons)

        objects, meshes = len(bpy.data.objects), len(bpy.data.meshes)
        with mock.patch.object(polygon_mesh, "fill_mesh", fill_then_fail):
            with self.assertRaises(import_policy.NotEnoughMemory):
                import_splats.import_gaussian_splats(bpy.context, st.data_file(SCENE), objects="PIECES",
                                                 piece_size=PIECE)
        self.assertEqual(len(calls), 3)
        self.assertEqual((len(bpy.data.objects), len(bpy.data.meshes)), (objects, meshes))


if __name__ == "__main__":
    unittest.main()
