# The add-on's one material reader (material_reader.py): the renderer and the mesh exporter take a material to be the
# same thing. An Emission-driven material (a red Principled BSDF left unconnected, a green Emission shader connected
# to the output) renders green and is exported green; a plain Principled material exports its own values, as the
# renderer is given them.
import os
import unittest

import bpy
import mathutils
import numpy as np

import mesh_export_testing as mt
import splat_testing as st
from raysplats.engine.material_table import MaterialTable

RED, GREEN = (1.0, 0.0, 0.0, 1.0), (0.0, 1.0, 0.0, 1.0)


class RecordingRenderScene:
    """Stands in for the native RenderScene: keeps the keyword arguments each add_material was given (and the
    Cryptomatte name the table gives each material)."""

    def __init__(self):
        self.materials = []
        self.cryptomatte_names = {}

    def add_material(self, **kwargs):
        self.materials.append(kwargs)
        return len(self.materials) - 1

    def set_material_cryptomatte_name(self, index, name):
        self.cryptomatte_names[index] = name


def renderer_input(material):
    """The add_material keyword arguments the renderer gets for `material` (through the engine's MaterialTable)."""
    scene = RecordingRenderScene()
    index = MaterialTable(scene, warn=print).index(material)
    assert scene.cryptomatte_names[index] == material.name
    return scene.materials[index]


def emission_driven_material():
    """A red Principled BSDF that is not connected, and a green Emission shader that is (strength 1)."""
    material = bpy.data.materials.new("Emission Driven")
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    principled = nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = RED
    output = nodes["Material Output"]
    for link in list(output.inputs["Surface"].links):
        links.remove(link)
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = GREEN
    emission.inputs["Strength"].default_value = 1.0
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return material


def add_cube(material):
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.view_layer.objects.active
    cube.data.materials.append(material)
    return cube


def exported_gltf_material(name):
    doc = mt.gltf_json(mt.export_mesh(name + ".glb"))
    (material,) = [m for m in doc["materials"] if m["name"] == name]
    return material["pbrMetallicRoughness"]


def exported_mtl(name):
    """{"Kd": [r, g, b], "d": [a], "Pr": [...], "Pm": [...]} of material `name` in the .mtl of an OBJ export."""
    stem = os.path.splitext(mt.export_mesh(name.replace(" ", "_") + ".obj"))[0]
    values, current = {}, None
    with open(stem + ".mtl") as f:
        for line in f:
            parts = line.split()
            if parts[:1] == ["newmtl"]:
                current = " ".join(parts[1:])
            elif parts and current is not None and current.replace("_", " ") == name:
                values[parts[0]] = [float(p) for p in parts[1:]]
    return values


class EmissionDrivenMaterial(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        self.material = emission_driven_material()
        add_cube(self.material)

    def test_the_renderer_is_given_the_connected_emission(self):
        given = renderer_input(self.material)
        np.testing.assert_allclose(given["emission_color"], GREEN[:3])
        self.assertEqual(given["emission_strength"], 1.0)
        np.testing.assert_allclose(given["base_color"], (0.0, 0.0, 0.0))

    def test_it_renders_green(self):
        scene = bpy.context.scene
        scene.render.engine = "RAYSPLATS"
        scene.render.resolution_x, scene.render.resolution_y = 16, 16
        scene.render.resolution_percentage = 100
        scene.raysplats.samples = 1
        scene.view_settings.view_transform = "Standard"
        scene.world = bpy.data.worlds.new("Black")
        scene.world.use_nodes = False
        st.set_world_color(scene.world, (0.0, 0.0, 0.0))
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        camera.location = (0.0, -6.0, 0.0)
        camera.rotation_euler = mathutils.Vector((0.0, 1.0, 0.0)).to_track_quat("-Z", "Y").to_euler()
        scene.camera = camera
        image = st.render_to_array("emission_driven")
        # The cube fills the middle of the view; with a black world and no lights its only light is its emission.
        np.testing.assert_allclose(image[6:10, 6:10, :3].reshape(-1, 3).mean(axis=0), GREEN[:3], atol=1e-3)

    def test_gltf_and_obj_get_the_colour_the_renderer_is_given(self):
        given = renderer_input(self.material)
        gltf = exported_gltf_material(self.material.name)
        np.testing.assert_allclose(gltf["baseColorFactor"], [*given["emission_color"], 1.0], atol=1e-6)
        mtl = exported_mtl(self.material.name)
        np.testing.assert_allclose(mtl["Kd"], given["emission_color"], atol=1e-6)
        # Not the unconnected Principled BSDF's red.
        self.assertNotAlmostEqual(gltf["baseColorFactor"][0], RED[0])


class PrincipledMaterial(unittest.TestCase):
    """The usual case is unchanged: base colour, alpha, metallic and roughness of the connected Principled BSDF."""

    def setUp(self):
        st.reset_scene()
        self.material = bpy.data.materials.new("Plain Principled")
        self.material.use_nodes = True
        principled = self.material.node_tree.nodes["Principled BSDF"]
        principled.inputs["Base Color"].default_value = (0.8, 0.1, 0.05, 1.0)
        principled.inputs["Metallic"].default_value = 0.25
        principled.inputs["Roughness"].default_value = 0.4
        principled.inputs["Alpha"].default_value = 0.5
        add_cube(self.material)

    def test_gltf_and_obj_get_the_principled_values_the_renderer_is_given(self):
        given = renderer_input(self.material)
        np.testing.assert_allclose(given["base_color"], (0.8, 0.1, 0.05), atol=1e-6)
        self.assertAlmostEqual(given["alpha"], 0.5, places=6)
        gltf = exported_gltf_material(self.material.name)
        np.testing.assert_allclose(gltf["baseColorFactor"], [*given["base_color"], given["alpha"]], atol=1e-6)
        self.assertAlmostEqual(gltf["metallicFactor"], given["metallic"], places=6)
        self.assertAlmostEqual(gltf["roughnessFactor"], given["roughness"], places=6)
        self.assertAlmostEqual(gltf["metallicFactor"], 0.25, places=6)
        self.assertAlmostEqual(gltf["roughnessFactor"], 0.4, places=6)
        mtl = exported_mtl(self.material.name)
        np.testing.assert_allclose(mtl["Kd"], given["base_color"], atol=1e-6)
        self.assertAlmostEqual(mtl["d"][0], 0.5, places=6)
        self.assertAlmostEqual(mtl["Pm"][0], 0.25, places=6)
        self.assertAlmostEqual(mtl["Pr"][0], 0.4, places=6)
