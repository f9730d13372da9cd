#include "active_tensegrity/design/generators.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/base/rotation.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::design
{
using namespace core;

namespace
{
std::string vec(const Vec3& v)
{
  const auto n = [](double x) { return shortestNumber(std::abs(x) < 1e-15 ? 0.0 : x); };
  return "[" + n(v.x()) + ", " + n(v.y()) + ", " + n(v.z()) + "]";
}

static_assert(kMaxTowerStages + 2 <= Cable::kMaxPoints, "a tower's sliding cable has stages + 2 nodes");

void requireRange(const std::string& what, double v, double lo, double hi, const std::string& unit)
{
  if (!(v >= lo && v <= hi))
    throw std::invalid_argument(what + ": must lie in [" + shortestNumber(lo) + ", " + shortestNumber(hi) + "] " +
                                unit + ", got " + shortestNumber(v));
}

void requireLength(const std::string& what, double v)
{
  requireRange(what, v, kMinGeneratedLength, kMaxGeneratedLength, "m");
}

void requirePrestress(const std::string& what, double v)
{
  requireRange(what, v, kMinGeneratedPrestress, kMaxGeneratedPrestress, "N");
}

const char* kMaterials = "materials:\n"
                         "  aluminium: {youngs_modulus: 70.0e9, poisson_ratio: 0.33, density: 2700.0}\n"
                         "  fibreglass: {youngs_modulus: 73.0e9, density: 2450.0}\n";

std::string analysis(bool pinned)
{
  return pinned ? "analysis: {type: static, steps: 10}\n" :
                  "analysis: {type: dynamic, duration: 0.5, output_interval: 0.01}\n";
}
}  // namespace

double prismTwist(int struts)
{
  return -(M_PI / 2.0 + M_PI / struts);
}

std::string prismScene(const PrismSpec& s)
{
  if (s.struts < 3 || s.struts > 64)
    throw std::invalid_argument("struts: a prism has 3 to 64 struts, got " + std::to_string(s.struts));
  requireLength("radius", s.radius);
  requireLength("height", s.height);
  requirePrestress("ring_prestress", s.ring_prestress);
  requireLength("strut_radius", s.strut_radius);
  // (degrees to radians and back may be off by an ulp: 360 degrees is in)
  if (!std::isnan(s.twist) && !(std::abs(s.twist * 180.0 / M_PI) <= kMaxGeneratedTwist * (1.0 + 1e-12)))
    throw std::invalid_argument("twist: must lie in [" + shortestNumber(-kMaxGeneratedTwist) + ", " +
                                shortestNumber(kMaxGeneratedTwist) + "] degrees, got " +
                                shortestNumber(s.twist * 180.0 / M_PI));
  if (s.driven && !s.pinned)
    throw std::invalid_argument("driven: a driven prism must be pinned (its top nodes are pushed against its base)");
  const double twist = std::isnan(s.twist) ? prismTwist(s.struts) : s.twist;
  if (!std::isfinite(twist))
    throw std::invalid_argument("twist: must be finite, got " + shortestNumber(twist));
  const int n = s.struts;
  std::vector<Vec3> bottom, top;
  for (int i = 0; i < n; ++i)
  {
    const double a = M_PI / 2.0 + 2.0 * M_PI * i / n;
    bottom.emplace_back(s.radius * std::cos(a), s.radius * std::sin(a), 0.0);
    top.emplace_back(s.radius * std::cos(a + twist), s.radius * std::sin(a + twist), s.height);
  }
  // force densities of the form: rings q, verticals 2 sin(pi/n) q, struts -2 sin(pi/n) q
  const double ring = 2.0 * s.radius * std::sin(M_PI / n);
  const double q = s.ring_prestress / ring;
  const double vertical = (top[1 % n] - bottom[0]).norm();
  const double vertical_prestress = 2.0 * std::sin(M_PI / n) * q * vertical;
  std::ostringstream y;
  y << "# Class-1 tensegrity prism of " << n << " struts (tensegrity_generate prism): bottom and top rings of radius "
    << shortestNumber(s.radius) << " m, " << shortestNumber(s.height) << " m apart, the top turned by "
    << roundedNumber(twist * 180.0 / M_PI, 9) << " degrees"
    << (std::isnan(s.twist) ? " (the form's -(90 + 180/n))" : " (not the form's twist: run tensegrity_formfind)")
    << ".\n# Force densities rings : verticals : struts = 1 : 2 sin(180/n) : -2 sin(180/n) = 1 : "
    << roundedNumber(2.0 * std::sin(M_PI / n), 9) << " : " << roundedNumber(-2.0 * std::sin(M_PI / n), 9) << ".\n";
  y << "name: prism" << n << "\n";
  y << "description: class-1 prism of " << n << " struts" << (s.pinned ? ", pinned at its bottom nodes" : "")
    << (s.driven ? ", its top nodes pressed down by the actuator press" : "") << "\n";
  y << kMaterials;
  // a driven prism folds: its cables are elastic (EA = 7.84 MPa * pi * (1 cm)^2 = 2463 N, the quadruplex's)
  const std::string cable =
      s.driven ? "    material: elastic\n    radius: 0.01\n" : "    material: fibreglass\n    radius: 0.0015\n";
  if (s.driven)
    y << "  elastic: {youngs_modulus: 7.84e6, density: 1000.0}\n";
  y << "nodes:\n";
  for (int i = 0; i < n; ++i)
    y << "  B" << i + 1 << ": {position: " << vec(bottom[i]) << (s.pinned ? ", fixed: true" : "") << "}\n";
  for (int i = 0; i < n; ++i)
    y << "  T" << i + 1 << ": {position: " << vec(top[i]) << "}\n";
  y << "struts:\n  radius: " << shortestNumber(s.strut_radius) << "\n  material: aluminium\n  members:\n";
  for (int i = 0; i < n; ++i)
    y << "    S" << i + 1 << ": [B" << i + 1 << ", T" << i + 1 << "]\n";
  y << "cables:\n  rings:\n" << cable << "    prestress: " << shortestNumber(s.ring_prestress) << "\n    members:\n";
  for (int i = 0; i < n; ++i)
    y << "      R" << i + 1 << ": [B" << i + 1 << ", B" << (i + 1) % n + 1 << "]\n";
  for (int i = 0; i < n; ++i)
    y << "      R" << n + i + 1 << ": [T" << i + 1 << ", T" << (i + 1) % n + 1 << "]\n";
  y << "  verticals:\n" << cable << "    prestress: " << shortestNumber(vertical_prestress) << "\n    members:\n";
  for (int i = 0; i < n; ++i)
    y << "      V" << i + 1 << ": [B" << i + 1 << ", T" << (i + 1) % n + 1 << "]\n";
  if (!s.driven)
  {
    y << "contact: {enabled: false, pairs: auto}\n" << analysis(s.pinned);
    return y.str();
  }
  y << "actuators:\n  # the actuation value moves every top node down by as much (each free across)\n  press:\n    "
       "nodes: [";
  for (int i = 0; i < n; ++i)
    y << "T" << i + 1 << (i + 1 < n ? ", " : "]\n");
  y << "    direction: [0.0, 0.0, -1.0]\n    range: [0.0, " << shortestNumber(s.height) << "]\n";
  y << "contact: {enabled: true, pairs: auto}\n";
  y << "actuation: {speed: " << shortestNumber(0.25 * s.height) << "}\n";
  y << "analysis: {type: static, max_actuation: " << shortestNumber(0.3 * s.height) << ", steps: 30}\n";
  y << "outputs: {height_nodes: [";
  for (int i = 0; i < n; ++i)
    y << "T" << i + 1 << (i + 1 < n ? ", " : "]}\n");
  return y.str();
}

std::string octahedronScene(const OctahedronSpec& s)
{
  requireLength("strut_length", s.strut_length);
  requirePrestress("prestress", s.prestress);
  const double a = s.strut_length / 4.0, b = s.strut_length / 2.0;
  // struts along z at y = +-a, along x at z = +-a, along y at x = +-a: the cyclic permutations of (0, +-a, +-b)
  std::vector<Vec3> nodes;
  for (int axis = 0; axis < 3; ++axis)
    for (double sa : { 1.0, -1.0 })
      for (double sb : { 1.0, -1.0 })
      {
        Vec3 p;
        p[axis] = 0.0;
        p[(axis + 1) % 3] = sa * a;
        p[(axis + 2) % 3] = sb * b;
        nodes.push_back(p);
      }
  const double cable = s.strut_length * std::sqrt(6.0) / 4.0;
  std::vector<std::pair<int, int>> cables;
  for (size_t i = 0; i < nodes.size(); ++i)
    for (size_t j = i + 1; j < nodes.size(); ++j)
      if (std::abs((nodes[i] - nodes[j]).norm() - cable) < 1e-9 * s.strut_length)
        cables.emplace_back(static_cast<int>(i), static_cast<int>(j));
  std::vector<char> fixed(nodes.size(), 0);
  if (s.pinned)  // the cable triangle lowest on average
  {
    double lowest = 1e300;
    int best[3] = { 0, 0, 0 };
    for (const auto& [i, j] : cables)
      for (const auto& [k, l] : cables)
        if (k == j && l > j)
          for (const auto& [m, o] : cables)
            if (m == i && o == l && (nodes[i].z() + nodes[j].z() + nodes[l].z()) < lowest)
            {
              lowest = nodes[i].z() + nodes[j].z() + nodes[l].z();
              best[0] = i;
              best[1] = j;
              best[2] = l;
            }
    for (int k : best)
      fixed[k] = 1;
  }
  std::ostringstream y;
  y << "# Expanded octahedron (tensegrity_generate octahedron): six struts of " << shortestNumber(s.strut_length)
    << " m in three orthogonal parallel pairs " << shortestNumber(b) << " m apart,\n# 24 cables of "
    << roundedNumber(cable, 9) << " m carrying " << shortestNumber(s.prestress)
    << " N each (force densities cables : struts = 1 : -1.5).\n";
  y << "name: octahedron\ndescription: expanded octahedron" << (s.pinned ? ", three nodes of a face pinned" : "")
    << "\n"
    << kMaterials << "nodes:\n";
  for (size_t i = 0; i < nodes.size(); ++i)
    y << "  N" << i + 1 << ": {position: " << vec(nodes[i]) << (fixed[i] ? ", fixed: true" : "") << "}\n";
  y << "struts:\n  radius: 0.012\n  material: aluminium\n  members:\n";
  for (int k = 0; k < 6; ++k)
    y << "    S" << k + 1 << ": [N" << 2 * k + 1 << ", N" << 2 * k + 2 << "]\n";
  y << "cables:\n  cables:\n    material: fibreglass\n    radius: 0.0015\n    prestress: "
    << shortestNumber(s.prestress) << "\n    members:\n";
  for (size_t k = 0; k < cables.size(); ++k)
    y << "      C" << k + 1 << ": [N" << cables[k].first + 1 << ", N" << cables[k].second + 1 << "]\n";
  y << "contact: {enabled: false, pairs: auto}\n" << analysis(s.pinned);
  return y.str();
}

std::string towerScene(const TowerSpec& s)
{
  if (s.stages < 1 || s.stages > kMaxTowerStages)
    throw std::invalid_argument("stages: a tower has 1 to " + std::to_string(kMaxTowerStages) +
                                " stages (its sliding cables run through every level: stages + 2 nodes, at most " +
                                std::to_string(Cable::kMaxPoints) + "), got " + std::to_string(s.stages));
  requireLength("width", s.width);
  const int top = s.stages;
  const double h = s.width / 2.0;
  const auto name = [](int level, int k)
  { return level == 0 ? "G" + std::to_string(k) : "L" + std::to_string(level) + "_" + std::to_string(k); };
  // corner k (1..4) of a level: big levels at 45 + 90 (k - 1) degrees, small levels at 90 (k - 1)
  const auto position = [&](int level, int k)
  {
    const bool big = level % 2 == 0;
    const double a = (big ? M_PI / 4.0 : 0.0) + M_PI / 2.0 * (k - 1);
    const double r = big ? s.width / std::sqrt(2.0) : s.width / 2.0;
    return Vec3(r * std::cos(a), r * std::sin(a), level * h);
  };
  const auto level_list = [&](int level)
  {
    std::string out = "[";
    for (int k = 1; k <= 4; ++k)
      out += name(level, k) + (k < 4 ? ", " : "]");
    return out;
  };
  std::ostringstream y;
  y << "# Clustered quadruplex tower of " << top << " stage" << (top > 1 ? "s" : "")
    << " (tensegrity_generate tower): width " << shortestNumber(s.width) << " m, height " << shortestNumber(top * h)
    << " m.\n"
    << "# Levels 0.." << top << " at z = level * " << shortestNumber(h)
    << " m; even levels are big squares (corners at 45, 135, 225, 315 deg), odd levels small\n"
    << "# squares (0, 90, 180, 270 deg). In each stage the small node at azimuth phi carries a strut to the big node\n"
    << "# at phi + 135 deg and a bracing to the big node at phi + 45 deg; the bracings at one corner form the\n"
    << "# sliding cable P<k>, which runs over its ground node to the driven body D<k>.\n";
  y << "name: tower" << top << "\n";
  y << "description: " << top << " quadruplex stages joined by strut-to-strut ball joints, bottom nodes pinned, "
    << "no gravity, every member at its free length at the start; pulling the driven bodies down folds the "
       "tower\n";
  y << "materials:\n"
       "  fibreglass: {youngs_modulus: 73.0e9, density: 2450.0}\n"
       "  rubber: {youngs_modulus: 7.84e6, poisson_ratio: 0.47, density: 930.0}\n"
       "  steel: {youngs_modulus: 210.0e9, poisson_ratio: 0.3, density: 7800.0}\n";
  y << "nodes:\n";
  for (int level = 0; level <= top; ++level)
    for (int k = 1; k <= 4; ++k)
      y << "  " << name(level, k) << ": {position: " << vec(position(level, k)) << (level == 0 ? ", fixed: true" : "")
        << "}\n";
  y << "  # driven bodies: point masses " << shortestNumber(0.2 * s.width)
    << " m below their ground node, moved straight down\n";
  for (int k = 1; k <= 4; ++k)
    y << "  D" << k << ": {position: " << vec(position(0, k) - Vec3(0.0, 0.0, 0.2 * s.width)) << ", mass: 1.0}\n";
  y << "struts:\n  radius: " << shortestNumber(0.04 * s.width)
    << "\n  material: rubber\n  core: {radius: " << shortestNumber(0.0125 * s.width)
    << ", material: steel}\n  members:\n";
  // stage st spans levels st - 1 and st; the strut joins the small node k to the big node k + 1, listed from
  // the lower level
  for (int st = 1; st <= top; ++st)
    for (int k = 1; k <= 4; ++k)
    {
      const int small = st % 2 == 1 ? st : st - 1, big = st % 2 == 1 ? st - 1 : st;
      const std::string a = name(big, k % 4 + 1), b = name(small, k);
      y << "    S" << st << "_" << k << ": [" << (big < small ? a : b) << ", " << (big < small ? b : a) << "]\n";
    }
  const auto square = [&](int level, const char* prefix)
  {
    std::string out;
    for (int k = 1; k <= 4; ++k)
      out += "      " + std::string(prefix) + std::to_string(level) + "_" + std::to_string(k) + ": [" + name(level, k) +
             ", " + name(level, k % 4 + 1) + "]\n";
    return out;
  };
  const std::string cable_section = "    material: fibreglass\n    radius: " + shortestNumber(0.003 * s.width) + "\n";
  y << "cables:\n";
  if (top >= 2)
  {
    y << "  squares:\n" << cable_section << "    members:\n";
    for (int level = 2; level <= top; level += 2)
      y << square(level, "Q");
  }
  y << "  sliding:\n    # from the top node down through every level, over the ground node (a pulley) to the driven "
       "body\n"
    << cable_section << "    members:\n";
  for (int k = 1; k <= 4; ++k)
  {
    y << "      P" << k << ": [";
    for (int level = top; level >= 0; --level)
      y << name(level, k) << ", ";
    y << "D" << k << "]\n";
  }
  y << "springs:\n  middle:\n    stiffness: 2000.0\n    members:\n";
  for (int level = 1; level <= top; level += 2)
    y << square(level, "M");
  y << "actuators:\n  # the travel of a driven body: the sliding cable inside the tower shortens by as much\n";
  for (int k = 1; k <= 4; ++k)
    y << "  pull" << k << ": {nodes: [D" << k << "], direction: [0.0, 0.0, -1.0], guided: true, range: [0.0, "
      << shortestNumber(0.45 * top * s.width) << "]}\n";
  y << "contact:\n  enabled: true\n  # adjacent struts of the same stage\n  pairs:\n";
  for (int st = 1; st <= top; ++st)
    for (int k = 1; k <= 4; ++k)
      y << "    - [S" << st << "_" << k << ", S" << st << "_" << k % 4 + 1 << "]\n";
  y << "  restitution: 0.5\n  friction: 0.1\n";
  y << "solver: {dt: 2.0e-4, integrator: newmark, newmark: {gamma: 0.6, beta: 0.3025}, newton_tolerance: 1.0e-6, "
       "max_iterations: 30, max_step_cuts: 12}\n";
  y << "actuation: {speed: 0.5}\n";
  y << "analysis: {type: static, max_actuation: " << shortestNumber(0.375 * top * s.width) << ", steps: " << 75 * top
    << "}\n";
  y << "outputs:\n  height_nodes: " << level_list(top) << "\n  layers:\n";
  for (int level = 1; level <= top; ++level)
    y << "    level" << level << ": " << level_list(level) << "\n";
  return y.str();
}

}  // namespace active_tensegrity::design
