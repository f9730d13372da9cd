/// A value per contact slot (State::contact_speed, the dynamics solver's per-slot memory), every slot holding
/// `fallback` until set. A scene with `pairs: auto` has a slot for every two struts (50 million for 10 000
/// struts) of which a step touches a few: up to denseMostSlots() the values are an array, above it a hash map
/// of the slots set to something other than the fallback. Both give the same values.
#pragma once

#include <cstdint>
#include <cstring>
#include <unordered_map>
#include <vector>

namespace active_tensegrity::core
{
class SlotValues
{
public:
  /// Above this many slots (4 194 304) only the slots set away from the fallback are stored (8 bytes a slot below
  /// it). Tests lower it to run a small scene both ways; it applies to the sets reset after it changes.
  static int& denseMostSlots()
  {
    static int most = 1 << 22;
    return most;
  }

  SlotValues() = default;
  SlotValues(int slots, double fallback)
  {
    reset(slots, fallback);
  }

  /// `slots` slots, each holding `fallback`.
  void reset(int slots, double fallback)
  {
    slots_ = slots;
    fallback_ = fallback;
    sparse_.clear();
    dense_.clear();
    sparse_mode_ = slots > denseMostSlots();
    if (!sparse_mode_)
      dense_.assign(static_cast<size_t>(slots), fallback);
  }

  int size() const
  {
    return slots_;
  }
  bool empty() const
  {
    return slots_ == 0;
  }
  bool isSparse() const
  {
    return sparse_mode_;
  }

  /// The value of slot i (0 <= i < size()).
  double operator[](int i) const
  {
    if (!isSparse())
      return dense_[static_cast<size_t>(i)];
    const auto it = sparse_.find(i);
    return it == sparse_.end() ? fallback_ : it->second;
  }

  void set(int i, double value)
  {
    if (!isSparse())
    {
      dense_[static_cast<size_t>(i)] = value;
      return;
    }
    if (sameBits(value, fallback_))
      sparse_.erase(i);
    else
      sparse_[i] = value;
  }

  /// How many slots a sparse set holds away from the fallback (the array's size when dense).
  size_t stored() const
  {
    return isSparse() ? sparse_.size() : dense_.size();
  }

  /// Same size, fallback and value in every slot (bitwise: NaN equals NaN).
  bool operator==(const SlotValues& o) const
  {
    if (slots_ != o.slots_ || !sameBits(fallback_, o.fallback_))
      return false;
    if (isSparse() && o.isSparse())
    {
      if (sparse_.size() != o.sparse_.size())
        return false;
      for (const auto& [i, v] : sparse_)
        if (!sameBits(v, o[i]))
          return false;
      return true;
    }
    for (int i = 0; i < slots_; ++i)
      if (!sameBits((*this)[i], o[i]))
        return false;
    return true;
  }
  bool operator!=(const SlotValues& o) const
  {
    return !(*this == o);
  }

private:
  static bool sameBits(double a, double b)
  {
    return std::memcmp(&a, &b, sizeof(double)) == 0;
  }

  int slots_ = 0;
  bool sparse_mode_ = false;
  double fallback_ = 0.0;
  std::vector<double> dense_;
  std::unordered_map<int, double> sparse_;
};

}  // namespace active_tensegrity::core
