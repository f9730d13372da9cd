#include "active_tensegrity/core/solvers/actuation_control.h"

#include "active_tensegrity/core/base/text.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

namespace active_tensegrity::core
{
namespace
{
// a trajectory's first point at its start time must match the current value this closely (m)
constexpr double kStartTolerance = 1e-6;
// values may leave [min, max] by this much (m) through rounding
constexpr double kBoundSlack = 1e-9;

}  // namespace

// ---------------------------------------------------------------------------------------------
// ActuatorMotion

ActuatorMotion ActuatorMotion::hold(double value)
{
  ActuatorMotion m;
  m.final_value_ = value;
  return m;
}

void ActuatorMotion::addQuadratic(double t0, double duration, double s0, double v0, double a)
{
  if (!(duration > 0.0))
    return;
  pieces_.push_back({ t0, t0 + duration, { s0, v0, 0.5 * a, 0.0 } });
}

void ActuatorMotion::addHermite(double t0, double t1, double s0, double v0, double s1, double v1)
{
  const double h = t1 - t0;
  const double d = (s1 - s0) / h;
  // s = s0 + v0 tau + c2 tau^2 + c3 tau^3 with s(h) = s1, s'(h) = v1
  const double c2 = (3.0 * d - 2.0 * v0 - v1) / h;
  const double c3 = (v0 + v1 - 2.0 * d) / (h * h);
  pieces_.push_back({ t0, t1, { s0, v0, c2, c3 } });
}

ActuatorMotion ActuatorMotion::ramp(double t0, const ActuationValue& start, double target, double max_speed,
                                    double max_accel)
{
  ActuatorMotion m;
  m.final_value_ = target;
  const double a = max_accel;
  double t = t0, s = start.value, v = start.rate;
  const double dist = target - s;
  // brake first when moving away from the target or too fast to stop before it
  if ((v != 0.0 && dist * v <= 0.0) || v * v / (2.0 * a) > std::abs(dist))
  {
    const double dir = v > 0.0 ? 1.0 : -1.0;
    const double duration = std::abs(v) / a;
    m.addQuadratic(t, duration, s, v, -dir * a);
    s += 0.5 * v * duration;
    t += duration;
    v = 0.0;
  }
  const double d = target - s;
  if (d == 0.0)
    return m;
  const double dir = d > 0.0 ? 1.0 : -1.0;
  const double D = std::abs(d);
  const double w0 = dir * v;  // >= 0 here
  const double vp = std::min(max_speed, std::sqrt(a * D + 0.5 * w0 * w0));
  // speed w0 -> vp, cruise at vp, vp -> 0
  const double t1 = std::abs(vp - w0) / a;
  const double dist1 = (vp + w0) * 0.5 * t1;  // distance covered while changing speed
  const double dist3 = vp * vp / (2.0 * a);
  const double cruise = std::max(0.0, D - dist1 - dist3);
  m.addQuadratic(t, t1, s, dir * w0, vp >= w0 ? dir * a : -dir * a);
  t += t1;
  s += dir * dist1;
  const double t2 = vp > 0.0 ? cruise / vp : 0.0;
  m.addQuadratic(t, t2, s, dir * vp, 0.0);
  t += t2;
  s += dir * cruise;
  m.addQuadratic(t, vp / a, s, dir * vp, -dir * a);
  return m;
}

ActuatorMotion ActuatorMotion::spline(double t0, const ActuationValue& start, const std::vector<double>& times,
                                      const std::vector<double>& values, const std::vector<double>& rates)
{
  ActuatorMotion m;
  if (times.empty())
    return hold(start.value);
  // knots: the start, then the points (a first point at t0 replaces the start's value, not its rate)
  std::vector<double> kt{ t0 }, ks{ start.value };
  std::vector<double> kv;
  const bool given = !rates.empty();
  size_t first = 0;
  if (times[0] <= t0)
    first = 1;  // the first point is the start itself (checked by the caller)
  for (size_t k = first; k < times.size(); ++k)
  {
    kt.push_back(times[k]);
    ks.push_back(values[k]);
  }
  const size_t n = kt.size();
  kv.assign(n, 0.0);
  kv[0] = start.rate;
  if (given)
  {
    for (size_t k = 1; k < n; ++k)
      kv[k] = rates[k - 1 + first];
  }
  else
  {
    // Fritsch-Carlson: harmonic-mean slopes, zero at local extrema; the curve stays monotone between
    // the points and so within their range; the end at rest
    std::vector<double> delta(n - 1);
    for (size_t k = 0; k + 1 < n; ++k)
      delta[k] = (ks[k + 1] - ks[k]) / (kt[k + 1] - kt[k]);
    for (size_t k = 1; k + 1 < n; ++k)
    {
      if (delta[k - 1] * delta[k] <= 0.0)
        kv[k] = 0.0;
      else
      {
        const double h0 = kt[k] - kt[k - 1], h1 = kt[k + 1] - kt[k];
        const double w1 = 2.0 * h1 + h0, w2 = h1 + 2.0 * h0;
        kv[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k]);
      }
    }
    kv[n - 1] = 0.0;
  }
  for (size_t k = 0; k + 1 < n; ++k)
    m.addHermite(kt[k], kt[k + 1], ks[k], kv[k], ks[k + 1], kv[k + 1]);
  m.final_value_ = ks[n - 1];  // held after the end: the last rate is 0 (the caller checks given rates)
  return m;
}

ActuationValue ActuatorMotion::evaluate(double t) const
{
  ActuationValue out;
  if (pieces_.empty() || t >= pieces_.back().t1)
  {
    out.value = final_value_;
    return out;
  }
  const Piece* p = &pieces_.front();
  if (t < p->t0)
  {
    out.value = p->c[0];  // before its start a motion rests at its start value
    return out;
  }
  {
    // the piece with t0 <= t < t1 (few pieces: a linear search from the back is enough)
    for (auto it = pieces_.rbegin(); it != pieces_.rend(); ++it)
      if (t >= it->t0)
      {
        p = &*it;
        break;
      }
  }
  const double tau = t - p->t0;
  const double* c = p->c;
  out.value = c[0] + tau * (c[1] + tau * (c[2] + tau * c[3]));
  out.rate = c[1] + tau * (2.0 * c[2] + 3.0 * tau * c[3]);
  out.accel = 2.0 * c[2] + 6.0 * tau * c[3];
  return out;
}

double ActuatorMotion::endTime() const
{
  return pieces_.empty() ? -INFINITY : pieces_.back().t1;
}

void ActuatorMotion::range(double& lo, double& hi) const
{
  lo = hi = final_value_;
  for (const Piece& p : pieces_)
  {
    const double* c = p.c;
    const double h = p.t1 - p.t0;
    std::vector<double> taus = { 0.0, h };
    // roots of c1 + 2 c2 tau + 3 c3 tau^2 inside the piece
    const double A = 3.0 * c[3], B = 2.0 * c[2], C = c[1];
    if (A != 0.0)
    {
      const double disc = B * B - 4.0 * A * C;
      if (disc >= 0.0)
      {
        const double r = std::sqrt(disc);
        taus.push_back((-B + r) / (2.0 * A));
        taus.push_back((-B - r) / (2.0 * A));
      }
    }
    else if (B != 0.0)
      taus.push_back(-C / B);
    for (double tau : taus)
      if (tau >= 0.0 && tau <= h)
      {
        const double s = c[0] + tau * (c[1] + tau * (c[2] + tau * c[3]));
        lo = std::min(lo, s);
        hi = std::max(hi, s);
      }
  }
}

// ---------------------------------------------------------------------------------------------
// ActuationController

ActuationController::ActuationController(const Model& model, const ActuationValues& initial)
{
  for (const Actuator& a : model.actuators)
  {
    names_.push_back(a.name);
    min_value_.push_back(a.min_value);
    max_value_.push_back(a.max_value);
  }
  reset(initial);
}

void ActuationController::reset(const ActuationValues& values)
{
  motions_.clear();
  for (size_t i = 0; i < names_.size(); ++i)
    motions_.push_back(ActuatorMotion::hold(i < values.size() ? values[i].value : 0.0));
}

int ActuationController::index(const std::string& name) const
{
  const auto it = std::find(names_.begin(), names_.end(), name);
  return it == names_.end() ? -1 : static_cast<int>(it - names_.begin());
}

ActuationValues ActuationController::values(double t) const
{
  ActuationValues u;
  values(t, u);
  return u;
}

void ActuationController::values(double t, ActuationValues& u) const
{
  u.resize(motions_.size());
  for (size_t i = 0; i < motions_.size(); ++i)
    u[i] = motions_[i].evaluate(t);
}

bool ActuationController::moving(double t) const
{
  for (const ActuatorMotion& m : motions_)
    if (t < m.endTime())
      return true;
  return false;
}

std::string ActuationController::checkNames(const std::vector<std::string>& names, std::vector<int>& indices) const
{
  indices.clear();
  if (names.empty())
    return "no actuator names given";
  std::set<std::string> seen;
  for (const std::string& n : names)
  {
    const int i = index(n);
    if (i < 0)
    {
      std::ostringstream msg;
      msg << "unknown actuator " << quoted(n) << " (the scene has:";
      for (const std::string& known : names_)
        msg << " " << known;
      msg << ")";
      return clipped(msg.str(), 4 * kMaxEchoLength);
    }
    if (!seen.insert(n).second)
      return "actuator " + quoted(n) + " named twice";
    indices.push_back(i);
  }
  return "";
}

std::string ActuationController::setTargets(double t, const std::vector<std::string>& names,
                                            const std::vector<double>& targets, const std::vector<double>& speeds,
                                            const std::vector<double>& accels, double default_speed,
                                            double default_accel)
{
  std::vector<int> idx;
  std::string err = checkNames(names, idx);
  if (!err.empty())
    return err;
  const size_t n = names.size();
  std::ostringstream msg;
  if (targets.size() != n)
  {
    msg << targets.size() << " targets for " << n << " actuator names";
    return msg.str();
  }
  const auto per_name = [&](const std::vector<double>& v, const char* what, double fallback,
                            std::vector<double>& out) -> std::string
  {
    if (!v.empty() && v.size() != 1 && v.size() != n)
    {
      std::ostringstream m;
      m << v.size() << " " << what << " for " << n << " actuator names (give none, one for all, or one per name)";
      return m.str();
    }
    out.resize(n);
    for (size_t k = 0; k < n; ++k)
    {
      const double x = v.empty() ? fallback : v[v.size() == 1 ? 0 : k];
      if (!std::isfinite(x) || x <= 0.0)
      {
        std::ostringstream m;
        m << what << " of " << quoted(names[k]) << " is " << x << " (must be finite and > 0)";
        return m.str();
      }
      out[k] = x;
    }
    return "";
  };
  std::vector<double> speed, accel;
  if (!(err = per_name(speeds, "max_speeds", default_speed, speed)).empty())
    return err;
  if (!(err = per_name(accels, "max_accelerations", default_accel, accel)).empty())
    return err;
  for (size_t k = 0; k < n; ++k)
  {
    const int i = idx[k];
    if (!std::isfinite(targets[k]))
    {
      msg << "target of " << quoted(names[k]) << " is " << targets[k] << ": not a finite number";
      return msg.str();
    }
    if (targets[k] < min_value_[i] - kBoundSlack || targets[k] > max_value_[i] + kBoundSlack)
    {
      msg << "target of " << quoted(names[k]) << " is " << targets[k] << " m, outside its range [" << min_value_[i]
          << ", " << max_value_[i] << "] m";
      return msg.str();
    }
  }
  for (size_t k = 0; k < n; ++k)
  {
    const int i = idx[k];
    motions_[i] = ActuatorMotion::ramp(t, motions_[i].evaluate(t), targets[k], speed[k], accel[k]);
  }
  return "";
}

std::string ActuationController::setTrajectory(double t, const std::vector<std::string>& names,
                                               const std::vector<double>& times_from_start,
                                               const std::vector<std::vector<double>>& positions,
                                               const std::vector<std::vector<double>>& velocities)
{
  std::vector<int> idx;
  std::string err = checkNames(names, idx);
  if (!err.empty())
    return err;
  const size_t n = names.size(), np = times_from_start.size();
  std::ostringstream msg;
  if (np == 0)
    return "the trajectory has no points";
  if (positions.size() != np || (!velocities.empty() && velocities.size() != np))
    return "positions and velocities must come one row per point";
  for (size_t p = 0; p < np; ++p)
  {
    const double tp = times_from_start[p];
    if (!std::isfinite(tp) || tp < 0.0 || (p > 0 && !(tp > times_from_start[p - 1])))
    {
      msg << "point " << p << ": time_from_start " << tp << " s (times must be finite, >= 0 and strictly increasing)";
      return msg.str();
    }
    if (positions[p].size() != n)
    {
      msg << "point " << p << ": " << positions[p].size() << " positions for " << n << " joint names";
      return msg.str();
    }
    if (!velocities.empty() && !velocities[p].empty() && velocities[p].size() != n)
    {
      msg << "point " << p << ": " << velocities[p].size() << " velocities for " << n << " joint names";
      return msg.str();
    }
    for (size_t k = 0; k < n; ++k)
    {
      const double x = positions[p][k];
      if (!std::isfinite(x))
      {
        msg << "point " << p << ": position of " << quoted(names[k]) << " is " << x;
        return msg.str();
      }
      if (!velocities.empty() && !velocities[p].empty() && !std::isfinite(velocities[p][k]))
      {
        msg << "point " << p << ": velocity of " << quoted(names[k]) << " is " << velocities[p][k];
        return msg.str();
      }
    }
  }
  // velocities are used only when every point has them
  bool given = !velocities.empty();
  for (const auto& v : velocities)
    given = given && !v.empty();
  if (given)
    for (size_t k = 0; k < n; ++k)
      if (velocities[np - 1][k] != 0.0)
      {
        msg << "the last point's velocity of " << quoted(names[k]) << " is " << velocities[np - 1][k]
            << " (a trajectory must end at rest)";
        return msg.str();
      }

  std::vector<ActuatorMotion> motions;
  std::vector<double> times(np);
  for (size_t p = 0; p < np; ++p)
    times[p] = t + times_from_start[p];
  for (size_t k = 0; k < n; ++k)
  {
    const int i = idx[k];
    const ActuationValue now = motions_[i].evaluate(t);
    std::vector<double> values(np), rates;
    for (size_t p = 0; p < np; ++p)
    {
      values[p] = positions[p][k];
      if (given)
        rates.push_back(velocities[p][k]);
    }
    if (times_from_start[0] == 0.0 && std::abs(values[0] - now.value) > kStartTolerance)
    {
      msg << "the first point (time 0) puts " << quoted(names[k]) << " at " << values[0] << " m but it is at "
          << now.value << " m; a jump is an impulse: give the first point a later time";
      return msg.str();
    }
    motions.push_back(ActuatorMotion::spline(t, now, times, values, rates));
    double lo = 0.0, hi = 0.0;
    motions.back().range(lo, hi);
    if (lo < min_value_[i] - kBoundSlack || hi > max_value_[i] + kBoundSlack)
    {
      msg << "the trajectory takes " << quoted(names[k]) << " to [" << lo << ", " << hi << "] m, outside its range ["
          << min_value_[i] << ", " << max_value_[i] << "] m";
      return msg.str();
    }
  }
  for (size_t k = 0; k < n; ++k)
    motions_[idx[k]] = std::move(motions[k]);
  return "";
}

}  // namespace active_tensegrity::core
