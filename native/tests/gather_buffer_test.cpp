// The k-nearest gather buffer of gather_buffer.h: (t, key) order, capacity, the prefix-transmittance cut and the
// continuation of a ray behind the previous pass, each with numbers predicted by hand.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "render/gather_buffer.h"

using namespace raysplats;

namespace {

constexpr float kNoLimit = std::numeric_limits<float>::infinity();
constexpr float kNoCut = 0.0f;  // a threshold that no prefix transmittance falls below

GatherBuffer buffer(int capacity, float base_transmittance = 1.0f) {
    GatherBuffer b;
    b.set_capacity(capacity);
    b.begin_pass(base_transmittance);
    return b;
}

std::vector<float> ts(const GatherBuffer& b) {
    std::vector<float> out;
    for (int i = 0; i < b.size(); ++i) out.push_back(b[i].t);
    return out;
}

std::vector<std::pair<std::uint32_t, std::uint32_t>> ids(const GatherBuffer& b) {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
    for (int i = 0; i < b.size(); ++i) out.emplace_back(b[i].geom, b[i].prim);
    return out;
}

TEST(GatherBuffer, KeepsHitsInDepthOrderWhateverTheInsertionOrder) {
    GatherBuffer b = buffer(8);
    for (const float t : {5.0f, 1.0f, 3.0f, 2.0f, 4.0f})
        EXPECT_EQ(b.insert(t, 0.1f, 0, std::uint32_t(t), kNoCut), kNoLimit);
    EXPECT_EQ(ts(b), (std::vector<float>{1, 2, 3, 4, 5}));
    EXPECT_EQ(b[0].prim, 1u);
    EXPECT_FLOAT_EQ(b[0].alpha, 0.1f);
    EXPECT_FALSE(b.truncated());
    EXPECT_FALSE(b.saturated());
}

TEST(GatherBuffer, OrdersEqualDepthsByGeometryThenPrimitive) {
    GatherBuffer b = buffer(8);
    b.insert(1.0f, 0.1f, 1, 0, kNoCut);
    b.insert(1.0f, 0.1f, 0, 7, kNoCut);
    b.insert(0.5f, 0.1f, 2, 9, kNoCut);
    b.insert(1.0f, 0.1f, 0, 3, kNoCut);
    using Id = std::pair<std::uint32_t, std::uint32_t>;
    EXPECT_EQ(ids(b), (std::vector<Id>{{2, 9}, {0, 3}, {0, 7}, {1, 0}}));
}

TEST(GatherBuffer, AFullBufferKeepsTheKNearestAndBoundsTheTraversalAtItsLast) {
    GatherBuffer b = buffer(3);
    EXPECT_EQ(b.insert(4.0f, 0.1f, 0, 4, kNoCut), kNoLimit);
    EXPECT_EQ(b.insert(2.0f, 0.1f, 0, 2, kNoCut), kNoLimit);
    EXPECT_EQ(b.insert(6.0f, 0.1f, 0, 6, kNoCut), 6.0f);  // full: nothing behind 6 can enter
    EXPECT_TRUE(b.truncated());
    EXPECT_EQ(b.insert(7.0f, 0.1f, 0, 7, kNoCut), kNoLimit);  // behind the last: ignored
    EXPECT_EQ(b.insert(6.0f, 0.1f, 0, 8, kNoCut), kNoLimit);  // same t, larger key: behind the last too
    EXPECT_EQ(ts(b), (std::vector<float>{2, 4, 6}));
    EXPECT_EQ(b.insert(1.0f, 0.1f, 0, 1, kNoCut), 4.0f);  // in front: 6 is dropped
    EXPECT_EQ(ts(b), (std::vector<float>{1, 2, 4}));
    EXPECT_EQ(b.insert(6.0f, 0.1f, 0, 5, kNoCut), kNoLimit);
    EXPECT_EQ(b.insert(3.0f, 0.1f, 0, 3, kNoCut), 3.0f);
    EXPECT_EQ(ts(b), (std::vector<float>{1, 2, 3}));
    EXPECT_EQ(b.size(), 3);
    EXPECT_FALSE(b.saturated());
}

// alpha 0.5 each from T = 1: the transmittance behind hits 0, 1, 2 is 0.5, 0.25, 0.125; with the threshold 0.2 the
// buffer ends at the third hit.
TEST(GatherBuffer, IsCutAtTheFirstHitWhoseTransmittanceFallsBelowTheThreshold) {
    GatherBuffer b = buffer(8);
    EXPECT_EQ(b.insert(1.0f, 0.5f, 0, 1, 0.2f), kNoLimit);
    EXPECT_EQ(b.insert(2.0f, 0.5f, 0, 2, 0.2f), kNoLimit);
    EXPECT_FALSE(b.saturated());
    EXPECT_EQ(b.insert(3.0f, 0.5f, 0, 3, 0.2f), 3.0f);
    EXPECT_TRUE(b.saturated());
    EXPECT_TRUE(b.truncated());
    EXPECT_EQ(b.size(), 3);
    // A hit in front moves the cut forward: the old third hit now lies behind it and is dropped.
    EXPECT_EQ(b.insert(0.5f, 0.5f, 0, 0, 0.2f), 2.0f);
    EXPECT_EQ(ts(b), (std::vector<float>{0.5f, 1, 2}));
    EXPECT_TRUE(b.saturated());
    // A hit at the cut's depth with a larger key lies behind the cut.
    EXPECT_EQ(b.insert(2.0f, 0.5f, 0, 9, 0.2f), 2.0f);
    EXPECT_EQ(ts(b), (std::vector<float>{0.5f, 1, 2}));
    EXPECT_EQ(b[2].prim, 2u);
}

TEST(GatherBuffer, CutsFromTheSegmentsTransmittanceSoFar) {
    GatherBuffer b = buffer(8, 0.3f);  // 0.3 * (1 - 0.5) = 0.15 < 0.2 at the first hit
    EXPECT_EQ(b.insert(1.0f, 0.5f, 0, 1, 0.2f), 1.0f);
    EXPECT_TRUE(b.saturated());
    EXPECT_EQ(b.size(), 1);
    b.begin_pass(1.0f);  // a new pass forgets the cut
    EXPECT_FALSE(b.saturated());
    EXPECT_EQ(b.size(), 0);
    EXPECT_EQ(b.insert(1.0f, 0.5f, 0, 1, 0.2f), kNoLimit);
}

TEST(GatherBuffer, ContinuesStrictlyBehindTheLastHitInDepthAndKeyOrder) {
    GatherBuffer b = buffer(2);
    EXPECT_FALSE(b.continues());
    b.insert(1.0f, 0.1f, 0, 1, kNoCut);
    b.insert(2.0f, 0.1f, 0, 5, kNoCut);
    ASSERT_TRUE(b.truncated());
    b.continue_behind_last();
    EXPECT_TRUE(b.continues());
    EXPECT_EQ(b.continuation_t(), 2.0f);
    b.begin_pass(0.8f);
    EXPECT_EQ(b.size(), 0);
    EXPECT_EQ(b.insert(1.0f, 0.1f, 0, 1, kNoCut), kNoLimit);  // gathered by the previous pass
    EXPECT_EQ(b.insert(2.0f, 0.1f, 0, 5, kNoCut), kNoLimit);  // the last hit itself
    EXPECT_EQ(b.insert(2.0f, 0.1f, 0, 4, kNoCut), kNoLimit);  // same t, smaller key: in front of it
    EXPECT_EQ(b.size(), 0);
    b.insert(2.0f, 0.1f, 0, 6, kNoCut);  // same t, larger key: new
    b.insert(3.0f, 0.1f, 0, 0, kNoCut);
    EXPECT_EQ(ts(b), (std::vector<float>{2, 3}));
    EXPECT_EQ(b[0].prim, 6u);
}

TEST(GatherBuffer, ContinuesBehindEveryHitAtASpeculativeEnd) {
    GatherBuffer b = buffer(4);
    b.continue_behind(5.0f);
    EXPECT_EQ(b.continuation_t(), 5.0f);
    b.begin_pass(1.0f);
    b.insert(5.0f, 0.1f, 0xffffffffu, 0xfffffffeu, kNoCut);  // any key at t = 5 counts as seen
    b.insert(4.0f, 0.1f, 0, 0, kNoCut);
    EXPECT_EQ(b.size(), 0);
    b.insert(5.5f, 0.1f, 0, 0, kNoCut);
    EXPECT_EQ(ts(b), (std::vector<float>{5.5f}));
}

}  // namespace
