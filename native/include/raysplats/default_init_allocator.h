// std::allocator whose resize() leaves new elements default-initialised (for arithmetic types: not written at all),
// so that the multi-threaded fill of a large array is what first touches its pages (in parallel) instead of a
// single-threaded zeroing pass. Used by the export meshes and the render film.
#pragma once

#include <memory>
#include <new>
#include <type_traits>
#include <utility>

namespace raysplats {

template <typename T>
struct DefaultInitAllocator : std::allocator<T> {
    template <typename U>
    struct rebind {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() = default;
    template <typename U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
    template <typename U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible<U>::value) {
        ::new (static_cast<void*>(p)) U;
    }
    template <typename U, typename... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

}  // namespace raysplats
