#pragma once

#include <cstdlib>
#include <memory>
#include <new>
#include <utility>
#include <vector>

#include <sys/mman.h>

namespace mild {

// An allocator for the large arrays of the map (index ids, descriptor words):
//  - a value-less construct() leaves trivial types uninitialised, so that vector::resize() of a
//    large array of ids costs no memset: the caller writes every element it grows into;
//  - blocks of 32 MB and more are 2 MB-aligned and marked for transparent huge pages (madvise; the
//    default policy of Debian and Ubuntu kernels), so that a new array of a large map is faulted in
//    a 2 MB page at a time instead of 4 KB: at 20,000 keyframes, growing the descriptor arrays
//    stalled an insert for 3.5 s, almost all of it in page faults (measured in a VM). Smaller
//    blocks stay ordinary, so that a small map does not carry up to 2 MB of a last huge page per
//    array (32 MB keeps that under 7 %).
template <class T, class Base = std::allocator<T>>
struct DefaultInitAllocator : Base {
  static constexpr size_t kHugePage = size_t{2} << 20;
  static constexpr size_t kHugeFrom = size_t{32} << 20;

  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U, typename std::allocator_traits<Base>::template rebind_alloc<U>>;
  };
  using Base::Base;
  DefaultInitAllocator() = default;
  template <class U, class B>
  DefaultInitAllocator(const DefaultInitAllocator<U, B>& other) : Base(other) {}  // NOLINT: rebinding

  T* allocate(size_t n) {
    const size_t bytes = n * sizeof(T);
    if (bytes < kHugeFrom) return Base::allocate(n);
    const size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
    void* p = nullptr;
    if (::posix_memalign(&p, kHugePage, rounded) != 0) throw std::bad_alloc();
    ::madvise(p, rounded, MADV_HUGEPAGE);  // advice only: without THP the block works as any other
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t n) {
    if (n * sizeof(T) < kHugeFrom) {
      Base::deallocate(p, n);
    } else {
      ::free(p);
    }
  }

  template <class U>
  void construct(U* p) noexcept(noexcept(::new (static_cast<void*>(p)) U)) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    std::allocator_traits<Base>::construct(static_cast<Base&>(*this), p, std::forward<Args>(args)...);
  }
};

template <class T>
using UninitializedVector = std::vector<T, DefaultInitAllocator<T>>;

}  // namespace mild
