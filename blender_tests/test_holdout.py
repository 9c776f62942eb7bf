# Blender's Holdout (Object.is_holdout, a collection's Holdout in the view layer), Shadow Catcher
# (Object.is_shadow_catcher, Cycles' Shadow Catcher pass) and the Environment pass (ViewLayer.use_pass_environment), as
# Cycles defines them (docs/reference.md, Holdout, Environment pass, Shadow Catcher):
# - on meshes, against Cycles: Combined's alpha and colour are 0 wherever a held-out object is seen, with and without
#   Film > Transparent, and the rest of the image is as without the holdout (bit for bit where no camera ray meets a
#   held-out object: other rays still see it);
# - on Gaussians (polygon and compact splat objects), against the closed form: a held-out Gaussian takes its
#   coverage T a out of Combined's alpha and adds no colour;
# - the Environment pass is the world's colour where the camera ray escapes, times the Gaussians' transmittance, and
#   agrees with Cycles on meshes;
# - a Shadow Catcher floor under a cube and a sun agrees with Cycles (the Shadow Catcher pass and the transparent
#   Combined's alpha), and under a splat object its Shadow Catcher pass follows the Gaussians' transmittance.
# Samples are spread over 1 % of a pixel around its centre (a Gaussian pixel filter of width 0.01 in both engines),
# so that pixel values are those of the pixel centre's ray.
import types
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import sync
from raysplats.objects import creation

WIDTH, HEIGHT = 64, 48
CAMERA_HEIGHT = 10.0
WORLD = (0.1, 0.2, 0.3)
HELD_OUT_OBJECT, HELD_OUT_BY_COLLECTION, FLOOR = 1, 2, 3


def new_scene(samples=4):
    """A camera 10 units above z = 0 looking down, both engines' samples at the pixel centre, the Object Index and
    Environment passes on, and a uniform world."""
    scene = st.pixel_centre_scene(WIDTH, HEIGHT, samples, WORLD, CAMERA_HEIGHT)
    view_layer = bpy.context.view_layer
    view_layer.use_pass_object_index = True
    view_layer.use_pass_environment = True
    return scene


def add_plane(size, location, pass_index):
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.scale = (size[0], size[1], 1.0)
    obj.pass_index = pass_index
    return obj


def mesh_scene(held_out):
    """A floor over the left half, a box held out by its object's Holdout and one in a collection held out in the
    view layer (when `held_out`), a light, and the world where none of them is."""
    scene = new_scene(samples=16)
    add_plane((4.0, 8.0), (-2.0, 0.0, 0.0), FLOOR)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.5, 1.0, 3.0))
    box = bpy.context.active_object
    box.pass_index = HELD_OUT_OBJECT
    box.is_holdout = held_out
    collection = bpy.data.collections.new("Held out")
    scene.collection.children.link(collection)
    bpy.ops.mesh.primitive_cube_add(size=1.5, location=(-1.5, -1.0, 2.0))
    other = bpy.context.active_object
    other.pass_index = HELD_OUT_BY_COLLECTION
    for users in list(other.users_collection):
        users.objects.unlink(other)
    collection.objects.link(other)
    bpy.context.view_layer.layer_collection.children[collection.name].holdout = held_out
    light = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    light.data.energy = 3.0
    light.rotation_euler = (0.4, 0.3, 0.0)
    scene.collection.objects.link(light)
    return scene


def render(scene, engine, name):
    """{"rgba": (H, W, 4), "index": (H, W), "env": (H, W, 3), "catcher": (H, W, 3) where the Shadow Catcher pass is on}
    of F12 into a multilayer EXR (rows top to bottom)."""
    scene.render.engine = engine
    exr = st.render_multilayer_exr(name)
    layer = next(name.split(".")[0] for name in exr)
    index, env = compat.render_pass_name("IndexOB"), compat.render_pass_name("Env")
    result = {"rgba": np.stack([exr[f"{layer}.Combined.{c}"] for c in "RGBA"], axis=-1),
              "index": exr[f"{layer}.{index}.X"],
              "env": np.stack([exr[f"{layer}.{env}.{c}"] for c in "RGB"], axis=-1)}
    if f"{layer}.Shadow Catcher.R" in exr:
        result["catcher"] = np.stack([exr[f"{layer}.Shadow Catcher.{c}"] for c in "RGB"], axis=-1)
    return result


def render_mesh_scene(held_out, transparent, engines, name):
    """render() of mesh_scene(held_out) with Film > Transparent `transparent`, by each engine."""
    scene = mesh_scene(held_out)
    scene.render.film_transparent = transparent
    return [render(scene, engine, f"{name}_{engine}_{transparent}") for engine in engines]


class MeshHoldout(unittest.TestCase):
    """Held-out meshes against Cycles, with and without a transparent film."""

    def test_agrees_with_cycles(self):
        for transparent in (False, True):
            with self.subTest(transparent=transparent):
                ours, cycles = render_mesh_scene(True, transparent, ("RAYSPLATS", "CYCLES"), "holdout")
                plain, = render_mesh_scene(False, transparent, ("RAYSPLATS",), "holdout_plain")
                self.compare(ours, cycles, plain, transparent)

    def compare(self, ours, cycles, plain, transparent):
        inside = st.interior(plain["index"])
        held = inside & np.isin(plain["index"], (HELD_OUT_OBJECT, HELD_OUT_BY_COLLECTION))
        for index in (HELD_OUT_OBJECT, HELD_OUT_BY_COLLECTION):
            self.assertGreater(np.sum(inside & (plain["index"] == index)), 20, index)
        # Where a held-out box is seen: no colour and no alpha, in both engines.
        self.assertTrue(np.all(ours["rgba"][held] == 0.0))
        np.testing.assert_allclose(cycles["rgba"][held], 0.0, atol=1e-6)
        # Elsewhere Combined's alpha is Cycles' (1 with an opaque film; the coverage with a transparent one), and the
        # pixels are those of the render without holdout, bit for bit: only camera rays see the holdout.
        rest = inside & ~held
        expected_alpha = np.ones(rest.shape) if not transparent else (plain["index"] != 0).astype(float)
        np.testing.assert_array_equal(ours["rgba"][rest][:, 3], expected_alpha[rest])
        np.testing.assert_allclose(cycles["rgba"][rest][:, 3], expected_alpha[rest], atol=1e-6)
        np.testing.assert_array_equal(ours["rgba"][rest], plain["rgba"][rest])
        # Over the whole image, edges included: the mean alpha difference from Cycles.
        difference = np.mean(np.abs(ours["rgba"][..., 3] - cycles["rgba"][..., 3]))
        print(f"\nHoldout against Cycles, Blender {bpy.app.version_string}, transparent {transparent}: mean |alpha "
              f"difference| {difference:.2e} ({np.sum(held)} held-out pixels RGBA 0)")
        self.assertLess(difference, 0.01)


SIGMA, OPACITY, LAYER_Z = 0.6, 0.9, 2.0
CENTRES = [(-1.2, 0.4, LAYER_Z), (1.3, -0.3, LAYER_Z)]
ORTHO_SCALE = 6.0


def flat_gaussian_cloud():
    return st.flat_gaussian_cloud(CENTRES, SIGMA, OPACITY)


def layer_points():
    """(x, y) where each pixel centre's ray (orthographic, looking down) meets the Gaussians' plane."""
    i, j = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    half = 0.5 * ORTHO_SCALE
    return (2.0 * i / WIDTH - 1.0) * half, (1.0 - 2.0 * j / HEIGHT) * half * HEIGHT / WIDTH


def gaussian_alpha(px, py):
    """The Gaussian layer's alpha at points (px, py) of its plane."""
    return st.flat_gaussian_alpha(px, py, CENTRES, SIGMA, OPACITY)


def gaussian_scene(kind, by_collection):
    """Two flat Gaussians 8 units below an orthographic camera (a polygon or compact splat object), held out by the
    object's Holdout or by its collection's, over a floor covering the left half."""
    scene = new_scene()
    scene.camera.data.type, scene.camera.data.ortho_scale = "ORTHO", ORTHO_SCALE
    add_plane((4.0, 8.0), (-2.0, 0.0, 0.0), FLOOR)
    if kind == "POLYGONS":
        obj, _ = creation.add_gaussian_object(bpy.context, "Splats", flat_gaussian_cloud(), 8, 3.0, "Z")
    else:
        obj = creation.add_compact_object(bpy.context, "Splats", flat_gaussian_cloud(), "Z")
    if by_collection:
        collection = bpy.data.collections.new("Held out")
        scene.collection.children.link(collection)
        for users in list(obj.users_collection):
            users.objects.unlink(obj)
        collection.objects.link(obj)
        bpy.context.view_layer.layer_collection.children[collection.name].holdout = True
    else:
        obj.is_holdout = True
    return scene


class GaussianHoldout(unittest.TestCase):
    """Held-out Gaussians against the closed form: Combined's alpha loses their coverage, their colour is gone."""

    def test_alpha_follows_the_opacity(self):
        px, py = layer_points()
        alpha = gaussian_alpha(px, py)
        on_floor = px < 0.0
        # Away from the floor's edge and from the rims of the disks, where the alpha drops to 0 within the samples'
        # spread.
        away = np.abs(px) > 0.1
        for cx, cy, _ in CENTRES:
            away &= np.abs(((px - cx) ** 2 + (py - cy) ** 2) / SIGMA ** 2 - 9.0) > 0.5
        seen = away & (alpha > 0.3)
        self.assertGreater(np.sum(seen & on_floor), 20)
        self.assertGreater(np.sum(seen & ~on_floor), 20)
        for kind, by_collection in (("POLYGONS", False), ("COMPACT", True), ("COMPACT", False)):
            for transparent in (False, True):
                with self.subTest(kind=kind, by_collection=by_collection, transparent=transparent):
                    scene = gaussian_scene(kind, by_collection)
                    scene.render.film_transparent = transparent
                    ours = render(scene, "RAYSPLATS", f"holdout_{kind}_{by_collection}_{transparent}")
                    # Over the floor: what the Gaussians let through; over the world: that too with an opaque film,
                    # nothing with a transparent one.
                    expected = np.where(on_floor | (not transparent), 1.0 - alpha, 0.0)
                    print(f"\nGaussian holdout, Blender {bpy.app.version_string}, {kind}: max |alpha - closed form| "
                          f"{np.max(np.abs(ours['rgba'][..., 3] - expected)[away]):.2e}")
                    np.testing.assert_allclose(ours["rgba"][..., 3][away], expected[away], atol=2e-3)
                    if transparent:
                        np.testing.assert_array_equal(ours["rgba"][~on_floor & away][:, :3], 0.0)
                        np.testing.assert_allclose(ours["rgba"][~on_floor & away][:, 3], 0.0, atol=1e-6)
                    # The Environment pass: the world through the Gaussians' transmittance, none on the floor.
                    world = np.where(on_floor, 0.0, 1.0 - alpha)[..., None] * np.array(WORLD)
                    np.testing.assert_allclose(ours["env"][away], world[away], atol=2e-3)


class EnvironmentPass(unittest.TestCase):
    """The Environment pass on meshes: the world's colour where nothing is hit, 0 elsewhere, as Cycles'."""

    def test_agrees_with_cycles_and_the_world(self):
        for transparent in (False, True):
            with self.subTest(transparent=transparent):
                ours, cycles = render_mesh_scene(False, transparent, ("RAYSPLATS", "CYCLES"), "environment")
                inside = st.interior(ours["index"])
                world = inside & (ours["index"] == 0)
                self.assertGreater(np.sum(world), 100)
                np.testing.assert_allclose(ours["env"][world], np.broadcast_to(WORLD, ours["env"][world].shape),
                                           atol=1e-6)
                self.assertTrue(np.all(ours["env"][inside & ~world] == 0.0))
                print(f"\nEnvironment against Cycles, Blender {bpy.app.version_string}: max |difference| "
                      f"{np.max(np.abs(ours['env'] - cycles['env'])[inside]):.2e}")
                np.testing.assert_allclose(ours["env"][inside], cycles["env"][inside], atol=1e-5)


def catcher_scene(samples):
    """A shadow catcher floor, a cube standing on it and a sun 0.5 rad from the vertical (angle 0: hard shadows), a
    black world and a black cube (so that neither lights the floor: the Shadow Catcher pass is the sun's visibility in
    both engines), a transparent film and the Shadow Catcher pass on (Cycles' check box, which RaySplats uses)."""
    scene = new_scene(samples=samples)
    st.set_world_color(scene.world, (0.0, 0.0, 0.0))
    scene.render.film_transparent = True
    bpy.context.view_layer.cycles.use_pass_shadow_catcher = True
    floor = add_plane((8.0, 8.0), (0.0, 0.0, 0.0), FLOOR)
    floor.is_shadow_catcher = True
    bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0.5, -0.5, 0.75))
    cube = bpy.context.active_object
    cube.pass_index = HELD_OUT_OBJECT
    black = bpy.data.materials.new("Black")
    black.diffuse_color = (0.0, 0.0, 0.0, 1.0)
    black.use_nodes = True
    black.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    cube.data.materials.append(black)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, 0.0
    sun.rotation_euler = (0.5, 0.0, 0.0)
    scene.collection.objects.link(sun)
    return scene


class ShadowCatcher(unittest.TestCase):
    """Shadow Catcher objects: the Shadow Catcher pass and the transparent Combined's alpha."""

    def test_a_cube_on_a_catcher_agrees_with_cycles(self):
        # 64 samples: the sun's hard shadow is the same in every sample but at its edge, where the pixel mean is the
        # lit fraction in both engines. With the Shadow Catcher pass the shadow is the pass's and Combined leaves the
        # catcher transparent; without it Combined's alpha is the shadow (Cycles' approximate shadow catcher).
        for with_pass in (True, False):
            with self.subTest(with_pass=with_pass):
                scene = catcher_scene(samples=64)
                bpy.context.view_layer.cycles.use_pass_shadow_catcher = with_pass
                ours = render(scene, "RAYSPLATS", f"catcher_{with_pass}")
                cycles = render(scene, "CYCLES", f"catcher_cycles_{with_pass}")
                self.compare_catchers(ours, cycles, with_pass)

    def compare_catchers(self, ours, cycles, with_pass):
        catcher = st.interior(ours["index"]) & (ours["index"] == FLOOR)
        self.assertGreater(np.sum(catcher), 500)
        np.testing.assert_array_equal(ours["rgba"][catcher][:, :3], 0.0)
        alpha_difference = np.abs(ours["rgba"][..., 3] - cycles["rgba"][..., 3])[catcher].mean()
        print(f"\nShadow catcher against Cycles, Blender {bpy.app.version_string}, pass {with_pass}: mean |alpha "
              f"difference| {alpha_difference:.2e}", end="")
        self.assertLess(alpha_difference, 0.01)
        if with_pass:
            shadow = catcher & (cycles["catcher"][..., 0] < 0.5)
            self.assertGreater(np.sum(shadow), 50)
            pass_difference = np.mean(np.abs(ours["catcher"] - cycles["catcher"])[catcher])
            print(f", mean |Shadow Catcher difference| {pass_difference:.2e} ({np.sum(shadow)} pixels in shadow)")
            self.assertLess(pass_difference, 0.01)
            np.testing.assert_array_equal(ours["rgba"][catcher][:, 3], 0.0)
            # In the shadow the pass is 0, outside it 1 (exactly in RaySplats, but at the shadow's edge).
            self.assertTrue(np.all(ours["catcher"][catcher & (cycles["catcher"][..., 0] < 0.02)] < 0.05))
            self.assertTrue(np.all(ours["catcher"][catcher & (cycles["catcher"][..., 0] > 0.98)] > 0.95))
        else:
            print()
            self.assertGreater(np.sum(catcher & (cycles["rgba"][..., 3] > 0.5)), 50)
        # The cube itself is an ordinary object in both: alpha 1.
        cube = st.interior(ours["index"]) & (ours["index"] == HELD_OUT_OBJECT)
        self.assertGreater(np.sum(cube), 20)
        np.testing.assert_allclose(ours["rgba"][cube][:, 3], 1.0, atol=1e-6)
        np.testing.assert_allclose(cycles["rgba"][cube][:, 3], 1.0, atol=1e-6)

    def test_a_splat_objects_shadow(self):
        # The Gaussians of GaussianHoldout (not held out) 2 units above the catcher; the sun 0.5 rad from the vertical
        # about X casts each one's shadow 2 tan(0.5) along +Y: the floor point (x, y) sees the sun through the layer at
        # (x, y - 2 tan 0.5), r = 1 - a there, and the camera sees it through T = 1 - a(x, y).
        for kind in ("POLYGONS", "COMPACT"):
            with self.subTest(kind=kind):
                scene = catcher_scene(samples=4)
                cube = next(obj for obj in scene.objects if obj.pass_index == HELD_OUT_OBJECT)
                bpy.data.objects.remove(cube)
                scene.camera.data.type, scene.camera.data.ortho_scale = "ORTHO", ORTHO_SCALE
                if kind == "POLYGONS":
                    creation.add_gaussian_object(bpy.context, "Splats", flat_gaussian_cloud(), 8, 3.0, "Z")
                else:
                    creation.add_compact_object(bpy.context, "Splats", flat_gaussian_cloud(), "Z")
                ours = render(scene, "RAYSPLATS", f"catcher_{kind}")
                px, py = layer_points()
                transmittance = 1.0 - gaussian_alpha(px, py)
                r = 1.0 - gaussian_alpha(px, py - LAYER_Z * np.tan(0.5))
                expected = 1.0 - transmittance * (1.0 - r)
                away = np.ones(px.shape, dtype=bool)
                for cx, cy, _ in CENTRES:
                    for y in (py, py - LAYER_Z * np.tan(0.5)):
                        away &= np.abs(((px - cx) ** 2 + (y - cy) ** 2) / SIGMA ** 2 - 9.0) > 0.5
                shadowed = away & (r < 0.5)
                unblocked = away & (r == 1.0) & (transmittance == 1.0)
                self.assertGreater(np.sum(shadowed), 20)
                self.assertGreater(np.sum(unblocked), 300)
                self.assertTrue(np.all(ours["catcher"][shadowed] < 1.0))
                print(f"\nSplat shadow on a catcher, Blender {bpy.app.version_string}, {kind}: max |pass - closed form| "
                      f"{np.max(np.abs(ours['catcher'][..., 0] - expected)[away]):.2e}")
                np.testing.assert_allclose(ours["catcher"][unblocked], 1.0, atol=1e-6)
                np.testing.assert_allclose(ours["catcher"][away], np.repeat(expected[away][:, None], 3, axis=1),
                                           atol=2e-3)
                # The pass is written: Combined leaves the catcher transparent behind the Gaussians' own coverage.
                np.testing.assert_allclose(ours["rgba"][..., 3][away], 1.0 - transmittance[away], atol=2e-3)


class GaussianShadowCatcher(unittest.TestCase):
    def test_a_splat_object_marked_shadow_catcher_is_drawn_and_warns(self):
        scene = gaussian_scene("COMPACT", by_collection=False)
        splats = next(obj for obj in scene.objects if obj.name.startswith("Splats"))
        splats.is_holdout, splats.is_shadow_catcher = False, True
        _, stats = sync.build_render_scene(bpy.context.evaluated_depsgraph_get())
        self.assertEqual(stats.splats, len(CENTRES))
        self.assertTrue(any("Shadow Catcher" in message and splats.name in message for message in stats.warnings),
                        stats.warnings)


class VisibilityPanel(unittest.TestCase):
    def test_object_properties_show_holdout_and_shadow_catcher(self):
        # Object Properties > Visibility is Blender's own panel, shown for this engine, with Mask > Holdout and the
        # Shadow Catcher check box Cycles draws in its own panel.
        scene = st.reset_render_scene(32, 24, 1)
        bpy.ops.mesh.primitive_plane_add()
        obj = bpy.context.active_object
        panel = bpy.types.OBJECT_PT_visibility
        self.assertIn("RAYSPLATS", panel.COMPAT_ENGINES)
        context = types.SimpleNamespace(engine=scene.render.engine, object=obj, scene=scene,
                                        workspace=types.SimpleNamespace(use_filter_by_owner=False))
        drawn = []
        panel.draw(types.SimpleNamespace(layout=st.RecordingLayout(drawn)), context)
        self.assertLessEqual({("Object", "is_holdout"), ("Object", "is_shadow_catcher")},
                             {(owner, name) for owner, name, _ in drawn})


if __name__ == "__main__":
    unittest.main()
