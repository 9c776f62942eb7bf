# Every fact of compat.py against its value on each Blender version the suite runs on (Debian's 3.4 and the
# official 4.2, 4.5, 5.0, 5.2 and 5.3 builds), written out here by hand from each Blender's behaviour, so that a probe
# that answers wrongly (hasattr on an RNA function is False, so PointCloud.resize went unseen on 5.2 and 5.3) fails
# here instead of silently choosing the older path. The facts that can be tried are also tried on the running Blender.
import unittest

import bpy
import numpy as np

from raysplats.blender import compat

VERSIONS = ((3, 4), (4, 2), (4, 5), (5, 0), (5, 2), (5, 3))


def per_version(*values):
    """{version: value} in the order of VERSIONS."""
    assert len(values) == len(VERSIONS)
    return dict(zip(VERSIONS, values))


def since(version, new, old):
    return {v: (new if v >= version else old) for v in VERSIONS}


EXPECTED = {
    "PRINCIPLED_VERSION": since((4, 0), "V2", "V1"),
    "AREA_LIGHT_POWER_SCALE": since((4, 0), 4.0 / np.pi, 1.0),
    "CAMERA_HAS_PANORAMA_SETTINGS": since((4, 0), True, False),
    "MOTION_BLUR_POSITION_IN_RENDER_SETTINGS": since((4, 2), True, False),
    "MATERIAL_HAS_SURFACE_RENDER_METHOD": since((4, 2), True, False),
    "EEVEE_ENGINE": per_version("BLENDER_EEVEE", "BLENDER_EEVEE_NEXT", "BLENDER_EEVEE_NEXT", "BLENDER_EEVEE",
                                "BLENDER_EEVEE", "BLENDER_EEVEE"),
    "MESH_POSITIONS_ARE_AN_ATTRIBUTE": since((3, 5), True, False),
    "MESH_TOPOLOGY_IN_INT32_ARRAYS": since((3, 6), True, False),
    "LOOP_STRIDE": since((3, 6), 4, 8),
    "FACE_STRIDE": since((3, 6), 4, 12),
    "FACE_SIZE_OFFSET": since((3, 6), None, 4),
    "MESH_INDEX_DTYPE": since((3, 6), np.int32, np.uint32),
    "FACE_CORNER_COUNT_IS_WRITABLE": since((3, 6), False, True),
    "EVALUATED_MESH_COPIES_ON_READ": since((3, 6), False, True),
    "UV_MAPS_ARE_ATTRIBUTES": since((3, 5), True, False),
    "NATIVE_GAUSSIAN_SPLAT_TYPE": since((5, 3), "GAUSSIAN_SPLAT", None),
    "HAS_NATIVE_GAUSSIAN_SPLATS": since((5, 3), True, False),
    "POINTCLOUD_CAN_RESIZE": since((5, 2), True, False),
    "SPLATS_AS_POINT_CLOUD": since((5, 3), True, False),
    "FLOAT4_ATTRIBUTE_TYPE": since((5, 2), "FLOAT4", "FLOAT_COLOR"),
    "QUATERNION_ATTRIBUTE_TYPE": since((4, 0), "QUATERNION", "FLOAT_COLOR"),
    "TRANSFORM_ROTATE_SIGN": since((5, 0), 1.0, -1.0),
    "IMAGE_FORMAT_HAS_MEDIA_TYPE": since((5, 0), True, False),
    "BPY_BMESH_POINTER_OFFSET": since((5, 2), 16, 24),
    "BPY_BMELEM_POINTER_OFFSET": since((5, 2), 24, 32),
    "RENDER_PASS_BUFFER_IS_FLAT": since((4, 2), True, False),
    "RENAMED_RENDER_PASSES": since((5, 0), {"IndexOB": "Object Index", "IndexMA": "Material Index",
                                            "Emit": "Emission", "DiffDir": "Diffuse Direct",
                                            "DiffInd": "Diffuse Indirect", "DiffCol": "Diffuse Color",
                                            "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect",
                                            "GlossCol": "Glossy Color", "TransDir": "Transmission Direct",
                                            "TransInd": "Transmission Indirect", "TransCol": "Transmission Color",
                                            "Env": "Environment"},
                                   {}),
    "COMPOSITOR_IS_NODE_GROUP": since((5, 0), True, False),
    "NEWER_THAN_TESTED": since((5, 2), False, False),  # every Blender in this table was tested
}
# Names in compat.py that are the same on every version (layouts, keys), not probed.
CONSTANTS = {"SOLID_COLOR_TYPE_ATTRIBUTE", "MESH_CORNER_VERTEX_ATTRIBUTE", "LOOP_VERTEX_OFFSET", "FACE_START_OFFSET",
             "MESH_ARRAY_ATTRIBUTES", "MESH_SELECTION_ATTRIBUTES", "ATTRIBUTE_VALUE_KEY", "BMESH_LAYOUT",
             "NEWEST_TESTED_BLENDER"}


def running_version():
    return tuple(bpy.app.version[:2])


class CompatFacts(unittest.TestCase):
    def test_every_fact_is_in_the_table(self):
        names = {name for name in vars(compat) if name.isupper() and not name.startswith("_")}
        self.assertEqual(names - CONSTANTS, set(EXPECTED),
                         "a fact added to compat.py needs its value per version here (or CONSTANTS)")

    def test_each_fact_has_this_versions_value(self):
        version = running_version()
        if version not in VERSIONS:
            self.skipTest(f"Blender {version[0]}.{version[1]} is not in this test's table (add its column)")
        for name, values in EXPECTED.items():
            with self.subTest(name):
                actual, expected = getattr(compat, name), values[version]
                if isinstance(expected, float):
                    self.assertAlmostEqual(actual, expected, places=12)
                else:
                    self.assertEqual(actual, expected)

    def test_point_cloud_resize_probe_matches_what_python_can_do(self):
        if not hasattr(bpy.types, "PointCloud"):
            self.skipTest("expected: this Blender has no PointCloud type")
        data = bpy.data.pointclouds.new("probe")
        try:
            try:
                data.resize(10)
                resized = len(data.points) == 10
            except AttributeError:
                resized = False
            self.assertEqual(compat.POINTCLOUD_CAN_RESIZE, resized)
        finally:
            bpy.data.pointclouds.remove(data)

    def test_splat_type_probe_matches_what_a_point_cloud_takes(self):
        if not hasattr(bpy.types, "PointCloud"):
            self.skipTest("expected: this Blender has no PointCloud type")
        data = bpy.data.pointclouds.new("probe")
        try:
            if compat.HAS_NATIVE_GAUSSIAN_SPLATS:
                data.type = compat.NATIVE_GAUSSIAN_SPLAT_TYPE
                self.assertEqual(data.type, "GAUSSIAN_SPLAT")
            else:
                self.assertFalse(hasattr(data, "type"))
        finally:
            bpy.data.pointclouds.remove(data)

    def test_attribute_types_hold_four_floats_unchanged(self):
        mesh = bpy.data.meshes.new("probe")
        try:
            mesh.vertices.add(2)
            values = np.array([0.25, -3.0, 7.5, 2.0, 1e-3, 0.0, -0.5, 9.0], np.float32)
            for data_type in (compat.FLOAT4_ATTRIBUTE_TYPE, compat.QUATERNION_ATTRIBUTE_TYPE):
                attribute = mesh.attributes.new(f"probe {data_type}", data_type, "POINT")
                key = compat.ATTRIBUTE_VALUE_KEY[data_type]
                attribute.data.foreach_set(key, values)
                back = np.empty(8, np.float32)
                attribute.data.foreach_get(key, back)
                np.testing.assert_array_equal(back, values)
        finally:
            bpy.data.meshes.remove(mesh)

    def test_bmesh_python_objects_hold_their_pointers_at_the_offsets(self):
        # Read at the offsets (safely: a wrong one is an error, not a crash), bmesh's Python objects must give a BMesh
        # with the counts Python sees and a vertex at the position Python sees (a wrong offset reads a word of the
        # object header: not an aligned pointer).
        import bmesh

        from raysplats.blender import blender_memory
        bm = bmesh.new()
        try:
            for k in range(5):
                bm.verts.new((float(k), 0.0, 0.0))
            bm.verts.ensure_lookup_table()
            bm.faces.new([bm.verts[k] for k in range(4)])
            layout = compat.BMESH_LAYOUT
            address = blender_memory.pointer_at(id(bm) + compat.BPY_BMESH_POINTER_OFFSET)
            self.assertTrue(address and address % 8 == 0, f"not a pointer: {address!r}")
            counts = tuple(blender_memory.int_at(address + layout[key]) for key in ("totvert", "totface"))
            self.assertEqual(counts, (5, 1))
            vert = bm.verts[2]
            element = blender_memory.pointer_at(id(vert) + compat.BPY_BMELEM_POINTER_OFFSET)
            self.assertTrue(element and element % 8 == 0, f"not a pointer: {element!r}")
            self.assertEqual(blender_memory.floats_at(element + layout["vert_co"], 3), (2.0, 0.0, 0.0))
        finally:
            bm.free()

    def test_the_manifest_admits_blender_up_to_the_newest_tested_and_no_further(self):
        # blender_version_max is exclusive: one minor version past NEWEST_TESTED_BLENDER.
        import os
        import re
        manifest = os.path.join(os.path.dirname(compat.__file__), "..", "blender_manifest.toml")
        with open(manifest, encoding="utf-8") as f:
            found = re.search(r'^blender_version_max = "(\d+)\.(\d+)\.0"$', f.read(), re.MULTILINE)
        self.assertIsNotNone(found, "no blender_version_max in blender_manifest.toml")
        major, minor = compat.NEWEST_TESTED_BLENDER
        self.assertEqual((int(found.group(1)), int(found.group(2))), (major, minor + 1))
        self.assertEqual(compat.NEWER_THAN_TESTED, running_version() > compat.NEWEST_TESTED_BLENDER)


if __name__ == "__main__":
    unittest.main()
