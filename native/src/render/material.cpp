#include "raysplats/render/material.h"

#include <cmath>
#include <string>

#include "raysplats/errors.h"

namespace raysplats {
namespace {

void require(bool ok, const char* what, const std::string& problem) {
    if (!ok) throw InvalidArgument(std::string(what) + ": " + problem);
}

}  // namespace

void Material::validate(const char* what) const {
    for (float v : {base_color[0], base_color[1], base_color[2], metallic, roughness, specular, transmission, ior,
                    emission_color[0], emission_color[1], emission_color[2], emission_strength, alpha,
                    specular_tint[0], specular_tint[1], specular_tint[2]})
        require(std::isfinite(v), what, "has a NaN or Inf parameter");
    require(base_color[0] >= 0 && base_color[1] >= 0 && base_color[2] >= 0, what, "base colour must be >= 0");
    require(metallic >= 0 && metallic <= 1, what, "metallic must be in [0, 1]");
    require(roughness >= 0 && roughness <= 1, what, "roughness must be in [0, 1]");
    if (principled_version == PrincipledVersion::V1)
        require(specular >= 0 && specular <= 1, what, "specular must be in [0, 1]");
    else
        require(specular >= 0, what, "specular IOR level must be >= 0");
    require(specular_tint[0] >= 0 && specular_tint[1] >= 0 && specular_tint[2] >= 0, what,
            "specular tint must be >= 0");
    require(transmission >= 0 && transmission <= 1, what, "transmission must be in [0, 1]");
    require(alpha >= 0 && alpha <= 1, what, "alpha must be in [0, 1]");
    require(ior > 0, what, "IOR must be > 0");
    require(emission_strength >= 0 && emission_color[0] >= 0 && emission_color[1] >= 0 && emission_color[2] >= 0,
            what, "emission must be >= 0");
    if (base_color_texture.pixels) {
        require(base_color_texture.width > 0 && base_color_texture.height > 0, what, "texture size must be > 0");
        const int c = base_color_texture.channels;
        require(c == 1 || c == 3 || c == 4, what, "texture channels must be 1, 3 or 4");
        const std::size_t n = std::size_t(base_color_texture.width) * std::size_t(base_color_texture.height) * std::size_t(c);
        for (std::size_t i = 0; i < n; ++i)
            if (!std::isfinite(base_color_texture.pixels[i]))
                require(false, what, "texture texel " + std::to_string(i / std::size_t(c)) + " has a NaN or Inf value");
    }
}

}  // namespace raysplats
