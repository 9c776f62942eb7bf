// A Principled-BSDF-like material (Blender 3.x Principled subset) for meshes (DESIGN §6).
#pragma once

#include <array>

namespace raysplats {

// A float image shared with the caller (not copied): the caller keeps `pixels` alive while the scene lives.
// Row 0 is the BOTTOM row (v = 0), like Blender's Image.pixels; values are linear unless `srgb` is set.
struct ImageTexture {
    const float* pixels = nullptr;  // width * height * channels floats
    int width = 0;
    int height = 0;
    int channels = 4;   // 1, 3 or 4 (RGBA; alpha ignored)
    bool srgb = false;  // sRGB-encoded (an 8-bit sRGB image): decoded to linear after bilinear filtering
};

// Diffuse lobe of a material.
enum class DiffuseModel {
    Lambert,     // f = base / pi (Blender 4.x Principled v2, Diffuse BSDF with roughness 0)
    // Blender 2.8-3.x Principled v1 (Cycles bsdf_principled_diffuse.h, PRINCIPLED_DIFFUSE_FULL), Disney 2012:
    // f = base / pi * [(1 - FV/2)(1 - FL/2) + RR (FL + FV + FL FV (RR - 1))], F* = (1 - cos)^5,
    // RR = roughness * (1 + dot(L, V)) (retro-reflection, brighter towards the light for rough surfaces).
    Principled,
};

struct Material {
    std::array<float, 3> base_color{0.8f, 0.8f, 0.8f};  // linear RGB
    // When pixels != nullptr the texture replaces base_color: sampled bilinearly at the mesh UVs, wrapping (repeat).
    ImageTexture base_color_texture;
    float metallic = 0.0f;
    float roughness = 0.5f;      // GGX alpha = roughness^2; below 0.02 the lobes are perfectly specular
    // Dielectric reflectance F0 = 0.08 * specular (Blender 3.x Principled). The specular layer (metal and
    // dielectric in one, as Cycles 3.x does) has F0 colour cspec0 = lerp(0.08 * specular, base, metallic) and the
    // Fresnel of Cycles' interpolate_fresnel_color: cspec0 + (1 - cspec0) * normalised dielectric Fresnel.
    float specular = 0.5f;
    DiffuseModel diffuse_model = DiffuseModel::Lambert;
    float transmission = 0.0f;   // weight of the glass lobe
    float ior = 1.45f;
    std::array<float, 3> emission_color{0.0f, 0.0f, 0.0f};
    float emission_strength = 1.0f;  // emitted radiance = emission_color * emission_strength
    float alpha = 1.0f;              // coverage; 1 - alpha of the rays pass through unchanged

    // Throws InvalidArgument (naming `what`) for NaN, out-of-range values or an inconsistent texture.
    void validate(const char* what) const;
};

}  // namespace raysplats
