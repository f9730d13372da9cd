#include "active_tensegrity/core/generators.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "active_tensegrity/core/rotation.h"
#include "active_tensegrity/core/text.h"

namespace active_tensegrity::core
{
namespace
{
std::string vec(const Vec3& v)
{
  const auto n = [](double x) { return shortestNumber(std::abs(x) < 1e-15 ? 0.0 : x); };
  return "[" + n(v.x()) + ", " + n(v.y()) + ", " + n(v.z()) + "]";
}

void requirePositive(const std::string& what, double v)
{
  if (!(std::isfinite(v) && v > 0.0))
    throw std::invalid_argument(what + ": must be positive and finite, got " + shortestNumber(v));
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
  requirePositive("radius", s.radius);
  requirePositive("height", s.height);
  requirePositive("ring_prestress", s.ring_prestress);
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
  y << "description: class-1 prism of " << n << " struts" << (s.pinned ? ", pinned at its bottom nodes" : "") << "\n";
  y << kMaterials << "nodes:\n";
  for (int i = 0; i < n; ++i)
    y << "  B" << i + 1 << ": {position: " << vec(bottom[i]) << (s.pinned ? ", fixed: true" : "") << "}\n";
  for (int i = 0; i < n; ++i)
    y << "  T" << i + 1 << ": {position: " << vec(top[i]) << "}\n";
  y << "struts:\n  radius: 0.012\n  material: aluminium\n  members:\n";
  for (int i = 0; i < n; ++i)
    y << "    S" << i + 1 << ": [B" << i + 1 << ", T" << i + 1 << "]\n";
  y << "cables:\n  rings:\n    material: fibreglass\n    radius: 0.0015\n    prestress: "
    << shortestNumber(s.ring_prestress) << "\n    members:\n";
  for (int i = 0; i < n; ++i)
    y << "      R" << i + 1 << ": [B" << i + 1 << ", B" << (i + 1) % n + 1 << "]\n";
  for (int i = 0; i < n; ++i)
    y << "      R" << n + i + 1 << ": [T" << i + 1 << ", T" << (i + 1) % n + 1 << "]\n";
  y << "  verticals:\n    material: fibreglass\n    radius: 0.0015\n    prestress: "
    << shortestNumber(vertical_prestress) << "\n    members:\n";
  for (int i = 0; i < n; ++i)
    y << "      V" << i + 1 << ": [B" << i + 1 << ", T" << (i + 1) % n + 1 << "]\n";
  y << "contact: {enabled: false, pairs: auto}\n" << analysis(s.pinned);
  return y.str();
}

std::string octahedronScene(const OctahedronSpec& s)
{
  requirePositive("strut_length", s.strut_length);
  requirePositive("prestress", s.prestress);
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

}  // namespace active_tensegrity::core
