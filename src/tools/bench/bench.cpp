// What the subcommands share (bench.h): the strut built in code and the heap allocation counter.
#include "bench.h"

#include <cmath>
#include <cstddef>

#include "../heap_counter.h"  // (defines malloc, calloc and realloc for this executable)

namespace active_tensegrity::tools::bench
{
long heapAllocations()
{
  return heapAllocationCount();
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
