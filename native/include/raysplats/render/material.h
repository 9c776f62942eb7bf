// A Principled-BSDF-like material (Blender 3.x Principled v1 or 4.x Principled v2 subset) for meshes
// (docs/design.md §6).
#pragma once

#include <array>
#include <cstdint>

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

// Which Cycles Principled BSDF the material follows (bsdf.h says what each models).
enum class PrincipledVersion {
    V1,  // Blender 2.8-3.x: one specular layer with interpolated Fresnel, F0 = 0.08 * specular
    // Blender 4.x (Cycles svm/closure.h, CLOSURE_BSDF_PRINCIPLED_ID): F82-tint metal, a dielectric specular layer with
    // real Fresnel from the IOR (scaled by "Specular IOR Level") over the diffuse base, energy-conserving layering,
    // glass transmission tinted by sqrt(base colour), optional multiple-scattering GGX energy compensation.
    V2,
};

struct Material {
    std::array<float, 3> base_color{0.8f, 0.8f, 0.8f};  // linear RGB
    // When pixels != nullptr the texture replaces base_color: sampled bilinearly at the mesh UVs, wrapping (repeat).
    ImageTexture base_color_texture;
    float metallic = 0.0f;
    float roughness = 0.5f;      // GGX alpha = roughness^2; below 0.02 the lobes are perfectly specular
    // V1: dielectric reflectance F0 = 0.08 * specular (Blender 3.x Principled). The specular layer (metal and
    // dielectric in one, as Cycles 3.x does) has F0 colour cspec0 = lerp(0.08 * specular, base, metallic) and the
    // Fresnel of Cycles' interpolate_fresnel_color: cspec0 + (1 - cspec0) * normalised dielectric Fresnel.
    // V2: "Specular IOR Level" (>= 0, 0.5 = the IOR's own reflectance): dielectric F0 = F0(ior) * 2 * specular.
    float specular = 0.5f;
    PrincipledVersion principled_version = PrincipledVersion::V1;
    std::array<float, 3> specular_tint{1.0f, 1.0f, 1.0f};  // V2: tints dielectric F0 and is the metals' F82 tint
    bool multiscatter = false;  // V2: "Multiscatter GGX" (energy compensation of the GGX lobes) instead of "GGX"
    DiffuseModel diffuse_model = DiffuseModel::Lambert;
    float transmission = 0.0f;   // weight of the glass lobe
    float ior = 1.45f;
    std::array<float, 3> emission_color{0.0f, 0.0f, 0.0f};
    float emission_strength = 1.0f;  // emitted radiance = emission_color * emission_strength
    float alpha = 1.0f;              // coverage; 1 - alpha of the rays pass through unchanged
    std::uint32_t pass_index = 0;    // Blender's Material.pass_index, which the Material Index pass shows
    float cryptomatte_id = 0.0f;     // its name's Cryptomatte id (Scene::set_material_cryptomatte_name; 0: none)

    // Throws InvalidArgument (naming `what`) for NaN, out-of-range values or an inconsistent texture.
    void validate(const char* what) const;
};

}  // namespace raysplats
