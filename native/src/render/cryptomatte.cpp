// Cryptomatte ids and a camera sample's coverage (raysplats/render/cryptomatte.h).
#include "raysplats/render/cryptomatte.h"

#include <algorithm>
#include <cstring>

#include "raysplats/render/render_settings.h"

namespace raysplats {

namespace {

inline std::uint32_t rotl32(std::uint32_t x, int r) { return (x << r) | (x >> (32 - r)); }

}  // namespace

std::uint32_t cryptomatte_hash(std::string_view name) {
    // MurmurHash3_x86_32 (Austin Appleby, MurmurHash3.cpp), seed 0: 4-byte little-endian blocks, then the tail.
    const auto* data = reinterpret_cast<const unsigned char*>(name.data());
    const std::size_t len = name.size();
    constexpr std::uint32_t c1 = 0xcc9e2d51u, c2 = 0x1b873593u;
    std::uint32_t h1 = 0;
    const std::size_t blocks = len / 4;
    for (std::size_t i = 0; i < blocks; ++i) {
        const unsigned char* b = data + 4 * i;
        std::uint32_t k1 = std::uint32_t(b[0]) | std::uint32_t(b[1]) << 8 | std::uint32_t(b[2]) << 16 |
                           std::uint32_t(b[3]) << 24;
        k1 *= c1;
        k1 = rotl32(k1, 15);
        k1 *= c2;
        h1 ^= k1;
        h1 = rotl32(h1, 13);
        h1 = h1 * 5 + 0xe6546b64u;
    }
    const unsigned char* tail = data + 4 * blocks;
    std::uint32_t k1 = 0;
    switch (len & 3) {
        case 3: k1 ^= std::uint32_t(tail[2]) << 16; [[fallthrough]];
        case 2: k1 ^= std::uint32_t(tail[1]) << 8; [[fallthrough]];
        case 1:
            k1 ^= tail[0];
            k1 *= c1;
            k1 = rotl32(k1, 15);
            k1 *= c2;
            h1 ^= k1;
    }
    h1 ^= std::uint32_t(len);
    // fmix32
    h1 ^= h1 >> 16;
    h1 *= 0x85ebca6bu;
    h1 ^= h1 >> 13;
    h1 *= 0xc2b2ae35u;
    h1 ^= h1 >> 16;
    return h1;
}

float cryptomatte_id(std::uint32_t hash) {
    // The Cryptomatte specification's uint32_to_float32: sign and mantissa kept, the exponent clamped to [1, 254].
    const std::uint32_t mantissa = hash & ((1u << 23) - 1u);
    const std::uint32_t exponent = std::clamp((hash >> 23) & 0xffu, 1u, 254u);
    const std::uint32_t bits = (hash & 0x80000000u) | exponent << 23 | mantissa;
    float id;
    std::memcpy(&id, &bits, sizeof id);
    return id;
}

namespace {

// By CryptomatteType: the passes' prefix (Cycles' names) and the type's key.
constexpr const char* kNames[kCryptomatteTypes][2] = {{"CryptoObject", "cryptomatte_object"},
                                                      {"CryptoMaterial", "cryptomatte_material"},
                                                      {"CryptoAsset", "cryptomatte_asset"}};

}  // namespace

const char* cryptomatte_pass_prefix(CryptomatteType type) { return kNames[std::size_t(type)][0]; }

const char* cryptomatte_key(CryptomatteType type) { return kNames[std::size_t(type)][1]; }

CryptomatteLayout cryptomatte_layout_of(const RenderSettings& settings) {
    CryptomatteLayout layout;
    layout.types = {settings.cryptomatte_object, settings.cryptomatte_material, settings.cryptomatte_asset};
    if (settings.cryptomatte_object || settings.cryptomatte_material || settings.cryptomatte_asset)
        // Cycles' engine.py: (min(16, levels) + 1) // 2 layers of two ranks.
        layout.ranks = 2 * ((std::min(16, settings.cryptomatte_levels) + 1) / 2);
    return layout;
}

void CryptomatteCoverage::add(const CryptomatteIds& ids, float weight) {
    if (!(weight > 0.0f)) return;
    for (int i = 0; i < count_; ++i)
        if (entries_[i].ids == ids) {
            entries_[i].weight += weight;
            return;
        }
    if (count_ < kCapacity) entries_[count_++] = Entry{ids, weight};
}

void CryptomatteCoverage::add_scaled(const CryptomatteCoverage& other, float scale) {
    for (int i = 0; i < other.count_; ++i) add(other.entries_[i].ids, other.entries_[i].weight * scale);
}

}  // namespace raysplats
