// Counts this process's heap allocations by interposing glibc's malloc family (the core and Eigen allocate
// through them; operator new does too). Include it in exactly one source file of an executable: it defines
// malloc, calloc and realloc. Not with AddressSanitizer, which replaces malloc itself (these would run before
// its initialization); GCC says so with __SANITIZE_ADDRESS__, clang 14 only with __has_feature.
#pragma once

#include <atomic>
#include <cstddef>

#if defined(__SANITIZE_ADDRESS__)
#define AT_HEAP_COUNTER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define AT_HEAP_COUNTER_ASAN 1
#endif
#endif

namespace active_tensegrity::tools
{
#ifndef AT_HEAP_COUNTER_ASAN
namespace heap_counter_detail
{
inline std::atomic<long> allocations{ 0 };
}
#endif
}  // namespace active_tensegrity::tools

#ifndef AT_HEAP_COUNTER_ASAN
extern "C"
{
  void* __libc_malloc(size_t size);
  void* __libc_calloc(size_t n, size_t size);
  void* __libc_realloc(void* p, size_t size);

  void* malloc(size_t size)
  {
    active_tensegrity::tools::heap_counter_detail::allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_malloc(size);
  }
  void* calloc(size_t n, size_t size)
  {
    active_tensegrity::tools::heap_counter_detail::allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_calloc(n, size);
  }
  void* realloc(void* p, size_t size)
  {
    active_tensegrity::tools::heap_counter_detail::allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_realloc(p, size);
  }
}
#endif

namespace active_tensegrity::tools
{
/// Heap allocations (malloc, calloc, realloc) made by this process so far; -1 in a build with AddressSanitizer
/// (nothing is counted there).
inline long heapAllocationCount()
{
#ifdef AT_HEAP_COUNTER_ASAN
  return -1;
#else
  return heap_counter_detail::allocations.load();
#endif
}
}  // namespace active_tensegrity::tools
