//   tensegrity_bench broad-phase [--repeat N]
// random scenes of 10 to 1000 struts (1 m long, radius 0.02 m, a constant number of struts per m^3)
// with every pair checked: candidates found and the time of BroadPhase::candidates() (the sweep),
// BroadPhase::direct() and of the narrow phase over the candidates (median over N timings).
#include <cmath>
#include <cstdio>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/base/rotation.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
// n struts of length 1 m and radius 0.02 m, centres uniform in a cube of n / density m^3, random
// axes, every pair checked
at::Model randomStruts(int n, double density, std::mt19937& rng)
{
  at::Model m;
  m.name = "random";
  for (int i = 0; i < n; ++i)
    m.bodies.push_back(strut("S" + std::to_string(i), 1.0, 0.02, 210e9, 0.3));
  at::finalizeModel(m);
  const double side = std::cbrt(n / density);
  std::uniform_real_distribution<double> u(0.0, side);
  std::normal_distribution<double> g(0.0, 1.0);
  m.q0.setZero(m.nq);
  for (const at::Body& b : m.bodies)
  {
    m.q0.segment<3>(b.offset) = at::Vec3(u(rng), u(rng), u(rng));
    m.q0.segment<4>(b.offset + 3) = at::thetaFromZAxis(at::Vec3(g(rng), g(rng), g(rng)));
  }
  m.listed_pairs.reserve(static_cast<size_t>(n) * (n - 1) / 2);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      m.listed_pairs.push_back(at::makeStrutPair(m, i, j));
  return m;
}
}  // namespace

int broadPhase(int repeat)
{
  constexpr double kDensity = 4.0;  // struts per m^3
  constexpr double kTarget = 0.02;  // s per timing sample
  std::printf("struts 1 m x r 0.02 m, centres uniform in a cube of n / %.0f m^3, all pairs checked, margin 0;\n",
              kDensity);
  std::printf("times: median over %d samples of about %.0f ms each\n", repeat, 1e3 * kTarget);
  std::printf("%6s %8s %6s %7s %8s %6s %9s %12s %12s %12s %12s\n", "n", "pairs", "cand", "contacts", "cand/n", "sweep",
              "setup ms", "candidates", "direct", "narrow/cand", "narrow/all");
  for (int n : { 10, 20, 50, 100, 200, 500, 1000 })
  {
    std::mt19937 rng(n);
    const at::Model m = randomStruts(n, kDensity, rng);
    const Clock::time_point t0 = Clock::now();
    const at::BroadPhase broad(m);
    const double setup = seconds(t0, Clock::now());
    std::vector<int> cand, dir;
    broad.candidates(m.q0, 0.0, cand);
    broad.direct(m.q0, 0.0, dir);
    if (cand != dir)
    {
      std::cerr << "tensegrity_bench: candidates() and direct() disagree at n = " << n << "\n";
      return 3;
    }
    int contacts = 0;
    for (size_t i = 0; i < m.listed_pairs.size(); ++i)
      contacts += at::contactGeometry(m, static_cast<int>(i), m.q0).gap < 0.0 ? 1 : 0;

    const auto f_cand = [&]
    {
      broad.candidates(m.q0, 0.0, cand);
      g_sink = g_sink + cand.size();
    };
    const auto f_direct = [&]
    {
      broad.direct(m.q0, 0.0, dir);
      g_sink = g_sink + dir.size();
    };
    const auto f_narrow = [&]
    {
      double s = 0.0;
      for (int i : cand)
        s += at::contactGeometry(m, i, m.q0).gap;
      g_sink = g_sink + s;
    };
    const auto f_all = [&]
    {
      double s = 0.0;
      for (size_t i = 0; i < m.listed_pairs.size(); ++i)
        s += at::contactGeometry(m, static_cast<int>(i), m.q0).gap;
      g_sink = g_sink + s;
    };
    const double t_cand = medianPerCall(f_cand, callsFor(f_cand, kTarget), repeat);
    const double t_direct = medianPerCall(f_direct, callsFor(f_direct, kTarget), repeat);
    const double t_narrow = medianPerCall(f_narrow, callsFor(f_narrow, kTarget), repeat);
    const double t_all = medianPerCall(f_all, callsFor(f_all, kTarget), repeat);
    std::printf("%6d %8zu %6zu %7d %8.2f %6s %9.2f %9.2f us %9.2f us %9.2f us %9.2f us\n", n, m.listed_pairs.size(),
                cand.size(), contacts, static_cast<double>(cand.size()) / n, broad.usesSweep() ? "yes" : "no",
                1e3 * setup, 1e6 * t_cand, 1e6 * t_direct, 1e6 * t_narrow, 1e6 * t_all);
  }
  return 0;
}
}  // namespace active_tensegrity::tools::bench
