# Blender materials -> indices in the native RenderScene, each converted once, by the add-on's one material reader
# (material_reader.py, docs/design.md §6), which the mesh exporter uses too.
from ..blender.material_reader import ImageCache, read_material


class MaterialTable:
    """Blender materials -> native material indices, converted once each.

    uv_map(material) says which UV map a material's texture reads: None (no texture), "" (the mesh's default
    UV map) or a UV map name; meshes using such a material hand per-corner UVs to the renderer."""

    def __init__(self, render_scene, warn):
        self.render_scene = render_scene
        self.warn = warn
        self.indices = {}
        self.uv_maps = {}
        self.names = set()  # of the materials converted (the Cryptomatte Material manifest)
        self.images = ImageCache(warn)
        self.default = render_scene.add_material()

    def index(self, material):
        if material is None:
            return self.default
        key = material.name_full
        if key not in self.indices:
            kwargs, uv_map = read_material(material, self.warn, self.images)
            # (The Material Index pass's value, which no exporter needs, so not the reader's.)
            self.indices[key] = self.render_scene.add_material(pass_index=material.pass_index, **kwargs)
            # (Cycles' shaders take the material's name, which Cryptomatte Material hashes.)
            self.render_scene.set_material_cryptomatte_name(self.indices[key], material.name)
            self.names.add(material.name)
            self.uv_maps[key] = uv_map
        return self.indices[key]

    def uv_map(self, material):
        if material is None:
            return None
        self.index(material)
        return self.uv_maps[material.name_full]
