# Edits made with Blender's own operators, modifiers and deformers; the exported Gaussians are checked
# against the analytically expected ones, computed here with numpy from the original file.
#
# Tolerances: object-level transforms act on the exact stored Gaussians (1e-5 relative covariance). Edits of
# the mesh itself go through float32 vertex positions: a vertex at distance |c| from the origin is stored to
# 2^-24 |c|, so a polygon of radius rho·s2 (s2 its smaller in-plane scale) is known to 2^-24 |c| / (rho s2)
# relative. Each Gaussian is allowed 1e-5 plus 20 times that noise floor; a real error (a wrong axis, scale
# or sign) is O(1) and fails regardless.
import math
import unittest

import bmesh
import bpy
import numpy as np

import splat_testing as st
from raysplats.blender.compat import TRANSFORM_ROTATE_SIGN

SCENE = "small_sh3_inria.ply"
EXACT_TOLERANCE = 1e-5
MESH_EDIT_TOLERANCE = None  # per Gaussian, from float32 resolution (see above)
# File (COLMAP, -Y up) -> Blender, written out independently of the add-on.
FILE_TO_BLENDER = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=np.float64)


def affine_gaussians(cloud, a4, planar):
    """Expected Gaussians after the affine map a4 (4x4): centres and full covariances.

    planar=False: the map acts on the whole Gaussian (object transforms): Σ' = A Σ Aᵀ.
    planar=True: the map acts on the polygon (mesh edits, modifiers). The polygon carries the two largest
    axes, so the in-plane part is A Σp Aᵀ, and the thickness rule of docs/design.md §5 adds the third axis along the
    new normal: s3' = thickness · sqrt(s1' s2'), thickness = s3 / sqrt(s1 s2) of the original."""
    a = a4[:3, :3]
    centres = cloud["positions"].astype(np.float64) @ a.T + a4[:3, 3]
    if not planar:
        return centres, np.einsum("ij,njk,lk->nil", a, st.covariances(cloud), a)
    in_plane = np.einsum("ij,njk,lk->nil", a, st.covariances(cloud, planar=True), a)
    values, vectors = np.linalg.eigh(in_plane)  # ascending: values[:, 0] ≈ 0 belongs to the normal
    s = np.sort(cloud["scales"].astype(np.float64), axis=1)
    thickness = s[:, 0] / np.sqrt(s[:, 1] * s[:, 2])
    s3_squared = thickness ** 2 * np.sqrt(np.maximum(values[:, 1], 0) * np.maximum(values[:, 2], 0))
    normals = vectors[:, :, 0]
    return centres, in_plane + s3_squared[:, None, None] * np.einsum("ni,nj->nij", normals, normals)


def random_directions(n, seed=1):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


class Edits(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        self.obj = st.import_file(SCENE, up_axis="Z")  # object transform = identity: mesh space = file space
        self.original = st.native().read_splats(st.data_file(SCENE))
        self.n = len(self.original["opacities"])

    def edit_mode(self, face_mask=None):
        """Enters Edit Mode with the faces in face_mask selected (all when None)."""
        mesh = self.obj.data
        mask = np.ones(len(mesh.polygons), dtype=bool) if face_mask is None else face_mask
        bpy.ops.object.mode_set(mode="OBJECT")
        mesh.vertices.foreach_set("select", np.zeros(len(mesh.vertices), dtype=bool))
        mesh.edges.foreach_set("select", np.zeros(len(mesh.edges), dtype=bool))
        mesh.polygons.foreach_set("select", mask)
        selected_vertices = np.zeros(len(mesh.vertices), dtype=bool)
        selected_vertices[np.repeat(np.nonzero(mask)[0] * 8, 8) + np.tile(np.arange(8), int(mask.sum()))] = True
        mesh.vertices.foreach_set("select", selected_vertices)
        bpy.context.view_layer.objects.active = self.obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.context.tool_settings.mesh_select_mode = (False, False, True)

    def assert_gaussians(self, exported, centres, sigmas, tolerance, what=""):
        err = st.relative_errors(st.covariances(exported), sigmas)
        extent = np.abs(centres).max(axis=1)
        if tolerance is None:
            s2 = np.sqrt(np.maximum(np.linalg.eigvalsh(sigmas)[:, 1], 1e-30))
            tolerance = 1e-5 + 20 * 2.0 ** -24 * extent / (3.0 * s2)
        worst = np.argmax(err / tolerance)
        self.assertTrue(np.all(err <= tolerance),
                        f"{what}: covariance error {err[worst]:.3g} > {np.broadcast_to(tolerance, err.shape)[worst]:.3g}"
                        f" for Gaussian {worst}")
        position_tolerance = 1e-5 * np.abs(centres).max() + 20 * 2.0 ** -24 * extent.max()
        np.testing.assert_allclose(exported["positions"], centres, atol=position_tolerance, err_msg=what)

    def assert_colours_follow(self, exported, original, rotation, indices=None, tolerance=2e-3):
        """Colour seen along d after the edit equals the original colour seen along Rᵀd."""
        idx = np.arange(len(original["opacities"])) if indices is None else indices
        d = random_directions(len(idx))
        seen = st.sh_colors(exported["sh"][idx], d)
        expected = st.sh_colors(original["sh"][idx], d @ rotation)  # rows: (Rᵀ d)ᵀ = dᵀ R
        np.testing.assert_allclose(seen, expected, atol=tolerance)

    def test_moving_rotating_and_scaling_faces(self):
        self.edit_mode()
        # An explicit pivot, so the expected map does not depend on how Blender picks one without a view.
        pivot = np.array([20.0, -30.0, 100.0])
        shift = np.array([10.0, -20.0, 5.0])
        bpy.ops.transform.translate(value=shift)
        bpy.ops.transform.rotate(value=0.7, orient_axis="Z", orient_type="GLOBAL", center_override=pivot)
        bpy.ops.transform.resize(value=(1.5, 0.8, 1.2), orient_type="GLOBAL", center_override=pivot)
        bpy.ops.object.mode_set(mode="OBJECT")
        exported = st.export_file("edit_transform.ply")

        # transform.rotate's direction differs between Blender versions (compat.TRANSFORM_ROTATE_SIGN).
        angle = TRANSFORM_ROTATE_SIGN * 0.7
        c, s = math.cos(angle), math.sin(angle)
        rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        linear = np.diag([1.5, 0.8, 1.2]) @ rotation
        a4 = np.eye(4)
        a4[:3, :3] = linear
        # x' = pivot + S R (x + shift - pivot)
        a4[:3, 3] = pivot + linear @ (shift - pivot)
        centres, sigmas = affine_gaussians(self.original, a4, planar=True)
        self.assert_gaussians(exported, centres, sigmas, MESH_EDIT_TOLERANCE, what="translate/rotate/resize")

    def test_rotating_faces_rotates_view_dependent_colour(self):
        self.edit_mode()
        bpy.context.scene.tool_settings.transform_pivot_point = "MEDIAN_POINT"
        bpy.ops.transform.rotate(value=1.1, orient_axis="X", orient_type="GLOBAL")
        bpy.ops.object.mode_set(mode="OBJECT")
        exported = st.export_file("edit_rotate_sh.ply")
        angle = TRANSFORM_ROTATE_SIGN * 1.1  # (see above)
        c, s = math.cos(angle), math.sin(angle)
        rotation = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        self.assert_colours_follow(exported, self.original, rotation)
        # Without following, the colours would differ by far more than the tolerance.
        d = random_directions(self.n)
        unrotated = np.abs(st.sh_colors(exported["sh"], d) - st.sh_colors(self.original["sh"], d)).max()
        self.assertGreater(unrotated, 0.05)

    def test_non_uniform_object_transform(self):
        st.reset_scene()
        self.obj = st.import_file(SCENE)  # default: -Y up, stored as the object's rotation
        self.obj.scale = (2.0, 0.5, 1.5)
        self.obj.location = (1.0, 2.0, 3.0)
        self.obj.rotation_euler.z = 0.4
        bpy.context.view_layer.update()
        exported = st.export_file("object_transform.ply")
        a4 = np.eye(4)
        a4[:3, :3] = FILE_TO_BLENDER.T
        a4 = a4 @ np.array(self.obj.matrix_world, dtype=np.float64)
        centres, sigmas = affine_gaussians(self.original, a4, planar=False)
        self.assert_gaussians(exported, centres, sigmas, EXACT_TOLERANCE, what="object transform")

    def test_object_rotation_rotates_view_dependent_colour(self):
        self.obj.rotation_euler = (0.3, -0.5, 1.2)
        bpy.context.view_layer.update()
        exported = st.export_file("object_rotation.ply", up_axis="Z")
        rotation = np.array(self.obj.matrix_world, dtype=np.float64)[:3, :3]
        self.assert_colours_follow(exported, self.original, rotation)

    def test_lattice_deformation(self):
        # The lattice must enclose every polygon vertex (outside it the deformation is no longer affine).
        vertices = np.empty(len(self.obj.data.vertices) * 3, dtype=np.float32)
        self.obj.data.vertices.foreach_get("co", vertices)
        vertices = vertices.reshape(-1, 3)
        low, high = vertices.min(axis=0).astype(np.float64), vertices.max(axis=0).astype(np.float64)
        lattice_data = bpy.data.lattices.new("Lattice")
        lattice_data.points_u = lattice_data.points_v = lattice_data.points_w = 2
        lattice_data.interpolation_type_u = lattice_data.interpolation_type_v = "KEY_LINEAR"
        lattice_data.interpolation_type_w = "KEY_LINEAR"
        lattice = bpy.data.objects.new("Lattice", lattice_data)
        bpy.context.scene.collection.objects.link(lattice)
        lattice.location = (low + high) / 2
        lattice.scale = (high - low) * 1.2
        # An affine deformation of the lattice points: trilinear interpolation keeps it affine inside.
        shear = np.array([[1.2, 0.3, 0.0], [0.0, 0.9, -0.2], [0.1, 0.0, 1.1]])
        offset = np.array([0.05, -0.02, 0.0])
        for point in lattice_data.points:
            p = np.array(point.co)
            point.co_deform = shear @ p + offset
        modifier = self.obj.modifiers.new("Lattice", "LATTICE")
        modifier.object = lattice
        bpy.context.view_layer.update()
        exported = st.export_file("lattice.ply")

        m_lattice = np.array(lattice.matrix_world, dtype=np.float64)
        deform = np.eye(4)
        deform[:3, :3], deform[:3, 3] = shear, offset
        a4 = m_lattice @ deform @ np.linalg.inv(m_lattice)
        centres, sigmas = affine_gaussians(self.original, a4, planar=True)
        self.assert_gaussians(exported, centres, sigmas, MESH_EDIT_TOLERANCE, what="lattice")

    def test_armature_deformation(self):
        armature_data = bpy.data.armatures.new("Armature")
        armature = bpy.data.objects.new("Armature", armature_data)
        bpy.context.scene.collection.objects.link(armature)
        bpy.context.view_layer.objects.active = armature
        bpy.ops.object.mode_set(mode="EDIT")
        bone = armature_data.edit_bones.new("Bone")
        bone.head, bone.tail = (0.0, 0.0, 0.0), (0.0, 0.0, 100.0)
        bpy.ops.object.mode_set(mode="POSE")
        pose_bone = armature.pose.bones["Bone"]
        pose_bone.rotation_mode = "XYZ"
        pose_bone.rotation_euler = (0.4, 0.0, -0.3)
        pose_bone.location = (5.0, 0.0, -3.0)
        bpy.ops.object.mode_set(mode="OBJECT")
        group = self.obj.vertex_groups.new(name="Bone")
        group.add(list(range(len(self.obj.data.vertices))), 1.0, "REPLACE")
        modifier = self.obj.modifiers.new("Armature", "ARMATURE")
        modifier.object = armature
        bpy.context.view_layer.update()
        exported = st.export_file("armature.ply")

        # Deform matrix of a fully weighted vertex: pose matrix times the inverse rest matrix (armature space).
        pose = np.array(armature.pose.bones["Bone"].matrix, dtype=np.float64)
        rest = np.array(armature_data.bones["Bone"].matrix_local, dtype=np.float64)
        a4 = pose @ np.linalg.inv(rest)
        centres, sigmas = affine_gaussians(self.original, a4, planar=True)
        self.assert_gaussians(exported, centres, sigmas, MESH_EDIT_TOLERANCE, what="armature")
        self.assert_colours_follow(exported, self.original, a4[:3, :3])

    def test_deleting_faces(self):
        mask = np.zeros(self.n, dtype=bool)
        mask[::3] = True
        self.edit_mode(mask)
        bpy.ops.mesh.delete(type="FACE")
        bpy.ops.object.mode_set(mode="OBJECT")
        exported = st.export_file("deleted.ply")
        kept = {key: value[~mask] for key, value in self.original.items() if isinstance(value, np.ndarray)}
        self.assertEqual(len(exported["opacities"]), int((~mask).sum()))
        centres, sigmas = affine_gaussians(kept, np.eye(4), planar=False)
        self.assert_gaussians(exported, centres, sigmas, EXACT_TOLERANCE, what="delete")
        np.testing.assert_allclose(exported["opacities"], kept["opacities"], rtol=1e-6)
        np.testing.assert_allclose(exported["sh"], kept["sh"], atol=1e-5)

    def test_duplicating_faces(self):
        mask = np.zeros(self.n, dtype=bool)
        mask[100:400] = True
        self.edit_mode(mask)
        bpy.ops.mesh.duplicate()
        bpy.ops.object.mode_set(mode="OBJECT")
        exported = st.export_file("duplicated.ply")
        self.assertEqual(len(exported["opacities"]), self.n + 300)
        copies = {key: value[mask] for key, value in self.original.items() if isinstance(value, np.ndarray)}
        tail = {key: value[self.n:] for key, value in exported.items() if isinstance(value, np.ndarray)}
        centres, sigmas = affine_gaussians(copies, np.eye(4), planar=False)
        self.assert_gaussians(tail, centres, sigmas, EXACT_TOLERANCE, what="duplicate")
        np.testing.assert_allclose(tail["opacities"], copies["opacities"], rtol=1e-6)
        np.testing.assert_allclose(tail["sh"], copies["sh"], atol=1e-5)

    def test_a_new_face_becomes_a_new_gaussian(self):
        self.edit_mode(np.zeros(self.n, dtype=bool))
        bm = bmesh.from_edit_mesh(self.obj.data)
        a, b, centre = 6.0, 2.0, np.array([50.0, -40.0, 30.0])
        corners = [(a, b), (-a, b), (-a, -b), (a, -b)]
        for vertex in bm.verts:
            vertex.select = False
        for x, y in corners:
            bm.verts.new((centre[0] + x, centre[1] + y, centre[2])).select = True
        bmesh.update_edit_mesh(self.obj.data)
        bpy.ops.mesh.edge_face_add()
        bpy.ops.object.mode_set(mode="OBJECT")
        exported = st.export_file("new_face.ply")
        self.assertEqual(len(exported["opacities"]), self.n + 1)
        new = {key: value[-1:] for key, value in exported.items() if isinstance(value, np.ndarray)}
        np.testing.assert_allclose(new["positions"][0], centre, atol=1e-4)
        # Rectangle (±a, ±b): C = diag(a², b², 0) = (rho²/2) diag(s1², s2², 0), rho = 3.
        sigma = st.covariances(new, planar=True)[0]
        np.testing.assert_allclose(sigma, np.diag([2 * a * a / 9, 2 * b * b / 9, 0]), atol=1e-4)
        self.assertAlmostEqual(float(new["opacities"][0]), st.native().NEW_FACE_OPACITY, places=6)
        np.testing.assert_allclose(new["sh"], 0.0)

    def test_mirror_modifier(self):
        modifier = self.obj.modifiers.new("Mirror", "MIRROR")
        modifier.use_axis = (True, False, False)
        modifier.use_mirror_merge = False
        bpy.context.view_layer.update()
        exported = st.export_file("mirror.ply")
        self.assertEqual(len(exported["opacities"]), 2 * self.n)
        reflect = np.diag([-1.0, 1.0, 1.0, 1.0])
        mirrored = {key: value[self.n:] for key, value in exported.items() if isinstance(value, np.ndarray)}
        centres, sigmas = affine_gaussians(self.original, reflect, planar=True)
        self.assert_gaussians(mirrored, centres, sigmas, MESH_EDIT_TOLERANCE, what="mirror")
        rotations = st.rotation_matrices(mirrored["rotations"])
        np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-5)
        originals = {key: value[:self.n] for key, value in exported.items() if isinstance(value, np.ndarray)}
        centres, sigmas = affine_gaussians(self.original, np.eye(4), planar=False)
        self.assert_gaussians(originals, centres, sigmas, EXACT_TOLERANCE, what="mirror source")
