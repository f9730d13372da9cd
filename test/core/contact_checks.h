// Contacts compared bit for bit: the solver's shortcuts (contacts formed in its pass over a step's end, on demand,
// or kept by a scan) against each other or against a full search.
#pragma once

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
}  // namespace active_tensegrity::test
