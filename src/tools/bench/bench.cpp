// What the subcommands share (bench.h): the strut built in code and the heap allocation counter.
#include "bench.h"

#include <atomic>
#include <cmath>
#include <cstddef>

// Heap allocations are counted by interposing glibc's malloc family in this executable (the core and
// Eigen allocate through them; operator new does too): `steps` reports them per step. Not with
// AddressSanitizer, which replaces malloc itself (this one would run before its initialization). GCC says
// so with __SANITIZE_ADDRESS__, clang 14 only with __has_feature.
#if defined(__SANITIZE_ADDRESS__)
#define AT_BENCH_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define AT_BENCH_ASAN 1
#endif
#endif
#ifndef AT_BENCH_ASAN
namespace
{
std::atomic<long> g_allocations{ 0 };
}
extern "C"
{
  void* __libc_malloc(size_t size);
  void* __libc_calloc(size_t n, size_t size);
  void* __libc_realloc(void* p, size_t size);
}
extern "C"
{
  void* malloc(size_t size)
  {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_malloc(size);
  }
  void* calloc(size_t n, size_t size)
  {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_calloc(n, size);
  }
  void* realloc(void* p, size_t size)
  {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_realloc(p, size);
  }
}
#endif

namespace active_tensegrity::tools::bench
{
long heapAllocations()
{
#ifdef AT_BENCH_ASAN
  return -1;
#else
  return g_allocations.load();
#endif
}

core::Body strut(const std::string& name, double length, double radius, double youngs_modulus, double poisson_ratio)
{
  core::Body b;
  b.name = name;
  b.kind = core::BodyKind::kStrut;
  b.length = length;
  core::StrutLayer layer;
  layer.material = "bench";
  layer.outer_radius = radius;
  layer.density = 2000.0;
  layer.youngs_modulus = youngs_modulus;
  layer.poisson_ratio = poisson_ratio;
  b.layers.push_back(layer);
  b.mass = layer.density * M_PI * radius * radius * length;
  const double jt = b.mass * (3.0 * radius * radius + length * length) / 12.0;
  b.inertia = core::Vec3(jt, jt, 0.5 * b.mass * radius * radius);
  return b;
}

}  // namespace active_tensegrity::tools::bench
