// What the subcommands share (bench.h): the strut built in code, the heap allocation counter, the processor.
#include "bench.h"

#include <cmath>
#include <cstddef>
#include <fstream>
#include <string>

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

namespace active_tensegrity::tools::bench
{
namespace
{
/// The first "key : value" line of /proc/cpuinfo with this key ("" when none).
std::string cpuInfo(const std::string& key)
{
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key, 0) == 0)
    {
      const size_t colon = line.find(':');
      return colon == std::string::npos ? "" : line.substr(std::min(line.size(), colon + 2));
    }
  return "";
}
}  // namespace

std::string cpuModel()
{
  const std::string m = cpuInfo("model name");
  return m.empty() ? "unknown processor" : m;
}

std::string cpuVectorFlags()
{
  const std::string flags = " " + cpuInfo("flags") + " ";
  std::string out;
  for (const char* f : { "avx2", "fma", "avx512f" })
    out += std::string(out.empty() ? "" : " ") +
           (flags.find(std::string(" ") + f + " ") != std::string::npos ? "" : "no-") + f;
  return out;
}
}  // namespace active_tensegrity::tools::bench
