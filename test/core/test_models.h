// Small models built in code for the core tests.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>

#include "active_tensegrity/oracle/mechanics.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::test
{
using namespace active_tensegrity::core;

inline Body makeStrut(const std::string& name, double length, double radius, double density)
{
  Body b;
  b.name = name;
  b.kind = BodyKind::kStrut;
  b.length = length;
  StrutLayer layer;
  layer.material = "steel";
  layer.outer_radius = radius;
  layer.density = density;
  layer.youngs_modulus = 210e9;
  layer.poisson_ratio = 0.3;
  b.layers.push_back(layer);
  b.mass = density * M_PI * radius * radius * length;
  const double jt = b.mass * (3.0 * radius * radius + length * length) / 12.0;
  b.inertia = Vec3(jt, jt, 0.5 * b.mass * radius * radius);
  return b;
}

/// Puts a steel core (E = 210 GPa, nu = 0.3) of the given radius inside a strut's one layer, which becomes its
/// sleeve (the mass and inertia are left as they were: contact tests).
inline void addSteelCore(Body& b, double radius)
{
  StrutLayer core = b.layers.back();
  core.material = "steel";
  core.inner_radius = 0.0;
  core.outer_radius = radius;
  core.youngs_modulus = 210e9;
  core.poisson_ratio = 0.3;
  b.layers.back().inner_radius = radius;
  b.layers.insert(b.layers.begin(), core);
}

/// One free strut, its quaternion norm its only constraint (no forces), its axis along `axis`, centre at 0.
inline Model freeStrutModel(const std::string& name, double length, double radius, double density, const Vec3& axis)
{
  Model m;
  m.bodies.push_back(makeStrut(name, length, radius, density));
  Constraint c;
  c.kind = Constraint::Kind::kQuatNorm;
  c.body = 0;
  m.constraints.push_back(c);
  finalizeModel(m);
  m.q0.setZero(m.nq);
  m.q0.segment<4>(3) = thetaFromZAxis(axis);
  return m;
}

inline Body makePointMass(const std::string& name, double mass)
{
  Body b;
  b.name = name;
  b.kind = BodyKind::kPointMass;
  b.mass = mass;
  return b;
}

inline Cable makeCable(const std::string& name, PointRef a, PointRef b, double k, double l0, double c)
{
  Cable cable;
  cable.name = name;
  cable.points = { a, b };
  cable.stiffness = k;
  cable.rest_length = l0;
  cable.damping = c;
  return cable;
}

inline Constraint pointConstraint(const std::string& name, PointRef a, PointRef b, int actuator = -1,
                                  const Vec3& direction = Vec3::UnitZ(), double offset = 0.0)
{
  Constraint c;
  c.name = name;
  c.a = a;
  c.b = b;
  if (actuator >= 0)
  {
    c.directions = { direction };
    c.offsets = { offset };
    c.actuator = actuator;
  }
  else
  {
    c.directions = { Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ() };
    c.offsets = { 0.0, 0.0, 0.0 };
  }
  return c;
}

/// Two struts, one point mass: cables strut-strut, strut-ground, strut-point mass (damped), a
/// ball joint between the struts, one end pinned, a quaternion norm per strut, one actuated
/// coordinate of the point mass and one of a strut end. Every kind of element and constraint.
inline Model mixedModel()
{
  Model m;
  m.name = "mixed";
  m.bodies.push_back(makeStrut("A", 1.2, 0.03, 7800.0));
  m.bodies.push_back(makeStrut("B", 1.0, 0.025, 7800.0));
  m.bodies.push_back(makePointMass("M", 0.7));
  finalizeModel(m);
  const Vec3 up(0.0, 0.0, 0.6), dn(0.0, 0.0, -0.6), up_b(0.0, 0.0, 0.5), dn_b(0.0, 0.0, -0.5);
  m.cables.push_back(makeCable("ab", PointRef{ 0, up }, PointRef{ 1, dn_b }, 3000.0, 0.3, 15.0));
  m.cables.push_back(makeCable("ag", PointRef{ 0, dn }, PointRef{ -1, Vec3(1.0, 0.5, -0.2) }, 2000.0, 0.5, 0.0));
  m.cables.push_back(makeCable("bm", PointRef{ 1, up_b }, PointRef{ 2, Vec3::Zero() }, 1500.0, 0.2, 8.0));
  m.cables.push_back(
      makeCable("am", PointRef{ 0, Vec3(0.01, 0.02, 0.3) }, PointRef{ 2, Vec3::Zero() }, 900.0, 0.1, 3.0));
  m.loads.push_back(PointLoad{ "push", PointRef{ 0, Vec3(0.02, -0.01, 0.4) }, Vec3(30.0, -12.0, 45.0) });
  m.loads.push_back(PointLoad{ "weight", PointRef{ 2, Vec3::Zero() }, Vec3(0.0, 0.0, -20.0) });
  m.actuators.push_back(Actuator{ "lift", -1.0, 1.0, {}, {} });
  m.constraints.push_back(pointConstraint("joint", PointRef{ 0, up }, PointRef{ 1, up_b }));
  m.constraints.push_back(pointConstraint("pin", PointRef{ 1, dn_b }, PointRef{ -1, Vec3(0.1, 0.2, 0.0) }));
  m.constraints.push_back(
      pointConstraint("act_m", PointRef{ 2, Vec3::Zero() }, PointRef{ -1, Vec3::Zero() }, 0, Vec3(0.0, 0.6, 0.8), 0.3));
  m.constraints.push_back(
      pointConstraint("act_a", PointRef{ 0, dn }, PointRef{ -1, Vec3::Zero() }, 0, Vec3(1.0, 0.0, 0.0), -0.1));
  m.actuators[0].constraints = { 2, 3 };
  for (int i = 0; i < 2; ++i)
  {
    Constraint c;
    c.kind = Constraint::Kind::kQuatNorm;
    c.body = i;
    c.name = m.bodies[i].name + ".norm";
    m.constraints.push_back(c);
  }
  m.gravity_enabled = true;
  finalizeModel(m);
  m.q0.setZero(m.nq);
  m.q0.segment<3>(0) = Vec3(0.1, 0.0, 0.7);
  m.q0.segment<4>(3) = thetaFromZAxis(Vec3(0.3, 0.2, 1.0));
  m.q0.segment<3>(7) = Vec3(-0.2, 0.3, 0.5);
  m.q0.segment<4>(10) = thetaFromZAxis(Vec3(-0.4, 0.1, 1.0));
  m.q0.segment<3>(14) = Vec3(0.9, 0.8, 1.6);
  return m;
}

/// A random vector near x (Theta off the unit sphere too: the formulas hold for any Theta).
inline Eigen::VectorXd perturbed(const Eigen::VectorXd& x, double amplitude, std::mt19937& rng)
{
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  Eigen::VectorXd y = x;
  for (int i = 0; i < y.size(); ++i)
    y(i) += u(rng);
  return y;
}

inline Eigen::VectorXd randomVector(int n, double amplitude, std::mt19937& rng)
{
  return perturbed(Eigen::VectorXd::Zero(n), amplitude, rng);
}

/// The dense top-left n x n block of a block-sparse matrix.
inline Eigen::MatrixXd denseBlock(const BlockSparseMatrix& m, int rows, int cols, int r0 = 0, int c0 = 0)
{
  return Eigen::MatrixXd(m.matrix()).block(r0, c0, rows, cols);
}

// m* zeta'' = -K zeta^1.5 (1 + D zeta'), zeta(0) = 0, zeta'(0) = v: the rebound speed ratio, by RK4
inline double reboundOfOneDegreeOfFreedom(double mass, double k, double v, double restitution)
{
  const double d = 3.0 * (1.0 - restitution * restitution) / (4.0 * v);
  const auto acc = [&](double z, double zd)
  { return z > 0.0 ? -k * std::pow(z, 1.5) * std::max(0.0, 1.0 + d * zd) / mass : 0.0; };
  double z = 0.0, zd = v;
  const double h = 1e-7;
  for (int i = 0; i < 10000000; ++i)
  {
    const double k1z = zd, k1v = acc(z, zd);
    const double k2z = zd + 0.5 * h * k1v, k2v = acc(z + 0.5 * h * k1z, zd + 0.5 * h * k1v);
    const double k3z = zd + 0.5 * h * k2v, k3v = acc(z + 0.5 * h * k2z, zd + 0.5 * h * k2v);
    const double k4z = zd + h * k3v, k4v = acc(z + h * k3z, zd + h * k3v);
    z += h / 6.0 * (k1z + 2 * k2z + 2 * k3z + k4z);
    zd += h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v);
    if (z < 0.0 && zd < 0.0)
      return -zd / v;
  }
  return std::nan("");
}

/// The impact of a mass on a linear spring-dashpot that never pulls (F = max(0, k z + c z')) from approach speed v,
/// in closed form: z = v / wd e^(-xi w0 t) sin(wd t) until the force k z + c z' falls to zero, at
/// wd t* = pi - atan(2 xi sqrt(1 - xi^2) / (1 - 2 xi^2)) (xi < 1/sqrt(2)); the mass leaves at the speed it has
/// then. The deepest overlap is at wd t = atan(sqrt(1 - xi^2) / xi).
struct LinearImpact
{
  double rebound = 0.0;          // exit speed / approach speed
  double max_penetration = 0.0;  // m
  double max_force = 0.0;        // N
  double force_time = 0.0;       // t*: how long the force acts, s
};
inline LinearImpact linearImpact(double mass, double k, double c, double v)
{
  const double w0 = std::sqrt(k / mass), xi = c / (2.0 * std::sqrt(k * mass));
  const double wd = w0 * std::sqrt(1.0 - xi * xi);
  const auto z = [&](double t) { return v / wd * std::exp(-xi * w0 * t) * std::sin(wd * t); };
  const auto zd = [&](double t)
  { return v * std::exp(-xi * w0 * t) * (std::cos(wd * t) - xi * w0 / wd * std::sin(wd * t)); };
  LinearImpact out;
  out.force_time = (M_PI - std::atan(2.0 * xi * std::sqrt(1.0 - xi * xi) / (1.0 - 2.0 * xi * xi))) / wd;
  out.rebound = -zd(out.force_time) / v;
  out.max_penetration = z(std::atan(std::sqrt(1.0 - xi * xi) / std::max(xi, 1e-300)) / wd);
  // the largest force, on a fine grid (F is smooth and single-peaked: relative error ~1e-9)
  for (int i = 0; i <= 20000; ++i)
  {
    const double t = out.force_time * i / 20000.0;
    out.max_force = std::max(out.max_force, k * z(t) + c * zd(t));
  }
  return out;
}

/// Newmark's trapezoidal rule (gamma 1/2, beta 1/4: no numerical damping) at step dt with a tight Newton tolerance
/// (m) and 30 iterations: contact tests that compare with closed forms.
inline SolverOptions trapezoidalOptions(double dt, double newton_tolerance)
{
  SolverOptions o;
  o.integrator = Integrator::kNewmark;
  o.dt = dt;
  o.newmark_gamma = 0.5;
  o.newmark_beta = 0.25;
  o.newton_tolerance = newton_tolerance;
  o.max_iterations = 30;
  return o;
}

}  // namespace active_tensegrity::test
