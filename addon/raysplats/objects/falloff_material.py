# The material imported Gaussian objects get: unlit splat colour with the exact Gaussian falloff
# alpha = a * exp(-|uv|^2 / 2), uv being the corner's local polygon coordinates (docs/design.md §5), so Material
# Preview (EEVEE) shows the splats as they are.
import bpy

from ..blender import compat
from .polygon_mesh import ATTR_COLOR, UV_MAP

MATERIAL_NAME = "RaySplats Gaussian"


def gaussian_material():
    material = bpy.data.materials.get(MATERIAL_NAME)
    if material is not None:
        return material
    material = bpy.data.materials.new(MATERIAL_NAME)
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()

    output = nodes.new("ShaderNodeOutputMaterial")
    output.location = (800, 0)
    color = nodes.new("ShaderNodeVertexColor")
    color.layer_name = ATTR_COLOR
    color.location = (-600, 200)
    uv = nodes.new("ShaderNodeUVMap")
    uv.uv_map = UV_MAP
    uv.location = (-800, -100)
    dot = nodes.new("ShaderNodeVectorMath")
    dot.operation = "DOT_PRODUCT"
    dot.location = (-600, -100)
    half = nodes.new("ShaderNodeMath")
    half.operation = "MULTIPLY"
    half.inputs[1].default_value = -0.5
    half.location = (-400, -100)
    falloff = nodes.new("ShaderNodeMath")
    falloff.operation = "EXPONENT"
    falloff.location = (-200, -100)
    alpha = nodes.new("ShaderNodeMath")
    alpha.operation = "MULTIPLY"
    alpha.use_clamp = True
    alpha.location = (0, 0)
    emission = nodes.new("ShaderNodeEmission")
    emission.location = (200, 200)
    transparent = nodes.new("ShaderNodeBsdfTransparent")
    transparent.location = (200, -150)
    mix = nodes.new("ShaderNodeMixShader")
    mix.location = (500, 0)

    links.new(uv.outputs["UV"], dot.inputs[0])
    links.new(uv.outputs["UV"], dot.inputs[1])
    links.new(dot.outputs["Value"], half.inputs[0])
    links.new(half.outputs[0], falloff.inputs[0])
    links.new(falloff.outputs[0], alpha.inputs[0])
    links.new(color.outputs["Alpha"], alpha.inputs[1])
    links.new(color.outputs["Color"], emission.inputs["Color"])
    links.new(alpha.outputs[0], mix.inputs["Fac"])
    links.new(transparent.outputs[0], mix.inputs[1])
    links.new(emission.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])

    set_eevee_transparency(material, sorted_blending=False)
    material.diffuse_color = (0.8, 0.8, 0.8, 1.0)
    return material


def set_eevee_transparency(material, sorted_blending=False):
    """How EEVEE (Material Preview) draws the splats' alpha.

    The default, sorted_blending=False, is stochastic transparency: Alpha Hashed on 3.x, Dithered on 4.2+. Each
    sample keeps a fragment with probability alpha and EEVEE's accumulated samples converge to the depth-ordered
    composite that the RaySplats render computes, whatever order the faces are drawn in. sorted_blending=True is
    alpha Blend (Blended on 4.2+): EEVEE sorts objects, not the faces inside one, so the back of a splat object
    is drawn over its front. It is kept for comparisons (examples/material_preview_agreement.py).
    Shadows follow the alpha (Hashed on 3.x, transparent shadows on 4.2+), as the renderer's shadow rays see
    the splats' transmittance."""
    if compat.MATERIAL_HAS_SURFACE_RENDER_METHOD:
        material.surface_render_method = "BLENDED" if sorted_blending else "DITHERED"
        material.use_transparent_shadow = True
    else:
        material.blend_method = "BLEND" if sorted_blending else "HASHED"
        material.shadow_method = "HASHED"
