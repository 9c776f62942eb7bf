// Cryptomatte (Friedman and Jones 2015, "Fully Automatic ID Mattes with Support for Motion Blur and Transparency"; the
// Cryptomatte specification 1.2.0), in Blender's layout as Cycles writes it, so that Blender's Cryptomatte node (and
// any compositor that reads the specification) picks objects, materials and assets by name.
//
// Contract:
// - An id is a name's MurmurHash3_x86_32 (seed 0) over its UTF-8 bytes, turned into a float by the specification's
//   uint32_to_float32: the hash's bits with the exponent clamped to [1, 254], so an id is never 0, denormal, infinite
//   or NaN. 0 means "no id" (a mesh without a material has no Material id; the world has none).
// - Each pixel of a pass type (Object, Material, Asset) keeps up to `ranks` ids with their coverage: the sum over the
//   pixel's samples of each id's compositing weight in that sample, divided by the pixel's samples (as Combined is
//   averaged, so the pixel filter weighs them as it weighs colour). A sample's weights are those of everything its
//   camera ray composited: a Gaussian's T_i a_i (the one that ends compositing takes the transmittance left), a mesh
//   the ray stops on the transmittance left in front of it; what reaches the world has no id. A pixel's ids are kept
//   in the order they first appear; once `ranks` are held, later ids are dropped (Cycles adds their weight to the
//   last rank's id instead; dropping keeps every rank's coverage its own id's). They are written sorted by coverage,
//   largest first (Cycles' film_sort_cryptomatte_slots).
// - Layout (Cycles: blender/addon/engine.py list_render_passes, kernel/film/cryptomatte_passes.h): rank pairs
//   (id, coverage) in RGBA layers of two ranks each, passes "CryptoObject00", "CryptoObject01", ... (Material,
//   Asset likewise); Blender's Levels setting L gives ceil(min(L, 16) / 2) layers. Absent ranks are (0, 0).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace raysplats {

struct RenderSettings;

// MurmurHash3_x86_32 of `name` with seed 0 (Austin Appleby's reference MurmurHash3.cpp).
std::uint32_t cryptomatte_hash(std::string_view name);
// The specification's uint32_to_float32 of a hash: a float that is never 0, denormal, infinite or NaN.
float cryptomatte_id(std::uint32_t hash);
inline float cryptomatte_id_of(std::string_view name) { return cryptomatte_id(cryptomatte_hash(name)); }

enum class CryptomatteType : std::uint8_t { Object, Material, Asset };
constexpr std::size_t kCryptomatteTypes = 3;
// "CryptoObject", "CryptoMaterial", "CryptoAsset": the passes' names before their two-digit layer number.
const char* cryptomatte_pass_prefix(CryptomatteType type);
// "cryptomatte_object", ...: the type's key in the bindings' film dict and its render setting's name.
const char* cryptomatte_key(CryptomatteType type);

// The ids of one thing a camera ray composites, by CryptomatteType (0: none).
using CryptomatteIds = std::array<float, kCryptomatteTypes>;

// Which Cryptomatte passes a render fills and how many ranks each keeps per pixel (RenderSettings::cryptomatte_*).
struct CryptomatteLayout {
    std::array<bool, kCryptomatteTypes> types{};
    int ranks = 0;  // 0: no Cryptomatte pass (nothing is computed for them); else even, 2 .. 16
    bool on() const { return ranks > 0; }
    int layers() const { return ranks / 2; }
};
CryptomatteLayout cryptomatte_layout_of(const RenderSettings& settings);

// What one camera sample gives the Cryptomatte passes (SampleRecord::cryptomatte): the weight in the pixel of each
// thing its camera ray composited, by ids (equal ids merged). It holds kCapacity things; a sample meeting more drops
// the rest (a camera ray meets few objects: all Gaussians of an object share its ids).
class CryptomatteCoverage {
public:
    static constexpr int kCapacity = 8;
    struct Entry {
        CryptomatteIds ids;
        float weight;
    };
    // User-provided, so that a value-initialised record (Segment{}) does not zero the entries: only [0, size()) are
    // ever read.
    CryptomatteCoverage() noexcept {}
    void add(const CryptomatteIds& ids, float weight);
    // Adds every entry of `other` with its weight times `scale` (the transmittance in front of it).
    void add_scaled(const CryptomatteCoverage& other, float scale);
    int size() const { return count_; }
    const Entry& operator[](int i) const { return entries_[i]; }

private:
    Entry entries_[kCapacity];
    int count_ = 0;
};

}  // namespace raysplats
