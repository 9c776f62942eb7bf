// SIMD policies: the same code over 4 floats with SSE (the x86-64 baseline) or 8 with AVX2 and FMA (or 4 with FMA
// for narrow groups), chosen at run time by the caller (gaussian_callbacks.cpp) or SSE alone (camera_splatting.cpp).
#pragma once

#include <immintrin.h>

namespace raysplats {

// For the group test: 4 lanes with SSE (the x86-64 baseline; two steps per group) or 8 with AVX2 and
// FMA, chosen at run time. madd(a, b, c) = a b + c is one fused operation (one rounding) with FMA and a mul and an
// add with SSE, so the two paths differ in the last bits of t and of the distance (each is deterministic on its
// machine); FMA makes the frames a little faster (docs/benchmarks.md). (Functions with a target attribute can only
// be inlined into callers with that target: see the callbacks at the end of gaussian_callbacks.cpp.)
struct Sse {
    using V = __m128;
    static constexpr int W = 4;
    static V load(const float* p) { return _mm_load_ps(p); }
    static V set1(float s) { return _mm_set1_ps(s); }
    static V add(V a, V b) { return _mm_add_ps(a, b); }
    static V sub(V a, V b) { return _mm_sub_ps(a, b); }
    static V mul(V a, V b) { return _mm_mul_ps(a, b); }
    static V div(V a, V b) { return _mm_div_ps(a, b); }
    static V le(V a, V b) { return _mm_cmple_ps(a, b); }
    static V ne(V a, V b) { return _mm_cmpneq_ps(a, b); }
    static V and_(V a, V b) { return _mm_and_ps(a, b); }
    static V abs(V a) { return _mm_andnot_ps(_mm_set1_ps(-0.0f), a); }
    static V neg(V a) { return _mm_xor_ps(a, _mm_set1_ps(-0.0f)); }
    static V madd(V a, V b, V c) { return _mm_add_ps(_mm_mul_ps(a, b), c); }  // a b + c
    static unsigned bits(V m) { return unsigned(_mm_movemask_ps(m)); }
    static void store(float* p, V a) { _mm_store_ps(p, a); }
};

// __m256 passes between these functions by value. Their callers are the AVX2 callbacks, of the same target, once the
// always_inline helpers of gaussian_callbacks.cpp are inlined into them (at any optimisation level), so the ABI note
// GCC gives (at the end of the including file, hence not scoped) concerns no call between different targets.
#pragma GCC diagnostic ignored "-Wpsabi"
struct Avx2 {
    using V = __m256;
    static constexpr int W = 8;
    __attribute__((target("avx2,fma"))) static V load(const float* p) { return _mm256_load_ps(p); }
    __attribute__((target("avx2,fma"))) static V set1(float s) { return _mm256_set1_ps(s); }
    __attribute__((target("avx2,fma"))) static V add(V a, V b) { return _mm256_add_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V div(V a, V b) { return _mm256_div_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V le(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
    __attribute__((target("avx2,fma"))) static V ne(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
    __attribute__((target("avx2,fma"))) static V and_(V a, V b) { return _mm256_and_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V abs(V a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a); }
    __attribute__((target("avx2,fma"))) static V neg(V a) { return _mm256_xor_ps(a, _mm256_set1_ps(-0.0f)); }
    __attribute__((target("avx2,fma"))) static V madd(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
    __attribute__((target("avx2,fma"))) static unsigned bits(V m) { return unsigned(_mm256_movemask_ps(m)); }
    __attribute__((target("avx2,fma"))) static void store(float* p, V a) { _mm256_store_ps(p, a); }
};

// Four lanes with FMA: the AVX2 path's operations on a group of at most four Gaussians, lane for lane the same
// results as Avx2's (madd fused; everything else is Sse's, the same IEEE operations and comparison predicates).
struct Fma4 : Sse {
    __attribute__((target("avx2,fma"))) static V madd(V a, V b, V c) { return _mm_fmadd_ps(a, b, c); }
};

// The policy for groups of at most four lanes on a path: Fma4 on the AVX2 path, Sse on the SSE path.
template <class S>
struct Narrow {
    using type = Sse;
};
template <>
struct Narrow<Avx2> {
    using type = Fma4;
};

}  // namespace raysplats
