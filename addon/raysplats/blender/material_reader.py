# The one reader of Blender materials (docs/design.md §6): what the renderer (engine/material_table.py) and every
# exporter (io/export_mesh.py) take a material to be. It follows the active Material Output's Surface link to the shader
# that is really connected: the Principled BSDF and the simple BSDF nodes, with a base-colour image texture when Base
# Color (or a Diffuse BSDF's Color) is linked from an Image Texture node. Nodes not connected to the output do not
# count, so an Emission-driven material is read as emission whatever other shaders sit in its tree.
#
# What a texture link may look like (anything else keeps the socket's unconnected value, with a warning):
#   Image Texture "Color" -> Base Color, the node's Vector unlinked (the default UV map), or linked from a
#   UV Map node's "UV" or a Texture Coordinate node's "UV"; Reroute nodes in between are followed.
# The image goes to the renderer as a float32 H x W x C array (row 0 = bottom, as Image.pixels), read once per
# image with one foreach_get. Native sampling is bilinear with repeat wrapping (material.cpp): the node's
# "Closest" and "Cubic" interpolation are drawn as "Linear" (differences only within a texel); an extension
# other than "Repeat" gets a warning (it differs only outside [0, 1] and at the border half-texel).

import numpy as np

from . import compat

# What the renderer takes for a keyword read_material leaves out, and for a slot without material: the defaults of
# the native RenderScene.add_material (native/python/render_bindings.cpp).
RENDERER_DEFAULTS = {"base_color": (0.8, 0.8, 0.8), "metallic": 0.0, "roughness": 0.5, "alpha": 1.0,
                     "emission_color": (0.0, 0.0, 0.0), "emission_strength": 1.0}
# Principled v1 (Blender 3.x) has the principled (Disney) diffuse, v2 (4.0) a Lambertian one (see compat).
PRINCIPLED_VERSION = compat.PRINCIPLED_VERSION
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
        if not link.is_valid or link.is_muted:
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


def _texture(material, socket, warn, images):
    """(kwargs, uv_map) of an Image Texture linked into a colour socket, or None when there is none that can
    be used (a warning says why if something is linked); the pixels come from `images` (an ImageCache)."""
    source = _linked_from(socket)
    if source is None:
        return None
    node, output = source
    where = f"Material '{material.name}': {socket.name}"
    if node.bl_idname != "ShaderNodeTexImage" or output.name != "Color":
        warn(f"{where} is linked from '{node.name}'; only an Image Texture's Color is supported, the "
             "unconnected value is used")
        return None
    if node.image is None:
        warn(f"{where}: Image Texture '{node.name}' has no image; the unconnected value is used")
        return None
    if node.projection != "FLAT":
        warn(f"{where}: Image Texture '{node.name}' uses {node.projection} projection; only Flat is "
             "supported, the unconnected value is used")
        return None
    uv_map = ""
    vector = _linked_from(node.inputs["Vector"])
    if vector is not None:
        vector_node, vector_output = vector
        if vector_node.bl_idname == "ShaderNodeUVMap":
            uv_map = vector_node.uv_map
        elif not (vector_node.bl_idname == "ShaderNodeTexCoord" and vector_output.name == "UV"):
            warn(f"{where}: the Vector of Image Texture '{node.name}' comes from '{vector_node.name}'; "
                 "only UV maps are supported, the unconnected value is used")
            return None
    if node.extension != "REPEAT":
        warn(f"{where}: Image Texture '{node.name}' extension {node.extension} is rendered as Repeat")
    image = images.get(node.image)
    if image is None:
        return None
    pixels, srgb = image
    return {"base_color_texture": pixels, "texture_srgb": srgb}, uv_map


def read_material(material, warn, images=None):
    """(keyword arguments of the native RenderScene.add_material, uv_map) of a Blender material: what its connected
    shader says the surface is. uv_map says which UV map its texture reads: None (no texture), "" (the mesh's default
    UV map) or a UV map name. Base-colour textures are read only with `images` (an ImageCache); without, the
    socket's unconnected value stands (the mesh files carry no textures). `warn` receives what is left out."""
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
        texture = _texture(material, node.inputs["Base Color"], warn, images) if images is not None else None
        linked = [s.name for s in node.inputs if s.is_linked and s.name in
                  ("Metallic", "Roughness", "Transmission", "Transmission Weight")]
        if linked:
            warn(f"Material '{material.name}': textures or node inputs on {', '.join(linked)} are not "
                 "supported yet; their unconnected values are used")
        left_out = [name for name in _UNSUPPORTED_LAYERS[PRINCIPLED_VERSION]
                    if find_input(node, name) is not None and
                    (find_input(node, name).is_linked or input_value(node, 0.0, name) > 0.0)]
        if left_out:
            warn(f"Material '{material.name}': {', '.join(left_out)} is not supported; rendered without it")
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
        texture = _texture(material, node.inputs["Color"], warn, images) if images is not None else None
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
        warn(f"Material '{material.name}': '{node.name}' is not a Principled BSDF; its viewport colour is "
             "used")
        return fallback, None
    if texture is None:
        return kwargs, None
    texture_kwargs, uv_map = texture
    kwargs.update(texture_kwargs)
    return kwargs, uv_map

