/// The actuation law a dynamics solver follows: the actuators' values, rates and accelerations at any time.
#pragma once

#include <functional>
#include <type_traits>
#include <utility>

#include "active_tensegrity/core/model/kinematics.h"

namespace active_tensegrity::core
{
/// s(t) for every actuator, written into a vector the caller keeps: the solver keeps that vector, so a law made with
/// ActuationLaw::writing costs no heap allocation per step once the vector has its size. A callable that returns
/// the values converts too (a lambda at a call site) and costs one allocation per call (its result).
class ActuationLaw
{
public:
  using Writing = std::function<void(double t, ActuationValues& u)>;

  ActuationLaw() = default;
  /// From any callable that returns the values at t (a lambda, a std::function).
  template <class F, std::enable_if_t<std::is_invocable_r_v<ActuationValues, const F&, double> &&
                                          !std::is_same_v<std::decay_t<F>, ActuationLaw>,
                                      int> = 0>
  ActuationLaw(F f)  // NOLINT(google-explicit-constructor): a law is written as a lambda at every call site
    : write_([f = std::move(f)](double t, ActuationValues& u) { u = f(t); })
  {
  }
  /// From a callable that writes the values at t into its second argument (resizing it as needed).
  static ActuationLaw writing(Writing w)
  {
    ActuationLaw law;
    law.write_ = std::move(w);
    return law;
  }

  /// The values at t into u.
  void operator()(double t, ActuationValues& u) const
  {
    write_(t, u);
  }
  /// The values at t.
  ActuationValues operator()(double t) const
  {
    ActuationValues u;
    write_(t, u);
    return u;
  }

private:
  Writing write_;
};

}  // namespace active_tensegrity::core
