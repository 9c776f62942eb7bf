# Object > Convert between our Gaussian objects and Blender 5.3's own Gaussian splat point clouds
# (tools/convert_splats.py, in the layout of objects/blender_splats.py).
# These tests check the attribute layout 5.3's importers write (scale linear, rotation w x y z, radiance:base = SH DC
# + opacity, radiance:sh_k = coefficient k + 1) on what each Blender holds: a mesh whose points carry those attributes
# below 5.3, a Gaussian-splat point cloud on 5.3 (test_blender_splats.py compares with 5.3's own importer).
import unittest

import bpy
import numpy as np

from raysplats.blender import compat
from raysplats.objects import blender_splats, polygon_mesh
from splat_testing import covariances, data_file, native, relative_errors, reset_scene

SH_REST = 15  # degree 3: 15 coefficients beyond the DC term


def world_gaussians(obj):
    """The Gaussians of our object `obj` in world coordinates (the core's dict)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return polygon_mesh.recover_object_gaussians(native(), obj, depsgraph, np.array(obj.matrix_world, np.float64))


def select_only(obj):
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def attribute_values(data, name, count):
    attribute = data.attributes[name]
    width = {"FLOAT_VECTOR": 3, "FLOAT_COLOR": 4, "QUATERNION": 4, "FLOAT4": 4}[attribute.data_type]
    values = np.empty(count * width, np.float32)
    attribute.data.foreach_get(compat.ATTRIBUTE_VALUE_KEY[attribute.data_type], values)
    return values.reshape((count, width))


class HandMadeSplatCloud(unittest.TestCase):
    """A splat cloud written attribute by attribute, as Blender 5.3's PLY importer lays it out, becomes our object
    with exactly those Gaussians."""

    def setUp(self):
        reset_scene()
        rng = np.random.default_rng(7)
        self.count = 40
        self.positions = rng.uniform(-2, 2, (self.count, 3)).astype(np.float32)
        # Three clearly different linear scales (the PLY's exp(log scale)), so each Gaussian has one frame.
        self.scales = np.stack([rng.uniform(0.20, 0.30, self.count), rng.uniform(0.08, 0.12, self.count),
                                rng.uniform(0.01, 0.02, self.count)], axis=1).astype(np.float32)
        rotations = rng.normal(size=(self.count, 4))
        self.rotations = (rotations / np.linalg.norm(rotations, axis=1, keepdims=True)).astype(np.float32)
        self.opacities = rng.uniform(0.1, 1.0, self.count).astype(np.float32)
        self.sh = rng.normal(0, 0.3, (self.count, SH_REST + 1, 3)).astype(np.float32)

        mesh = bpy.data.meshes.new("hand made")
        mesh.vertices.add(self.count)
        mesh.vertices.foreach_set("co", self.positions.ravel())

        def add(name, data_type, values):
            attribute = mesh.attributes.new(name, data_type, "POINT")
            attribute.data.foreach_set(compat.ATTRIBUTE_VALUE_KEY[data_type], values.astype(np.float32).ravel())

        add("scale", "FLOAT_VECTOR", self.scales)
        add("rotation", compat.QUATERNION_ATTRIBUTE_TYPE, self.rotations)
        add("radiance:base", compat.FLOAT4_ATTRIBUTE_TYPE,
            np.concatenate([self.sh[:, 0, :], self.opacities[:, None]], axis=1))
        for k in range(SH_REST):
            add(f"radiance:sh_{k}", "FLOAT_VECTOR", self.sh[:, k + 1, :])
        self.splats = bpy.data.objects.new("hand made", mesh)
        bpy.context.scene.collection.objects.link(self.splats)
        self.splats.location = (1.0, -2.0, 0.5)
        self.splats.rotation_euler = (0.3, -0.2, 1.1)
        self.splats.scale = (2.0, 2.0, 2.0)

    def test_converts_to_a_gaussian_object_with_the_same_gaussians(self):
        self.assertTrue(blender_splats.is_blender_splat_object(self.splats))
        select_only(self.splats)
        bpy.context.view_layer.update()  # matrix_world follows location/rotation/scale on evaluation
        matrix = np.array(self.splats.matrix_world)
        self.assertEqual(bpy.ops.object.raysplats_from_native_splats(), {"FINISHED"})
        obj = bpy.context.active_object
        self.assertTrue(polygon_mesh.is_gaussian_object(obj))
        self.assertNotIn("hand made", [o.name for o in bpy.data.objects if not polygon_mesh.is_gaussian_object(o)],
                         "the splat object should be replaced (Keep Original is off)")
        np.testing.assert_allclose(np.array(obj.matrix_world), matrix, atol=1e-6)
        self.assertEqual(obj.raysplats.sh_degree, 3)
        # In object space the Gaussians are the hand-made ones: the scales were taken as linear, the quaternions as
        # w x y z, radiance:base as SH DC + opacity and radiance:sh_k as coefficient k + 1.
        ours = polygon_mesh.recover_object_gaussians(native(), obj, bpy.context.evaluated_depsgraph_get(), np.eye(4))
        expected = {"rotations": self.rotations, "scales": self.scales}
        np.testing.assert_allclose(ours["positions"], self.positions, atol=1e-5)
        self.assertLess(relative_errors(covariances(ours), covariances(expected)).max(), 1e-4)
        np.testing.assert_allclose(ours["opacities"], self.opacities, atol=1e-6)
        np.testing.assert_allclose(ours["sh"], self.sh, atol=1e-4)

    def test_a_mesh_without_the_splat_attributes_is_not_converted(self):
        plain = bpy.data.objects.new("plain", bpy.data.meshes.new("plain"))
        bpy.context.scene.collection.objects.link(plain)
        plain.data.vertices.add(3)
        self.assertFalse(blender_splats.is_blender_splat_object(plain))
        select_only(plain)
        self.assertFalse(bpy.ops.object.raysplats_from_native_splats.poll())


class RoundTrip(unittest.TestCase):
    """Our object -> Blender splats -> our object keeps every Gaussian (float precision) and the transform."""

    def test_round_trip_of_a_real_scene(self):
        reset_scene()
        bpy.ops.import_scene.gaussian_splats(filepath=data_file("small_sh3_inria.ply"), max_count=3000)
        obj = bpy.context.active_object
        obj.location = (0.5, 1.0, -0.25)
        obj.scale = (1.5, 1.5, 1.5)
        bpy.context.view_layer.update()
        before = world_gaussians(obj)
        count = len(before["opacities"])
        name = obj.name

        select_only(obj)
        self.assertEqual(bpy.ops.object.raysplats_to_native_splats(), {"FINISHED"})
        splats = bpy.context.active_object
        self.assertTrue(blender_splats.is_blender_splat_object(splats))
        data = splats.data
        self.assertEqual(compat.point_count(data), count)
        # The layout Blender 5.3 renders: names and types.
        self.assertEqual(data.attributes["scale"].data_type, "FLOAT_VECTOR")
        self.assertEqual(data.attributes["rotation"].data_type, compat.QUATERNION_ATTRIBUTE_TYPE)
        self.assertEqual(data.attributes["radiance:base"].data_type, compat.FLOAT4_ATTRIBUTE_TYPE)
        self.assertEqual(sorted(a.name for a in data.attributes if a.name.startswith("radiance:sh_")),
                         sorted(f"radiance:sh_{k}" for k in range(SH_REST)))
        # radiance:base holds the SH DC coefficient itself (not a colour) and the opacity, in object space.
        self.assertNotIn(name, bpy.data.objects, "the RaySplats object should be replaced (Keep Original is off)")
        base = attribute_values(data, "radiance:base", count)
        np.testing.assert_allclose(base[:, 3], before["opacities"], atol=1e-6)
        # Linear scales: the largest standard deviation of each Gaussian, times the object's scale 1.5, is the world one.
        scales = attribute_values(data, "scale", count)
        np.testing.assert_allclose(1.5 * scales.max(axis=1), before["scales"].max(axis=1), rtol=1e-4)

        select_only(splats)
        self.assertEqual(bpy.ops.object.raysplats_from_native_splats(), {"FINISHED"})
        back = bpy.context.active_object
        self.assertTrue(polygon_mesh.is_gaussian_object(back))
        self.assertEqual(back.raysplats.up_axis, "-Y", "the export up axis of the original should come back")
        after = world_gaussians(back)
        scene_size = np.abs(before["positions"]).max()
        np.testing.assert_allclose(after["positions"], before["positions"], atol=1e-5 * scene_size)
        self.assertLess(relative_errors(covariances(after), covariances(before)).max(), 1e-4)
        np.testing.assert_allclose(after["opacities"], before["opacities"], atol=1e-6)
        np.testing.assert_allclose(after["sh"], before["sh"], atol=1e-4 * np.abs(before["sh"]).max())


if __name__ == "__main__":
    unittest.main()
