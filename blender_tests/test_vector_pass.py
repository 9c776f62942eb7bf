# The Vector pass (View Layer > Passes > Vector, Blender's use_pass_vector), as Cycles writes it for the
# compositor's Vector Blur node: four components, the motion on the image in pixels (y up) of the surface a pixel
# sees, to the previous frame (X, Y = raster(previous) - raster(now)) and from the next (Z, W = raster(now) -
# raster(next)); written with Motion Blur off (Cycles leaves it empty with motion blur on, and so does RaySplats):
# - analytic, orthographic: a plane moving 30 px a frame along +X and a camera moving 15 px a frame along +Y give
#   (-30, +15, -30, +15) on the plane and 0 on the world, within 1e-3 px; a splat object moving likewise gives the same
#   where it covers the pixel;
# - analytic, perspective: a still plane seen by a camera moving along its view axis gives each pixel the motion of
#   its Position-pass point under the pinhole projections of the previous and next frames, within 1e-3 px;
# - against Cycles: a moving cube and a moving, turning camera (perspective): over the pixels inside an object in both
#   (the same Object Index in the pixel's 3 x 3 neighbourhood), mean |difference| within VECTOR_TOLERANCE px.
import unittest

import bpy
import numpy as np

import splat_testing as st

WIDTH, HEIGHT = 120, 60
ORTHO_SCALE = 4.0  # scene units across the width: 30 pixels per unit
# Mean |difference| (px) over pixels inside an object. RaySplats writes the pixel's first sample (as Position), Cycles
# averages its samples: inside a pixel the vector varies by its gradient (up to about 0.2 px a pixel here, the cube
# turning), so the two differ by about a quarter of it.
VECTOR_TOLERANCE = 0.1


def base_scene(camera_type, samples=4):
    scene = st.camera_above_scene(WIDTH, HEIGHT, samples, camera_type, ORTHO_SCALE)
    scene.render.use_motion_blur = False
    bpy.context.view_layer.use_pass_vector = True
    bpy.context.view_layer.use_pass_position = True
    bpy.context.view_layer.use_pass_object_index = True
    return scene


def vector_and_position(exr):
    layer = next(name.split(".")[0] for name in exr)
    vector = np.stack([exr[f"{layer}.Vector.{c}"] for c in "XYZW"], axis=-1)
    position = np.stack([exr[f"{layer}.Position.{c}"] for c in "XYZ"], axis=-1)
    return vector, position


class Analytic(unittest.TestCase):
    def check_ortho(self, obj, name):
        scene = bpy.context.scene
        st.drive(obj, "location", 0, "(frame - 5) * 1.0")  # 30 px a frame along +X
        st.drive(scene.camera, "location", 1, "(frame - 5) * 0.5")  # 15 px a frame along +Y
        scene.frame_set(5)
        vector, position = vector_and_position(st.render_multilayer_exr(name))
        covered = np.any(position != 0.0, axis=-1)
        self.assertGreater(int(covered.sum()), 200, "the object is in view")
        expected = np.array([-30.0, 15.0, -30.0, 15.0], dtype=np.float32)
        error = np.abs(vector[covered] - expected).max()
        print(f"\nVector ({name}), Blender {bpy.app.version_string}: {int(covered.sum())} px covered, max |error| "
              f"{error:.2e} px; world's max |vector| {np.abs(vector[~covered]).max():.2e}")
        self.assertLess(error, 1e-3)
        np.testing.assert_array_equal(vector[~covered], 0.0)
        self.assertEqual(scene.frame_current, 5)

    def test_moving_plane_and_camera(self):
        base_scene("ORTHO")
        bpy.ops.mesh.primitive_plane_add(size=1.0)
        plane = bpy.context.object
        plane.data.materials.append(st.emission_material("Plane"))
        self.check_ortho(plane, "vector_ortho_plane")

    def test_moving_splat_object(self):
        base_scene("ORTHO")
        obj = st.import_file("donut_sh0.ply")
        obj.scale = (5.0, 5.0, 5.0)
        self.check_ortho(obj, "vector_ortho_splats")

    def test_perspective_dolly(self):
        scene = base_scene("PERSP")
        camera = scene.camera
        camera.data.lens = 35.0
        bpy.ops.mesh.primitive_plane_add(size=6.0)
        bpy.context.object.data.materials.append(st.emission_material("Plane"))
        st.drive(camera, "location", 2, "10 - (frame - 5) * 0.5")
        scene.frame_set(5)
        vector, position = vector_and_position(st.render_multilayer_exr("vector_dolly"))
        covered = np.any(position != 0.0, axis=-1)
        # Pinhole of a camera at height z looking down -Z (sensor 36 mm across the width): raster x = w/2 + f X /
        # (z - Z), y up likewise, with f = lens / 36 * width pixels.
        f = 35.0 / 36.0 * WIDTH

        def raster(p, z):
            return np.stack((WIDTH / 2 + f * p[:, 0] / (z - p[:, 2]), HEIGHT / 2 + f * p[:, 1] / (z - p[:, 2])), -1)

        points = position[covered].astype(np.float64)
        now = raster(points, 10.0)
        expected = np.concatenate((raster(points, 10.5) - now, now - raster(points, 9.5)), axis=-1)
        error = np.abs(vector[covered] - expected).max()
        print(f"\nVector (dolly), Blender {bpy.app.version_string}: max |error| {error:.2e} px (largest vector "
              f"{np.abs(expected).max():.2f} px)")
        self.assertGreater(float(np.abs(expected).max()), 1.0)
        self.assertLess(error, 1e-3)

    def test_empty_with_motion_blur_on(self):
        scene = base_scene("ORTHO")
        bpy.ops.mesh.primitive_plane_add(size=1.0)
        st.drive(bpy.context.object, "location", 0, "(frame - 5) * 1.0")
        scene.frame_set(5)
        scene.render.use_motion_blur = True
        vector, _ = vector_and_position(st.render_multilayer_exr("vector_with_blur"))
        np.testing.assert_array_equal(vector, 0.0)


class AgainstCycles(unittest.TestCase):
    def test_moving_cube_and_camera_agree_with_cycles(self):
        scene = base_scene("PERSP", samples=16)
        scene.render.resolution_x, scene.render.resolution_y = 160, 120
        bpy.ops.mesh.primitive_cube_add(size=1.6)
        cube = bpy.context.object
        cube.pass_index = 1
        st.drive(cube, "location", 0, "(frame - 5) * 0.5")
        st.drive(cube, "rotation_euler", 2, "(frame - 5) * 0.2")
        bpy.ops.mesh.primitive_cube_add(size=1.2, location=(1.8, 0.9, -0.5))
        bpy.context.object.pass_index = 2
        camera = scene.camera
        camera.data.lens = 35.0
        st.drive(camera, "location", 2, "8 - (frame - 5) * 0.25")
        st.drive(camera, "rotation_euler", 2, "(frame - 5) * 0.025")
        scene.frame_set(5)
        results = {}
        for engine in ("CYCLES", "RAYSPLATS"):
            scene.render.engine = engine
            if engine == "CYCLES":
                st.use_cycles_on_cpu(scene, 16).max_bounces = 0
            exr = st.render_multilayer_exr(f"vector_{engine.lower()}")
            layer = next(name.split(".")[0] for name in exr)
            index_name = next(name for name in exr if name.split(".")[1] in ("IndexOB", "Object Index"))
            results[engine] = vector_and_position(exr)[0], exr[index_name]
        index = results["CYCLES"][1]
        inside = np.ones(index.shape, dtype=bool)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                for image in (results["CYCLES"][1], results["RAYSPLATS"][1]):
                    inside &= np.roll(np.roll(image, dy, axis=0), dx, axis=1) == index
        inside &= index > 0
        difference = np.abs(results["RAYSPLATS"][0][inside] - results["CYCLES"][0][inside])
        print(f"\nVector against Cycles, Blender {bpy.app.version_string} (160x120, 16 spp): {int(inside.sum())} px "
              f"inside objects, mean |difference| {difference.mean():.4f} px (limit {VECTOR_TOLERANCE}), max "
              f"{difference.max():.3f} px; largest vector {np.abs(results['CYCLES'][0][inside]).max():.2f} px")
        self.assertGreater(int(inside.sum()), 500)
        self.assertGreater(float(np.abs(results["CYCLES"][0][inside]).max()), 5.0, "the objects move")
        self.assertLessEqual(difference.mean(), VECTOR_TOLERANCE)
        self.assertLess(difference.max(), 0.5)


if __name__ == "__main__":
    unittest.main()
