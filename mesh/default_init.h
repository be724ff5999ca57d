// Vectors whose resize leaves new elements uninitialised, for large arrays that a parallel pass fills entirely.
// std::vector<int>::resize zeroes its new elements on one thread, and on these virtual machines a serial first touch
// of fresh memory is costly: the vertex stars' 27 MB on cow -> horse took 11-45 ms of memset on one core before the
// parallel counting sort wrote every entry again (docs/performance_log.md, 2026-12-07).
#pragma once

#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

namespace morphmap {

/// std::allocator, except that value-less construction default-initialises (leaves an int unset) instead of
/// value-initialising (zeroing) it. Construction with arguments is unchanged.
template <class T>
class DefaultInitAllocator : public std::allocator<T> {
 public:
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() = default;
  template <class U>
  explicit DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}

  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible<U>::value) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

/// A vector whose resize(n) does not zero: every element must be written before it is read.
template <class T>
using UninitialisedVector = std::vector<T, DefaultInitAllocator<T>>;

}  // namespace morphmap
