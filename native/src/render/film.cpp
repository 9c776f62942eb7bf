#include "raysplats/render/film.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>

#include "raysplats/errors.h"
#include "render_math.h"

namespace raysplats {
namespace {

// Writes through a temporary file in the same folder and renames it over `path`, so a failed write never
// leaves a half-written file in place of a good one.
template <typename Write>
void write_atomically(const std::string& path, Write write) {
    const std::string tmp = path + ".tmp-raysplats";
    if (!write(tmp)) {
        std::remove(tmp.c_str());
        throw Error("cannot write '" + path + "'");
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        std::remove(tmp.c_str());
        throw Error("cannot rename the temporary file onto '" + path + "'");
    }
}

}  // namespace

void Film::resize(int w, int h) {
    allocate(w, h);
    clear(0, 0, w, h);
}

void Film::allocate(int w, int h) {
    width = w;
    height = h;
    const std::size_t n = pixel_count();
    rgba.resize(4 * n);
    depth.resize(n);
    normal.resize(3 * n);
    alpha.resize(n);
}

void Film::clear(int x0, int y0, int x1, int y1) {
    for (int y = y0; y < y1; ++y) {
        const std::size_t begin = std::size_t(y) * width + x0, end = std::size_t(y) * width + x1;
        std::fill(rgba.begin() + 4 * begin, rgba.begin() + 4 * end, 0.0f);
        std::fill(depth.begin() + begin, depth.begin() + end, std::numeric_limits<float>::infinity());
        std::fill(normal.begin() + 3 * begin, normal.begin() + 3 * end, 0.0f);
        std::fill(alpha.begin() + begin, alpha.begin() + end, 0.0f);
    }
}

void Film::write_png(const std::string& path) const {
    std::vector<unsigned char> bytes(4 * pixel_count());
    for (std::size_t i = 0; i < pixel_count(); ++i) {
        const float a = rgba[4 * i + 3];
        for (int c = 0; c < 3; ++c) {
            // Un-premultiply for PNG's straight alpha.
            float v = a > 0.0f ? rgba[4 * i + c] / a : 0.0f;
            v = linear_to_srgb(std::clamp(v, 0.0f, 1.0f));
            bytes[4 * i + c] = (unsigned char)std::lround(255.0f * v);
        }
        bytes[4 * i + 3] = (unsigned char)std::lround(255.0f * std::clamp(a, 0.0f, 1.0f));
    }
    write_atomically(path, [&](const std::string& tmp) {
        return stbi_write_png(tmp.c_str(), width, height, 4, bytes.data(), 4 * width) != 0;
    });
}

void Film::write_pfm(const std::string& path) const {
    write_atomically(path, [&](const std::string& tmp) {
        FILE* f = std::fopen(tmp.c_str(), "wb");
        if (!f) return false;
        // PFM: rows bottom to top, little endian (negative scale).
        std::fprintf(f, "PF\n%d %d\n-1.0\n", width, height);
        std::vector<float> row(3 * std::size_t(width));
        bool ok = true;
        for (int y = height - 1; y >= 0 && ok; --y) {
            for (int x = 0; x < width; ++x)
                for (int c = 0; c < 3; ++c) row[3 * x + c] = rgba[4 * (std::size_t(y) * width + x) + c];
            ok = std::fwrite(row.data(), sizeof(float), row.size(), f) == row.size();
        }
        return std::fclose(f) == 0 && ok;
    });
}

}  // namespace raysplats
