#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>
#include <type_traits>

#include <sys/mman.h>

namespace mild {

// A growable array of trivially copyable elements in its own anonymous memory mapping, for the
// arrays that grow with the map (descriptor words, index ids). Growing past the capacity is
// mremap: the mapping is extended in place, or its page tables are moved to a larger range, never
// its elements copied; the new part is faulted in as it is written. A std::vector of a 50,000-keyframe map
// copies a gigabyte of descriptors and faults in its new block in one insert (a 2 s stall); here
// growing costs microseconds however large the array. New elements are not initialised: resize()'s
// caller writes every element it grows into. With kHugePages the mapping asks for transparent huge
// pages (advice only), so that a large array is faulted in 2 MB at a time; without, it is whole
// 4 KB pages, for the many arrays of a few megabytes where rounding each up to 2 MB would waste more
// than the pages save.
template <class T, bool kHugePages = true>
class MappedArray {
  static_assert(std::is_trivially_copyable_v<T>, "MappedArray moves its elements as bytes");

 public:
  MappedArray() = default;
  MappedArray(const MappedArray& other) { *this = other; }
  MappedArray(MappedArray&& other) noexcept { swap(other); }
  MappedArray& operator=(const MappedArray& other) {
    if (this == &other) return *this;
    clear();
    reserve(other.size_);
    if (other.size_ > 0) std::memcpy(data_, other.data_, other.size_ * sizeof(T));
    size_ = other.size_;
    return *this;
  }
  MappedArray& operator=(MappedArray&& other) noexcept {
    MappedArray(std::move(other)).swap(*this);
    return *this;
  }
  ~MappedArray() { release(); }

  void swap(MappedArray& other) noexcept {
    std::swap(data_, other.data_);
    std::swap(size_, other.size_);
    std::swap(capacity_, other.capacity_);
  }

  T* data() { return data_; }
  const T* data() const { return data_; }
  size_t size() const { return size_; }
  size_t capacity() const { return capacity_; }
  bool empty() const { return size_ == 0; }
  T& operator[](size_t i) { return data_[i]; }
  const T& operator[](size_t i) const { return data_[i]; }
  T* begin() { return data_; }
  T* end() { return data_ + size_; }
  const T* begin() const { return data_; }
  const T* end() const { return data_ + size_; }

  // Keeps the mapping: a cleared map refills without faulting its pages in again.
  void clear() { size_ = 0; }
  void resize(size_t n) {
    if (n > capacity_) reserve(n);
    size_ = n;
  }
  void push_back(const T& value) {
    if (size_ == capacity_) reserve(std::max<size_t>(16, capacity_ + capacity_ / 4));
    data_[size_++] = value;
  }
  void reserve(size_t n) {
    if (n <= capacity_) return;
    const size_t bytes = mappingBytes(n * sizeof(T));
    void* p = data_ == nullptr ? mapAligned(bytes) : grow(bytes);
    if (huge(bytes)) ::madvise(p, bytes, MADV_HUGEPAGE);
    data_ = static_cast<T*>(p);
    capacity_ = bytes / sizeof(T);
  }
  // Gives the whole mapping back.
  void release() {
    if (data_ != nullptr) ::munmap(data_, mappedBytes());
    data_ = nullptr;
    size_ = capacity_ = 0;
  }

 private:
  static constexpr size_t kPage = 4096;
  static constexpr size_t kHugePage = size_t{2} << 20;

  // Arrays of 2 MB and more are whole huge pages at 2 MB-aligned addresses: the kernel maps them
  // with huge pages only there, and the queries' random reads into the descriptor words and ids
  // cost twice as much with 4 KB pages (their TLB misses; measured at 10,000 keyframes).
  static bool huge(size_t bytes) { return kHugePages && bytes >= kHugePage; }
  static size_t mappingBytes(size_t bytes) {
    const size_t unit = huge(bytes) ? kHugePage : kPage;
    return (bytes + unit - 1) / unit * unit;
  }
  size_t mappedBytes() const { return mappingBytes(capacity_ * sizeof(T)); }

  static void* mapAligned(size_t bytes) {
    const size_t slack = huge(bytes) ? kHugePage : 0;
    void* p = ::mmap(nullptr, bytes + slack, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    if (slack == 0) return p;
    const auto begin = reinterpret_cast<uintptr_t>(p);
    const uintptr_t aligned = (begin + kHugePage - 1) / kHugePage * kHugePage;
    if (aligned > begin) ::munmap(p, aligned - begin);
    const uintptr_t end = begin + bytes + slack;
    if (end > aligned + bytes) ::munmap(reinterpret_cast<void*>(aligned + bytes), end - aligned - bytes);
    return reinterpret_cast<void*>(aligned);
  }

  // Extends the mapping where it is if the addresses after it are free, else moves its pages (not
  // their contents) onto a new aligned range that replaces a placeholder mapping.
  void* grow(size_t bytes) {
    const size_t old_bytes = mappedBytes();
    const bool aligned = reinterpret_cast<uintptr_t>(data_) % kHugePage == 0;
    if (aligned || !huge(bytes)) {
      void* p = ::mremap(data_, old_bytes, bytes, 0);
      if (p != MAP_FAILED) return p;
    }
    void* target = mapAligned(bytes);
    void* p = ::mremap(data_, old_bytes, bytes, MREMAP_MAYMOVE | MREMAP_FIXED, target);
    if (p == MAP_FAILED) {
      ::munmap(target, bytes);
      throw std::bad_alloc();
    }
    return p;
  }

  T* data_ = nullptr;
  size_t size_ = 0;
  size_t capacity_ = 0;
};

}  // namespace mild
