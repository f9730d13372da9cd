// Contacts compared bit for bit: a scan's shortcuts or the dynamics solver's near list against a full search.
#pragma once

#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/contact/contact.h"

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

/// The contacts touching in a state the dynamics solver made, found by evaluating every checked strut pair and every
/// ground contact from its natural coordinates with the impact speeds it remembers: what the solver's near list
/// (State::natural.contacts) must equal, bit for bit.
inline std::vector<core::ContactPairState> searchEverySlot(const core::Model& model, const core::State& s)
{
  const core::NaturalModel nm = core::buildNaturalModel(model);
  std::vector<int> slots;
  if (model.contact.enabled)
    model.checkedPairList(&slots);
  for (size_t i = 0; i < model.ground_contacts.size(); ++i)
    slots.push_back(model.pairSlots() + static_cast<int>(i));
  std::vector<core::ContactPairState> out;
  for (const int slot : slots)
  {
    const core::NaturalContactSlot c = core::naturalContactSlot(nm, slot);
    Eigen::Matrix<double, 14, 1> f;
    const core::ContactPairState st =
        core::naturalContact(nm, c, core::naturalContactInput(nm, c, s.natural.x, s.natural.v, s.u),
                             s.contactSpeed(slot), &f, nullptr, nullptr);
    if (st.active)
      out.push_back(st);
  }
  return out;
}

}  // namespace active_tensegrity::test
