#include "active_tensegrity/planning/trajectory.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

#include "active_tensegrity/core/solvers/actuation_control.h"

namespace active_tensegrity::planning
{
namespace
{
using Values = std::vector<double>;
using Vec = Eigen::VectorXd;

double perActuator(const std::vector<double>& v, size_t i)
{
  return v.size() == 1 ? v[0] : v[i];
}

Vec vec(const Values& v)
{
  return Eigen::Map<const Vec>(v.data(), static_cast<Eigen::Index>(v.size()));
}

Values values(const Vec& v)
{
  return Values(v.data(), v.data() + v.size());
}

/// One piece of the blended curve: a straight line a -> b, or the quadratic arc p0, p1 (the corner), p2.
struct Piece
{
  bool arc = false;
  Vec a, b;        // line
  Vec p0, p1, p2;  // arc
  int corner = -1;
  bool stop_at_end = false;  // a sharp corner (d = 0) follows: the path speed is 0 there
};

std::vector<Piece> pieces(const std::vector<Values>& w, const std::vector<double>& d)
{
  std::vector<Piece> out;
  const size_t m = w.size();
  Vec from = vec(w.front());
  for (size_t k = 1; k < m; ++k)
  {
    const Vec corner = vec(w[k]);
    const Vec in = corner - vec(w[k - 1]);
    const bool last = k + 1 == m;
    const double dk = last ? 0.0 : d[k];
    Piece line;
    line.a = from;
    line.b = in.norm() > 0.0 ? Vec(corner - dk * in.normalized()) : corner;
    line.stop_at_end = !last && dk == 0.0;
    if ((line.b - line.a).norm() > 0.0)
      out.push_back(line);
    else if (line.stop_at_end && !out.empty())
      out.back().stop_at_end = true;
    if (dk > 0.0)
    {
      const Vec outv = vec(w[k + 1]) - corner;
      Piece arc;
      arc.arc = true;
      arc.p0 = line.b;
      arc.p1 = corner;
      arc.p2 = corner + dk * outv.normalized();
      arc.corner = static_cast<int>(k);
      out.push_back(arc);
      from = arc.p2;
    }
    else
      from = corner;
  }
  return out;
}

/// Position, first and second derivative of a piece at its parameter u in [0, 1].
void evaluate(const Piece& p, double u, Vec& x, Vec& dx, Vec& ddx)
{
  if (!p.arc)
  {
    x = p.a + u * (p.b - p.a);
    dx = p.b - p.a;
    ddx = Vec::Zero(x.size());
    return;
  }
  x = (1 - u) * (1 - u) * p.p0 + 2 * u * (1 - u) * p.p1 + u * u * p.p2;
  dx = 2 * (1 - u) * (p.p1 - p.p0) + 2 * u * (p.p2 - p.p1);
  ddx = 2 * (p.p2 - 2 * p.p1 + p.p0);
}

/// The curve on an arc-length grid: position, unit tangent, curvature vector; the speed cap where the
/// path must stop.
struct Grid
{
  std::vector<double> s;
  std::vector<Vec> x, t, k;
  std::vector<bool> stop;
};

Grid grid(const std::vector<Piece>& ps, double ds)
{
  Grid g;
  double s = 0.0;
  Vec x, dx, ddx;
  for (size_t p = 0; p < ps.size(); ++p)
  {
    // arc length of the piece by the midpoint rule on a fine parameter grid
    const int fine = 256;
    double length = 0.0;
    for (int j = 0; j < fine; ++j)
    {
      evaluate(ps[p], (j + 0.5) / fine, x, dx, ddx);
      length += dx.norm() / fine;
    }
    const int n = std::max(2, static_cast<int>(std::ceil(length / ds)));
    // a piece starts with its own point after a sharp corner (the same position, the new tangent: the cell
    // of zero length keeps the directions apart)
    for (int j = p == 0 || ps[p - 1].stop_at_end ? 0 : 1; j <= n; ++j)
    {
      // the parameter is close to proportional to arc length (exactly for lines, within the arc's speed
      // ratio for the arcs); s accumulates the true chord lengths
      const double u = static_cast<double>(j) / n;
      evaluate(ps[p], u, x, dx, ddx);
      if (!g.x.empty())
        s += (x - g.x.back()).norm();
      const double speed = dx.norm();
      const Vec t = dx / speed;
      g.s.push_back(s);
      g.x.push_back(x);
      g.t.push_back(t);
      g.k.push_back((ddx - t.dot(ddx) * t) / (speed * speed));
      g.stop.push_back(j == n && ps[p].stop_at_end);
    }
  }
  g.stop.front() = g.stop.back() = true;
  return g;
}
}  // namespace

Trajectory restToRest(const std::vector<Values>& waypoints, const std::vector<double>& max_speeds,
                      const std::vector<double>& max_accelerations, double sample_dt)
{
  Trajectory out;
  const size_t n = waypoints.front().size();
  out.times = { 0.0 };
  out.positions = { waypoints.front() };
  out.velocities = { Values(n, 0.0) };
  out.accelerations = { Values(n, 0.0) };
  double t0 = 0.0;
  for (size_t w = 0; w + 1 < waypoints.size(); ++w)
  {
    const Values& a = waypoints[w];
    const Values& b = waypoints[w + 1];
    double vs = INFINITY, as = INFINITY;
    for (size_t i = 0; i < n; ++i)
    {
      const double d = std::abs(b[i] - a[i]);
      if (d > 0.0)
      {
        vs = std::min(vs, perActuator(max_speeds, i) / d);
        as = std::min(as, perActuator(max_accelerations, i) / d);
      }
    }
    if (!std::isfinite(vs))
      continue;  // a repeated waypoint
    core::ActuationValue rest;
    const core::ActuatorMotion s = core::ActuatorMotion::ramp(0.0, rest, 1.0, vs, as);
    const double T = s.endTime();
    const int samples = std::max(2, static_cast<int>(std::ceil(T / sample_dt)));
    for (int k = 1; k <= samples; ++k)
    {
      const double t = T * k / samples;
      const core::ActuationValue p = s.evaluate(t);
      Values pos(n), vel(n), acc(n);
      for (size_t i = 0; i < n; ++i)
      {
        const double d = b[i] - a[i];
        pos[i] = k == samples ? b[i] : a[i] + p.value * d;
        vel[i] = k == samples ? 0.0 : p.rate * d;
        acc[i] = p.accel * d;
      }
      out.times.push_back(t0 + t);
      out.positions.push_back(pos);
      out.velocities.push_back(vel);
      out.accelerations.push_back(acc);
    }
    t0 += T;
  }
  out.duration = t0;
  return out;
}

std::vector<double> blendLengths(const std::vector<Values>& waypoints, double tolerance)
{
  std::vector<double> d(waypoints.size(), 0.0);
  for (size_t k = 1; k + 1 < waypoints.size(); ++k)
  {
    const Vec in = vec(waypoints[k]) - vec(waypoints[k - 1]);
    const Vec out = vec(waypoints[k + 1]) - vec(waypoints[k]);
    if (in.norm() == 0.0 || out.norm() == 0.0)
      continue;
    // the arc's farthest point from the corner is its midpoint, (d / 4) |u_out - u_in| away
    const double turn = (out.normalized() - in.normalized()).lpNorm<Eigen::Infinity>();
    if (turn < 1e-12)
      continue;
    d[k] = std::min({ 4.0 * tolerance / turn, 0.5 * in.norm(), 0.5 * out.norm() });
  }
  return d;
}

std::vector<Values> blendedCurve(const std::vector<Values>& waypoints, const std::vector<double>& d, double spacing,
                                 std::vector<int>* corner)
{
  std::vector<Values> points = { waypoints.front() };
  if (corner)
    *corner = { -1 };
  Vec x, dx, ddx;
  for (const Piece& p : pieces(waypoints, d))
  {
    // lines: their end only (continuation follows a straight line); arcs: chords no longer than spacing
    // (the arc's parameter speed is largest at an end)
    const int n = p.arc ? std::max(4, static_cast<int>(std::ceil(2.0 *
                                                                 std::max((p.p1 - p.p0).lpNorm<Eigen::Infinity>(),
                                                                          (p.p2 - p.p1).lpNorm<Eigen::Infinity>()) /
                                                                 spacing))) :
                          1;
    for (int j = 1; j <= n; ++j)
    {
      evaluate(p, static_cast<double>(j) / n, x, dx, ddx);
      points.push_back(values(x));
      if (corner)
        corner->push_back(p.corner);
    }
  }
  points.back() = waypoints.back();
  return points;
}

Trajectory timeOptimal(const std::vector<Values>& waypoints, const std::vector<double>& d,
                       const std::vector<double>& max_speeds, const std::vector<double>& max_accelerations,
                       double sample_dt)
{
  const size_t n = waypoints.front().size();
  const std::vector<Piece> ps = pieces(waypoints, d);
  if (ps.empty())
    return restToRest(waypoints, max_speeds, max_accelerations, sample_dt);
  double total = 0.0;
  for (size_t k = 1; k < waypoints.size(); ++k)
    total += (vec(waypoints[k]) - vec(waypoints[k - 1])).norm();
  const Grid g = grid(ps, std::min(1e-3, total / 200.0));
  const size_t m = g.s.size();
  // 2 % of every acceleration kept back for the grid (a cell's constant path acceleration joins the forward and
  // backward passes)
  std::vector<double> amax(n);
  for (size_t i = 0; i < n; ++i)
    amax[i] = 0.98 * perActuator(max_accelerations, i);
  // caps of the squared path speed: the speed limits, and half of each acceleration for the centripetal part
  std::vector<double> cap(m), x(m);
  const auto tangential = [&](size_t j, double xj)
  {
    double a = INFINITY;
    for (size_t i = 0; i < n; ++i)
      if (std::abs(g.t[j][i]) > 1e-12)
        a = std::min(a, (amax[i] - std::abs(g.k[j][i]) * xj) / std::abs(g.t[j][i]));
    return std::max(0.0, a);
  };
  for (size_t j = 0; j < m; ++j)
  {
    double c = INFINITY;
    for (size_t i = 0; i < n; ++i)
    {
      if (std::abs(g.t[j][i]) > 1e-12)
        c = std::min(c, std::pow(perActuator(max_speeds, i) / std::abs(g.t[j][i]), 2));
      if (std::abs(g.k[j][i]) > 1e-12)
        c = std::min(c, 0.5 * amax[i] / std::abs(g.k[j][i]));
    }
    cap[j] = g.stop[j] ? 0.0 : c;
  }
  // forward (accelerating) and backward (braking) passes over x = (ds/dt)^2
  x[0] = 0.0;
  for (size_t j = 0; j + 1 < m; ++j)
    x[j + 1] = std::min(cap[j + 1], x[j] + 2.0 * tangential(j, x[j]) * (g.s[j + 1] - g.s[j]));
  for (size_t j = m - 1; j > 0; --j)
    x[j - 1] = std::min(x[j - 1], x[j] + 2.0 * tangential(j, x[j]) * (g.s[j] - g.s[j - 1]));
  // times at the grid points
  std::vector<double> t(m, 0.0);
  for (size_t j = 0; j + 1 < m; ++j)
  {
    const double v = std::sqrt(x[j]) + std::sqrt(x[j + 1]);
    t[j + 1] = t[j] + (v > 0.0 ? 2.0 * (g.s[j + 1] - g.s[j]) / v : 0.0);
  }
  Trajectory out;
  out.duration = t.back();
  const int samples = std::max(2, static_cast<int>(std::ceil(out.duration / sample_dt)));
  size_t j = 0;
  for (int k = 0; k <= samples; ++k)
  {
    const double tk = out.duration * k / samples;
    while (j + 2 < m && t[j + 1] < tk)
      ++j;
    // constant path acceleration over the grid interval
    const double h = g.s[j + 1] - g.s[j];
    const double acc = h > 0.0 ? (x[j + 1] - x[j]) / (2.0 * h) : 0.0;
    const double tau = std::clamp(tk - t[j], 0.0, t[j + 1] - t[j]);
    const double v0 = std::sqrt(x[j]);
    const double ds = std::min(h, v0 * tau + 0.5 * acc * tau * tau);
    const double f = h > 0.0 ? ds / h : 0.0;
    const double v = std::sqrt(std::max(0.0, x[j] + 2.0 * acc * ds));
    const Vec pos = g.x[j] + f * (g.x[j + 1] - g.x[j]);
    const Vec tan = ((1 - f) * g.t[j] + f * g.t[j + 1]).normalized();
    const Vec curv = (1 - f) * g.k[j] + f * g.k[j + 1];
    const bool end = k == samples;
    out.times.push_back(tk);
    out.positions.push_back(end ? waypoints.back() : values(pos));
    out.velocities.push_back(end ? Values(n, 0.0) : values(tan * v));
    out.accelerations.push_back(values(tan * acc + curv * v * v));
  }
  return out;
}

}  // namespace active_tensegrity::planning
