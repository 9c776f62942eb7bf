#include "raysplats/render/light.h"

#include <cmath>
#include <string>

#include "raysplats/errors.h"

namespace raysplats {

void Light::validate(const char* what) const {
    auto require = [&](bool ok, const char* problem) {
        if (!ok) throw InvalidArgument(std::string(what) + ": " + problem);
    };
    light_to_world.check_affine((std::string(what) + " light_to_world").c_str());
    for (float v : {color[0], color[1], color[2], power, spot_size, spot_blend, size_x, size_y, sun_angle})
        require(std::isfinite(v), "has a NaN or Inf parameter");
    require(color[0] >= 0 && color[1] >= 0 && color[2] >= 0, "colour must be >= 0");
    require(power >= 0, "power must be >= 0");
    require(spot_size > 0 && spot_size <= 3.14159266f, "spot size must be in (0, pi]");
    require(spot_blend >= 0 && spot_blend <= 1, "spot blend must be in [0, 1]");
    require(size_x > 0 && size_y > 0, "area light size must be > 0");
    require(sun_angle >= 0 && sun_angle <= 3.14159266f, "sun angle must be in [0, pi]");
}

}  // namespace raysplats
