# Blender materials -> native materials (DESIGN §6): the Principled BSDF and the simple BSDF nodes, with a
# base-colour image texture when Base Color (or a Diffuse BSDF's Color) is linked from an Image Texture node.
#
# What a texture link may look like (anything else keeps the socket's unconnected value, with a warning):
#   Image Texture "Color" -> Base Color, the node's Vector unlinked (the default UV map), or linked from a
#   UV Map node's "UV" or a Texture Coordinate node's "UV"; Reroute nodes in between are followed.
# The image goes to the renderer as a float32 H x W x C array (row 0 = bottom, as Image.pixels), read once per
# image with one foreach_get. Native sampling is bilinear with repeat wrapping (material.cpp): the node's
# "Closest" and "Cubic" interpolation are drawn as "Linear" (differences only within a texel); an extension
# other than "Repeat" gets a warning (it differs only outside [0, 1] and at the border half-texel).

import bpy
import numpy as np

# Cycles' Principled BSDF v1 (Blender 2.8-3.x) has the principled (Disney) diffuse with roughness-dependent
# retro-reflection; v2 (Blender 4.x) a Lambertian diffuse under an energy-conserving dielectric specular layer, F82-tint
# metal and Specular IOR Level / Specular Tint inputs (native/src/render/bsdf.h models both).
PRINCIPLED_VERSION = "V1" if bpy.app.version < (4, 0, 0) else "V2"
PRINCIPLED_DIFFUSE = "PRINCIPLED" if PRINCIPLED_VERSION == "V1" else "LAMBERT"
# Principled lobes RaySplats leaves out, by the inputs that switch them on (names of Blender 3.x and 4.x).
_UNSUPPORTED_LAYERS = {"V1": ("Subsurface", "Sheen", "Clearcoat"),
                       "V2": ("Subsurface Weight", "Sheen Weight", "Coat Weight", "Thin Film Thickness")}


def find_input(node, *names):
    """The first of the named inputs a node has (Blender 4 renamed several Principled inputs)."""
    for name in names:
        socket = node.inputs.get(name)
        if socket is not None:
            return socket
    return None


def input_value(node, default, *names):
    socket = find_input(node, *names)
    if socket is None:
        return default
    value = socket.default_value
    try:
        return tuple(value)[:3]
    except TypeError:
        return float(value)


def _linked_from(socket):
    """The (node, output socket) feeding `socket`, following Reroute nodes; None if unlinked or muted."""
    while socket is not None and socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or getattr(link, "is_muted", False):
            return None
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            socket = node.inputs[0]
            continue
        return node, link.from_socket
    return None


# Byte images in these colour spaces hold sRGB-encoded values (Cycles decodes them after filtering, svm/image.h
# NODE_IMAGE_COMPRESS_AS_SRGB); those in the data spaces hold values used as they are.
_SRGB_SPACES = {"sRGB"}
_RAW_SPACES = {"Non-Color", "Raw", "Linear", "Linear Rec.709", "Linear CIE-XYZ E", "Linear CIE-XYZ D65",
               "Utility - Raw"}


class ImageCache:
    """Image -> (pixels H x W x C float32, srgb) read once, or None (with a warning) if it has no pixels."""

    def __init__(self, warn):
        self.warn = warn
        self.images = {}

    def get(self, image):
        key = image.name_full
        if key not in self.images:
            self.images[key] = self._read(image)
        return self.images[key]

    def _read(self, image):
        width, height = image.size
        channels = image.channels
        if width * height == 0 or channels not in (1, 3, 4):
            self.warn(f"Image '{image.name}' has no pixels that can be read (missing file?); materials using it "
                      "keep their unconnected colour")
            return None
        if image.source == "TILED":
            self.warn(f"Image '{image.name}': UDIM tiles are not supported; the first tile is used")
        pixels = np.empty(width * height * channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        # Blender converts float images to scene linear itself (Cycles BlenderImageLoader: "Float images are
        # already converted on the Blender side"); byte images keep the values of their colour space.
        space = image.colorspace_settings.name
        srgb = not image.is_float and space in _SRGB_SPACES
        if not image.is_float and space not in _SRGB_SPACES and space not in _RAW_SPACES:
            self.warn(f"Image '{image.name}': colour space '{space}' is not supported; its values are used as "
                      "linear (Non-Color)")
        return pixels.reshape(height, width, channels), srgb


class MaterialTable:
    """Blender materials -> native material indices, converted once each.

    uv_map(material) says which UV map a material's texture reads: None (no texture), "" (the mesh's default
    UV map) or a UV map name; meshes using such a material hand per-corner UVs to the renderer."""

    def __init__(self, render_scene, warn):
        self.render_scene = render_scene
        self.warn = warn
        self.indices = {}
        self.uv_maps = {}
        self.images = ImageCache(warn)
        self.default = render_scene.add_material()

    def index(self, material):
        if material is None:
            return self.default
        key = material.name_full
        if key not in self.indices:
            kwargs, uv_map = self._convert(material)
            self.indices[key] = self.render_scene.add_material(**kwargs)
            self.uv_maps[key] = uv_map
        return self.indices[key]

    def uv_map(self, material):
        if material is None:
            return None
        self.index(material)
        return self.uv_maps[material.name_full]

    def _texture(self, material, socket):
        """(kwargs, uv_map) of an Image Texture linked into a colour socket, or None when there is none that can
        be used (a warning says why if something is linked)."""
        source = _linked_from(socket)
        if source is None:
            return None
        node, output = source
        where = f"Material '{material.name}': {socket.name}"
        if node.bl_idname != "ShaderNodeTexImage" or output.name != "Color":
            self.warn(f"{where} is linked from '{node.name}'; only an Image Texture's Color is supported, the "
                      "unconnected value is used")
            return None
        if node.image is None:
            self.warn(f"{where}: Image Texture '{node.name}' has no image; the unconnected value is used")
            return None
        if node.projection != "FLAT":
            self.warn(f"{where}: Image Texture '{node.name}' uses {node.projection} projection; only Flat is "
                      "supported, the unconnected value is used")
            return None
        uv_map = ""
        vector = _linked_from(node.inputs["Vector"])
        if vector is not None:
            vector_node, vector_output = vector
            if vector_node.bl_idname == "ShaderNodeUVMap":
                uv_map = vector_node.uv_map
            elif not (vector_node.bl_idname == "ShaderNodeTexCoord" and vector_output.name == "UV"):
                self.warn(f"{where}: the Vector of Image Texture '{node.name}' comes from '{vector_node.name}'; "
                          "only UV maps are supported, the unconnected value is used")
                return None
        if node.extension != "REPEAT":
            self.warn(f"{where}: Image Texture '{node.name}' extension {node.extension} is rendered as Repeat")
        image = self.images.get(node.image)
        if image is None:
            return None
        pixels, srgb = image
        return {"base_color_texture": pixels, "texture_srgb": srgb}, uv_map

    def _convert(self, material):
        """(add_material keyword arguments, uv_map) of a Blender material."""
        fallback = {"base_color": tuple(material.diffuse_color)[:3], "metallic": float(material.metallic),
                    "roughness": float(material.roughness)}
        if not material.use_nodes or material.node_tree is None:
            return fallback, None
        output = next((n for n in material.node_tree.nodes
                       if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output), None)
        surface = output.inputs["Surface"] if output else None
        if surface is None or not surface.is_linked:
            return fallback, None
        node = surface.links[0].from_node
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            texture = self._texture(material, node.inputs["Base Color"])
            linked = [s.name for s in node.inputs if s.is_linked and s.name in
                      ("Metallic", "Roughness", "Transmission", "Transmission Weight")]
            if linked:
                self.warn(f"Material '{material.name}': textures or node inputs on {', '.join(linked)} are not "
                          "supported yet; their unconnected values are used")
            left_out = [name for name in _UNSUPPORTED_LAYERS[PRINCIPLED_VERSION]
                        if find_input(node, name) is not None and
                        (find_input(node, name).is_linked or input_value(node, 0.0, name) > 0.0)]
            if left_out:
                self.warn(f"Material '{material.name}': {', '.join(left_out)} is not supported; rendered without it")
            specular = input_value(node, 0.5, "Specular", "Specular IOR Level")
            kwargs = {
                "base_color": input_value(node, (0.8, 0.8, 0.8), "Base Color"),
                "metallic": input_value(node, 0.0, "Metallic"),
                "roughness": input_value(node, 0.5, "Roughness"),
                "specular": min(1.0, max(0.0, specular)),
                "transmission": input_value(node, 0.0, "Transmission Weight", "Transmission"),
                "ior": max(1.0, input_value(node, 1.45, "IOR")),
                "emission_color": input_value(node, (0.0, 0.0, 0.0), "Emission Color", "Emission"),
                "emission_strength": input_value(node, 1.0, "Emission Strength"),
                "alpha": input_value(node, 1.0, "Alpha"),
                "diffuse_model": PRINCIPLED_DIFFUSE,
            }
            if PRINCIPLED_VERSION == "V2":
                # Specular IOR Level has no upper bound in v2 (F0 = F0(IOR) * 2 * level, clamped to 0.99 natively).
                kwargs.update(principled_version="V2", specular=max(0.0, specular),
                              specular_tint=input_value(node, (1.0, 1.0, 1.0), "Specular Tint"),
                              multiscatter=node.distribution == "MULTI_GGX")
        elif kind == "ShaderNodeBsdfDiffuse":
            texture = self._texture(material, node.inputs["Color"])
            kwargs = {"base_color": input_value(node, (0.8, 0.8, 0.8), "Color"), "roughness": 1.0, "specular": 0.0}
        elif kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            return {"base_color": input_value(node, (0.8, 0.8, 0.8), "Color"), "metallic": 1.0,
                    "roughness": input_value(node, 0.5, "Roughness")}, None
        elif kind == "ShaderNodeBsdfGlass":
            return {"base_color": input_value(node, (1.0, 1.0, 1.0), "Color"), "transmission": 1.0,
                    "roughness": input_value(node, 0.0, "Roughness"),
                    "ior": max(1.0, input_value(node, 1.45, "IOR"))}, None
        elif kind == "ShaderNodeEmission":
            return {"base_color": (0.0, 0.0, 0.0), "specular": 0.0,
                    "emission_color": input_value(node, (1.0, 1.0, 1.0), "Color"),
                    "emission_strength": input_value(node, 1.0, "Strength")}, None
        else:
            self.warn(f"Material '{material.name}': '{node.name}' is not a Principled BSDF; its viewport colour is "
                      "used")
            return fallback, None
        if texture is None:
            return kwargs, None
        texture_kwargs, uv_map = texture
        kwargs.update(texture_kwargs)
        return kwargs, uv_map
