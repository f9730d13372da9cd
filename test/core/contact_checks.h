// Contacts compared: bit for bit, a scan's shortcuts against a full search; to a tolerance, the dynamics solver's
// contacts against a search over the body poses it writes.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/contact.h"

namespace active_tensegrity::test
{
/// The same contacts in the same order, every field a consumer reads (peaks, messages, CSV) equal to the last bit;
/// `t` names the time in the messages.
inline void expectSameContacts(const std::vector<core::ContactPairState>& a,
                               const std::vector<core::ContactPairState>& b, double t)
{
  ASSERT_EQ(a.size(), b.size()) << "t = " << t;
  for (size_t i = 0; i < a.size(); ++i)
  {
    EXPECT_EQ(a[i].pair, b[i].pair) << "t = " << t;
    EXPECT_EQ(a[i].normal_force, b[i].normal_force) << "t = " << t;
    EXPECT_EQ(a[i].friction_force, b[i].friction_force) << "t = " << t;
    EXPECT_EQ(a[i].penetration, b[i].penetration) << "t = " << t;
    EXPECT_EQ(a[i].penetration_rate, b[i].penetration_rate) << "t = " << t;
    EXPECT_EQ(a[i].force_on_a, b[i].force_on_a) << "t = " << t;
    EXPECT_EQ(a[i].point_a, b[i].point_a) << "t = " << t;
  }
}

/// The same contacts in the same order, every field a consumer reads within `rel` of the larger (forces, rates) or
/// of the struts' size `length` (depths, points): the dynamics solver's contacts, formed from its natural
/// coordinates, against a search over the body poses it writes.
inline void expectAgreeingContacts(const std::vector<core::ContactPairState>& a,
                                   const std::vector<core::ContactPairState>& b, double t, double rel, double length)
{
  ASSERT_EQ(a.size(), b.size()) << "t = " << t;
  const auto near = [rel](double x, double y, double scale)
  { return std::abs(x - y) <= rel * std::max({ std::abs(x), std::abs(y), scale }); };
  for (size_t i = 0; i < a.size(); ++i)
  {
    EXPECT_EQ(a[i].pair, b[i].pair) << "t = " << t;
    const double force = std::max(a[i].normal_force, b[i].normal_force);
    EXPECT_TRUE(near(a[i].normal_force, b[i].normal_force, 0.0)) << "t = " << t << ": " << a[i].normal_force << " against " << b[i].normal_force;
    EXPECT_TRUE(near(a[i].friction_force, b[i].friction_force, force)) << "t = " << t << ": " << a[i].friction_force << " against " << b[i].friction_force;
    EXPECT_TRUE(near(a[i].penetration, b[i].penetration, 0.0)) << "t = " << t << ": " << a[i].penetration << " against " << b[i].penetration;
    EXPECT_TRUE(near(a[i].penetration_rate, b[i].penetration_rate, 1e-3)) << "t = " << t << ": " << a[i].penetration_rate << " against " << b[i].penetration_rate;
    EXPECT_LE((a[i].force_on_a - b[i].force_on_a).norm(), rel * force) << "t = " << t;
    EXPECT_LE((a[i].point_a - b[i].point_a).norm(), rel * length) << "t = " << t;
  }
}
}  // namespace active_tensegrity::test
