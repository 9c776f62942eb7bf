# The compositor's data passes, Mist, Position, Object Index and Material Index, switched on with Blender's own View
# Layer check boxes and set by Blender's own settings (the World's Mist Pass, Object and Material pass_index):
# - on meshes they agree with Cycles pixel for pixel and with the geometry (a plane at a known distance);
# - on Gaussians (polygon and compact splat objects, and with Camera Rays as Splats) they follow the rule
#   docs/reference.md states: mist accumulated through the Gaussians weighted by their alpha, position and indices
#   where the opacity reaches 0.5, as Depth; checked against numpy from the Gaussians' known centres and opacities.
# Samples are spread over 1 % of a pixel around its centre (a Gaussian pixel filter of width 0.01 in both engines),
# so the first sample, which Position and the indices keep, lies at the pixel centre in both.
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import final
from raysplats.objects import creation

WIDTH, HEIGHT = 64, 48
CAMERA_HEIGHT = 10.0
HALF_TAN = 18.0 / 50.0  # a 50 mm lens on the 36 mm sensor spanning the image width
MIST_START, MIST_DEPTH = 3.0, 8.0
FALLOFF_EXPONENTS = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}
PASSES = ("use_pass_mist", "use_pass_position", "use_pass_object_index", "use_pass_material_index")


def pixel_centres():
    """(x, y) image-plane tangents of every pixel centre of the camera looking down -Z (rows top to bottom)."""
    i, j = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    return (2.0 * i / WIDTH - 1.0) * HALF_TAN, (1.0 - 2.0 * j / HEIGHT) * HALF_TAN * HEIGHT / WIDTH


def mist_of(distance, falloff):
    """Cycles' mist (kernel/film/data_passes.h) at `distance` from the camera."""
    return np.clip((distance - MIST_START) / MIST_DEPTH, 0.0, 1.0) ** FALLOFF_EXPONENTS[falloff]


def material(name, pass_index):
    result = bpy.data.materials.new(name)
    result.pass_index = pass_index
    return result


def new_scene(falloff="QUADRATIC"):
    """A camera 10 units above z = 0 looking down, both engines' pixel filters at the pixel centre, the four data
    passes on, and the World's mist from 3 to 11 units."""
    scene = st.pixel_centre_scene(WIDTH, HEIGHT, 4, (0.1, 0.1, 0.1), CAMERA_HEIGHT)
    mist = scene.world.mist_settings
    mist.start, mist.depth, mist.falloff = MIST_START, MIST_DEPTH, falloff
    for name in PASSES:
        setattr(bpy.context.view_layer, name, True)
    return scene


def add_plane(name, size, location, object_index, material_index=None, rotation=(0.0, 0.0, 0.0)):
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=location, rotation=rotation)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (size[0], size[1], 1.0)
    obj.pass_index = object_index
    if material_index is not None:
        obj.data.materials.append(material(name, material_index))
    return obj


def mesh_scene(falloff):
    """A floor at distance 10 (left half), a box whose top is at distance 6, a tilted plane without a material, and
    the world where none of them is."""
    scene = new_scene(falloff)
    add_plane("Floor", (4.0, 6.0), (-2.0, 0.0, 0.0), object_index=3, material_index=5)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.5, 1.0, 3.0))
    box = bpy.context.active_object
    box.pass_index = 7
    box.data.materials.append(material("Box", 2))
    add_plane("Tilted", (1.5, 1.5), (1.8, -1.4, 1.0), object_index=12, rotation=(0.5, 0.3, 0.0))
    return scene


def passes(exr):
    """{pass name: array} of a multilayer EXR's first view layer: Mist (H, W), Position (H, W, 3), IndexOB, IndexMA,
    Alpha and Depth where present."""
    layer = next(name.split(".")[0] for name in exr)
    result = {name: exr[f"{layer}.{compat.render_pass_name(name)}.{channel}"] for name, channel in
              (("Mist", "Z"), ("IndexOB", "X"), ("IndexMA", "X"), ("Alpha", "A"), ("Depth", "Z"))
              if f"{layer}.{compat.render_pass_name(name)}.{channel}" in exr}
    result["Position"] = np.stack([exr[f"{layer}.Position.{c}"] for c in "XYZ"], axis=-1)
    return result


def render(scene, engine, name):
    scene.render.engine = engine
    return passes(st.render_multilayer_exr(name))


def pass_names(exr):
    return {name.split(".")[1] for name in exr}


class MeshDataPasses(unittest.TestCase):
    """Mesh-only scenes: RaySplats against Cycles, and both against the geometry."""

    def test_agree_with_cycles_and_the_geometry(self):
        for falloff in FALLOFF_EXPONENTS:
            with self.subTest(falloff=falloff):
                scene = mesh_scene(falloff)
                ours = render(scene, "RAYSPLATS", "data_passes_" + falloff)
                cycles = render(scene, "CYCLES", "data_passes_cycles_" + falloff)
                self.compare(ours, cycles, falloff)

    def test_mist_through_a_transparent_surface_agrees_with_cycles(self):
        # A plane of alpha 0.4 at distance 6 over the floor: Cycles adds 0.4 (1 - mist(6)) + 0.6 (1 - mist(10)), each
        # path through the plane weighted by its transparency; RaySplats passes through it with probability 0.6 (the
        # same expectation; 256 samples: a standard error of 0.015 per pixel here, 4e-4 for the mean).
        scene = mesh_scene("LINEAR")
        plane = add_plane("Veil", (4.0, 6.0), (-2.0, 0.0, 4.0), object_index=14)
        veil = bpy.data.materials.new("Veil")
        veil.use_nodes = True
        veil.node_tree.nodes["Principled BSDF"].inputs["Alpha"].default_value = 0.4
        plane.data.materials.append(veil)
        scene.raysplats.samples = scene.cycles.samples = 256
        ours = render(scene, "RAYSPLATS", "data_passes_veil")
        cycles = render(scene, "CYCLES", "data_passes_veil_cycles")
        x, y = pixel_centres()
        inside = (x * 6.0 < -0.1) & (np.abs(y * 6.0) < 1.5)  # the veil over the floor, away from its edges
        self.assertGreater(np.sum(inside), 400)
        length = np.sqrt(1.0 + x * x + y * y)
        expected = 1.0 - 0.4 * (1.0 - mist_of(6.0 * length, "LINEAR")) - 0.6 * (1.0 - mist_of(10.0 * length, "LINEAR"))
        np.testing.assert_allclose(cycles["Mist"][inside], expected[inside], atol=2e-3)  # (Cycles' own rule)
        np.testing.assert_allclose(ours["Mist"][inside], cycles["Mist"][inside], atol=0.08)
        self.assertLess(abs(np.mean(ours["Mist"][inside] - cycles["Mist"][inside])), 2e-3)

    def compare(self, ours, cycles, falloff):
        inside = st.interior(ours["IndexOB"], cycles["IndexOB"], ours["IndexMA"], cycles["IndexMA"])
        # Every object and the world keep some pixels away from edges.
        for index in (0, 3, 7, 12):
            self.assertGreater(np.sum(inside & (cycles["IndexOB"] == index)), 20, index)
        np.testing.assert_array_equal(ours["IndexOB"][inside], cycles["IndexOB"][inside])
        np.testing.assert_array_equal(ours["IndexMA"][inside], cycles["IndexMA"][inside])
        # Materials: the floor's 5, the box's 2; the plane without a material and the world: 0.
        for obj, mat in ((3, 5), (7, 2), (12, 0), (0, 0)):
            self.assertTrue(np.all(ours["IndexMA"][inside & (ours["IndexOB"] == obj)] == mat), (obj, mat))
        np.testing.assert_allclose(ours["Position"][inside], cycles["Position"][inside], atol=2e-3)
        np.testing.assert_allclose(ours["Mist"][inside], cycles["Mist"][inside], atol=2e-3)
        world = inside & (cycles["IndexOB"] == 0)
        self.assertTrue(np.all(ours["Position"][world] == 0.0))
        self.assertTrue(np.all(ours["Mist"][world] == 1.0))
        # The floor, z = 0, seen through each pixel's centre, at its distance from the camera.
        x, y = pixel_centres()
        floor = inside & (ours["IndexOB"] == 3)
        expected = np.stack([x * CAMERA_HEIGHT, y * CAMERA_HEIGHT, np.zeros_like(x)], axis=-1)
        np.testing.assert_allclose(ours["Position"][floor], expected[floor], atol=2e-3)
        distance = CAMERA_HEIGHT * np.sqrt(1.0 + x * x + y * y)
        np.testing.assert_allclose(ours["Mist"][floor], mist_of(distance, falloff)[floor], atol=1e-3)
        # The box's top, z = 4, at distance 6 and more.
        top = inside & (ours["IndexOB"] == 7) & (np.abs(ours["Position"][..., 2] - 4.0) < 1e-3)
        self.assertGreater(np.sum(top), 20)
        np.testing.assert_allclose(ours["Mist"][top], mist_of(6.0 * np.sqrt(1.0 + x * x + y * y), falloff)[top],
                                   atol=1e-3)


GAUSSIAN_OBJECT_INDEX, GAUSSIAN_MATERIAL_INDEX = 9, 11
LAYER_Z, SIGMA, OPACITY = 2.0, 0.6, 0.9
CENTRES = [(-1.2, 0.4, LAYER_Z), (1.3, -0.3, LAYER_Z)]


def gaussian_scene(kind, falloff="LINEAR", orthographic=True):
    """Two flat Gaussians 8 units below the camera (polygon or compact splat object, pass index 9, its material's
    11) over a floor (pass index 3, material 5) that covers the left half."""
    scene = new_scene(falloff)
    camera = scene.camera.data
    if orthographic:
        camera.type, camera.ortho_scale = "ORTHO", 6.0
    bpy.context.view_layer.use_pass_z = True
    bpy.context.view_layer.raysplats_passes.use_pass_alpha = True
    add_plane("Floor", (4.0, 8.0), (-2.0, 0.0, 0.0), object_index=3, material_index=5)
    cloud = st.flat_gaussian_cloud(CENTRES, SIGMA, OPACITY)
    if kind == "POLYGONS":
        obj, _ = creation.add_gaussian_object(bpy.context, "Splats", cloud, 8, 3.0, "Z")
        obj.material_slots[0].material.pass_index = GAUSSIAN_MATERIAL_INDEX  # the falloff material
    else:
        obj = creation.add_compact_object(bpy.context, "Splats", cloud, "Z")
        obj.data.materials.append(material("Splats", GAUSSIAN_MATERIAL_INDEX))
    obj.pass_index = GAUSSIAN_OBJECT_INDEX
    return scene


def gaussian_alpha(px, py):
    """The alpha of the Gaussian layer at points (px, py) of its plane."""
    return st.flat_gaussian_alpha(px, py, CENTRES, SIGMA, OPACITY)


class GaussianDataPasses(unittest.TestCase):
    """Gaussians: mist through their alpha, position and indices where the opacity reaches 0.5."""

    def check_rule(self, out, px, py, distance_to_layer, distance_to_floor, falloff, mist_atol=2e-3, margin=0.02):
        """`px`, `py`: where each pixel centre's ray meets the Gaussians' plane; distances from the camera to that
        point and to the floor's."""
        alpha = gaussian_alpha(px, py)
        on_floor = px < 0.0
        behind = np.where(on_floor, 1.0 - mist_of(distance_to_floor, falloff), 0.0)
        expected_mist = 1.0 - alpha * (1.0 - mist_of(distance_to_layer, falloff)) - (1.0 - alpha) * behind
        # Away from the floor's edge (x = 0 on the Gaussians' plane and near it below) and from the rims of the disks,
        # where the alpha drops from 0.01 to 0 within the samples' spread.
        away = np.abs(px) > 0.1
        for cx, cy, _ in CENTRES:
            away &= np.abs(((px - cx) ** 2 + (py - cy) ** 2) / SIGMA ** 2 - 9.0) > 0.5
        np.testing.assert_allclose(out["Mist"][away], expected_mist[away], atol=mist_atol)
        # Where the layer's alpha reaches 0.5 it is the surface: its object and material; elsewhere the floor, or
        # nothing. (Away from the 0.5 contour, where the first sample's side is a matter of rounding.)
        splat = (alpha > 0.5 + margin) & away
        floor = (alpha < 0.5 - margin) & on_floor & away
        world = (alpha < 0.5 - margin) & ~on_floor & away
        for mask in (splat, floor, world):
            self.assertGreater(np.sum(mask), 20)
        self.assertTrue(np.all(out["IndexOB"][splat] == GAUSSIAN_OBJECT_INDEX))
        self.assertTrue(np.all(out["IndexMA"][splat] == GAUSSIAN_MATERIAL_INDEX))
        self.assertTrue(np.all(out["IndexOB"][floor] == 3))
        self.assertTrue(np.all(out["IndexMA"][floor] == 5))
        np.testing.assert_allclose(out["Position"][floor][:, 2], 0.0, atol=2e-3)
        self.assertTrue(np.all(out["IndexOB"][world] == 0))
        self.assertTrue(np.all(out["IndexMA"][world] == 0))
        self.assertTrue(np.all(out["Position"][world] == 0.0))
        self.assertTrue(np.all(out["Depth"][world] == 1e10))
        return splat

    def test_orthographic_polygon_and_compact_objects(self):
        x, y = pixel_centres()
        # The orthographic camera's rays are parallel, through (x, y) in units of half the ortho scale.
        px, py = x / HALF_TAN * 3.0, y / HALF_TAN * 3.0
        for kind in ("POLYGONS", "COMPACT"):
            for falloff in ("LINEAR", "QUADRATIC"):
                with self.subTest(kind=kind, falloff=falloff):
                    out = render(gaussian_scene(kind, falloff), "RAYSPLATS", f"data_passes_gaussians_{kind}_{falloff}")
                    # Orthographic: the distance along the view axis.
                    splat = self.check_rule(out, px, py, CAMERA_HEIGHT - LAYER_Z, CAMERA_HEIGHT, falloff)
                    expected = np.stack([px, py, np.full_like(px, LAYER_Z)], axis=-1)
                    np.testing.assert_allclose(out["Position"][splat], expected[splat], atol=2e-3)
                    # Position is the camera ray's point at Depth.
                    seen = out["Depth"] < 1e9
                    np.testing.assert_allclose(out["Position"][seen][:, 2], CAMERA_HEIGHT - out["Depth"][seen],
                                               atol=2e-4)

    def test_perspective_traced_and_splatted(self):
        x, y = pixel_centres()
        length = np.sqrt(1.0 + x * x + y * y)
        directions = np.stack([x, y, -np.ones_like(x)], axis=-1) / length[..., None]
        depth = CAMERA_HEIGHT - LAYER_Z
        for splatting in (False, True):
            with self.subTest(camera_ray_splatting=splatting):
                scene = gaussian_scene("COMPACT", "QUADRATIC", orthographic=False)
                scene.raysplats.camera_ray_splatting = splatting
                out = render(scene, "RAYSPLATS", f"data_passes_gaussians_splatting_{splatting}")
                # A pixel centre's ray meets the Gaussians' plane at x, y times its view depth. Splatting takes a
                # splat's mist where the ray reaches its centre's view depth, the same point for Gaussians centred on
                # the plane; its alpha is the projected (EWA) footprint's, which differs from the traced Gaussian's by
                # up to 0.01 here.
                splat = self.check_rule(out, x * depth, y * depth, depth * length, CAMERA_HEIGHT * length,
                                        "QUADRATIC", mist_atol=1e-2 if splatting else 2e-3,
                                        margin=0.08 if splatting else 0.02)
                # Position is the camera ray's point at Depth (for a splat, the point nearest its centre).
                seen = out["Depth"] < 1e9
                camera = np.array([0.0, 0.0, CAMERA_HEIGHT])
                np.testing.assert_allclose(out["Position"][seen], camera + out["Depth"][seen][:, None] * directions[seen],
                                           atol=2e-3)
                if not splatting:
                    np.testing.assert_allclose(out["Position"][splat][:, 2], LAYER_Z, atol=2e-3)


class PersistentData(unittest.TestCase):
    def test_a_changed_pass_index_reaches_the_kept_scene(self):
        # Render > Performance > Persistent Data keeps the native scene between renders (final.py): a new pass index
        # of a mesh, a Gaussian object or a material is neither geometry nor transform, and must still reach it.
        scene = gaussian_scene("COMPACT")
        scene.render.use_persistent_data = True
        first = passes(st.render_multilayer_exr("data_passes_persistent_1"))
        passes(st.render_multilayer_exr("data_passes_persistent_2"))
        self.assertEqual(final.last_render["scene"], "kept")
        splats, floor = bpy.data.objects["Splats"], bpy.data.objects["Floor"]
        splats.pass_index, floor.pass_index = 21, 22
        second = passes(st.render_multilayer_exr("data_passes_persistent_3"))
        for old, new in ((GAUSSIAN_OBJECT_INDEX, 21), (3, 22)):
            self.assertGreater(np.sum(first["IndexOB"] == old), 20)
            np.testing.assert_array_equal(second["IndexOB"] == new, first["IndexOB"] == old)
        floor.material_slots[0].material.pass_index = 23
        splats.material_slots[0].material.pass_index = 24
        third = passes(st.render_multilayer_exr("data_passes_persistent_4"))
        np.testing.assert_array_equal(third["IndexMA"] == 23, first["IndexMA"] == 5)
        np.testing.assert_array_equal(third["IndexMA"] == 24, first["IndexMA"] == GAUSSIAN_MATERIAL_INDEX)


class PassesAreOptIn(unittest.TestCase):
    def test_blender_draws_the_mist_settings(self):
        # World > Mist Pass is Blender's own panel, declared compatible (engine/ui.py).
        self.assertIn("RAYSPLATS", bpy.types.EEVEE_WORLD_PT_mist.COMPAT_ENGINES)

    def test_only_the_checked_data_passes_are_written(self):
        scene = mesh_scene("LINEAR")
        view_layer = bpy.context.view_layer
        for name in PASSES:
            setattr(view_layer, name, False)
        self.assertEqual(pass_names(st.render_multilayer_exr("data_passes_none")), {"Combined"})
        view_layer.use_pass_mist = view_layer.use_pass_object_index = True
        self.assertEqual(pass_names(st.render_multilayer_exr("data_passes_two")),
                         {"Combined", "Mist", compat.render_pass_name("IndexOB")})


if __name__ == "__main__":
    unittest.main()
