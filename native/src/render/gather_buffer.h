// The per-ray buffer of the k nearest Gaussian hits of one sorted gathering pass (internal; docs/design.md §6).
//
// Filled by the intersect callback (gaussian_callbacks.cpp) while Embree traverses, in exact (t, key) order,
// key = geom << 32 | prim; consumed by the segment tracer (gaussian_segment_tracer.cpp), which composites the hits
// front to back and, when the buffer may have missed hits behind its last one, continues the ray behind it with a
// new pass. Everything here runs per candidate hit inside the callback, so it is inline (flattened into the
// callbacks with their SIMD target).
#pragma once

#include <cstdint>
#include <limits>

namespace raysplats {

struct GatherHit {
    float t;
    float alpha;
    std::uint32_t geom;
    std::uint32_t prim;
};

constexpr int kGatherCapacity = 128;  // upper bound of RenderSettings::gather_buffer_size

inline std::uint64_t gather_key(std::uint32_t geom, std::uint32_t prim) { return (std::uint64_t(geom) << 32) | prim; }

class GatherBuffer {
public:
    // k, 1 <= k <= kGatherCapacity.
    void set_capacity(int k) { capacity_ = k; }
    int capacity() const { return capacity_; }

    // A new pass: an empty buffer whose prefix transmittances start from `base_transmittance` (the segment's
    // transmittance so far). The continuation point of the previous pass is kept.
    void begin_pass(float base_transmittance) {
        count_ = 0;
        saturated_ = false;
        base_transmittance_ = base_transmittance;
    }

    // Offers a hit of this pass. Hits at or before the continuation point (gathered by an earlier pass) and hits
    // behind the last one of a full buffer are ignored. Returns where the traversal may stop: the t of the last hit
    // when the buffer is full, of the cut when it is saturated (see prefix_), +inf otherwise.
    float insert(float t, float alpha, std::uint32_t geom, std::uint32_t prim, float cut_threshold) {
        constexpr float kNoLimit = std::numeric_limits<float>::infinity();
        const std::uint64_t key = gather_key(geom, prim);
        if (has_after_ && (t < after_t_ || (t == after_t_ && key <= after_key_))) return kNoLimit;
        const int k = capacity_;
        int last = count_;  // index of the buffer's last hit after the insertion
        if (count_ == k) {
            if (!hit_before(t, key, hits_[k - 1])) return kNoLimit;
            last = k - 1;  // the last hit is dropped
        }
        // Insertion from the back: each shifted hit now lies behind the new one.
        const float keep = 1.0f - alpha;
        int pos = last;
        while (pos > 0 && hit_before(t, key, hits_[pos - 1])) {
            hits_[pos] = hits_[pos - 1];
            prefix_[pos] = prefix_[pos - 1] * keep;
            --pos;
        }
        hits_[pos] = GatherHit{t, alpha, geom, prim};
        prefix_[pos] = (pos > 0 ? prefix_[pos - 1] : base_transmittance_) * keep;
        count_ = last + 1;
        saturated_ = prefix_[last] < cut_threshold;
        if (saturated_) {
            // Entries before pos - 1 are unchanged and were above the threshold (the buffer ends at the first one
            // below); the new hit may lie behind the cut (equal t, larger key).
            int cut = pos > 0 ? pos - 1 : 0;
            while (!(prefix_[cut] < cut_threshold)) ++cut;
            count_ = cut + 1;
            return hits_[cut].t;
        }
        if (count_ == k) return hits_[k - 1].t;
        return kNoLimit;
    }

    int size() const { return count_; }
    const GatherHit& operator[](int i) const { return hits_[i]; }
    // The buffer was cut (prefix fell below the threshold). If compositing the buffer then does not terminate (the
    // approximate prefix was early by a rounding), the ray goes on behind its last hit.
    bool saturated() const { return saturated_; }
    // The pass may have missed hits behind the buffer's last one (it is full, or was cut).
    bool truncated() const { return count_ == capacity_ || saturated_; }

    // The next pass gathers only hits strictly after the buffer's last one in (t, key) order.
    void continue_behind_last() {
        const GatherHit& last = hits_[count_ - 1];
        after_t_ = last.t;
        after_key_ = gather_key(last.geom, last.prim);
        has_after_ = true;
    }
    // The next pass gathers only hits strictly behind t (every key at t is taken as gathered).
    void continue_behind(float t) {
        after_t_ = t;
        after_key_ = ~std::uint64_t(0);
        has_after_ = true;
    }
    bool continues() const { return has_after_; }
    float continuation_t() const { return after_t_; }

private:
    static bool hit_before(float t, std::uint64_t key, const GatherHit& h) {
        return t < h.t || (t == h.t && key < gather_key(h.geom, h.prim));
    }

    // Hits strictly after (after_t_, after_key_) in (t, key) order.
    float after_t_ = -1e30f;
    std::uint64_t after_key_ = 0;
    bool has_after_ = false;
    int count_ = 0;
    int capacity_ = 48;  // k, <= kGatherCapacity
    GatherHit hits_[kGatherCapacity];
    // prefix_[j] ~ base_transmittance * prod_{i <= j} (1 - alpha_i): the transmittance behind hit j. An insertion at
    // p multiplies the entries it shifts by the new hit's (1 - alpha) in the same pass, so no serial product chain
    // is rescanned (that and the shift were a fifth of the sorted callback). The floats can differ from the
    // sequential product in the last bits; they only decide where the buffer is cut, and compositing, which
    // multiplies sequentially, never relies on them (see `saturated`).
    // The buffer ends at the first hit where prefix falls below the threshold: everything behind it is irrelevant
    // (unseen hits can only lower the transmittance), so tfar shrinks to its t: it bounds the traversal depth like
    // an opaque hit would.
    float prefix_[kGatherCapacity];
    float base_transmittance_ = 1.0f;
    bool saturated_ = false;
};

}  // namespace raysplats
