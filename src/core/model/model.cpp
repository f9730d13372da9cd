#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
namespace
{
/// The first slot of the k-th strut's row among n struts (its pairs with the struts after it).
long long rowStart(long long k, long long n)
{
  return k * (2 * n - k - 1) / 2;
}
}  // namespace

double effectiveModulus(const StrutLayer& la, const StrutLayer& lb)
{
  return 1.0 / ((1.0 - la.poisson_ratio * la.poisson_ratio) / la.youngs_modulus +
                (1.0 - lb.poisson_ratio * lb.poisson_ratio) / lb.youngs_modulus);
}

double effectiveModulus(const Body& a, const Body& b)
{
  return effectiveModulus(a.layers.back(), b.layers.back());
}

StrutPair makeStrutPair(const Model& model, int body_a, int body_b)
{
  StrutPair p;
  p.body_a = body_a;
  p.body_b = body_b;
  const Body& a = model.bodies[body_a];
  const Body& b = model.bodies[body_b];
  p.stiffness90 = 4.0 / 3.0 * effectiveModulus(a, b) * std::pow(a.radius() * b.radius(), 0.25);
  if (a.layers.size() > 1 || b.layers.size() > 1)
  {
    // the innermost layers (a strut without a core: its one layer, of thickness 0 here)
    const StrutLayer& ca = a.layers.front();
    const StrutLayer& cb = b.layers.front();
    p.core_gap = (a.radius() - ca.outer_radius) + (b.radius() - cb.outer_radius);
    p.core_stiffness90 = 4.0 / 3.0 * effectiveModulus(ca, cb) * std::pow(ca.outer_radius * cb.outer_radius, 0.25);
  }
  return p;
}

void Model::checkAllStrutPairs(const std::vector<int>& struts, const std::vector<std::pair<int, int>>& joined)
{
  if (struts.size() > static_cast<size_t>(kMostAutoPairStruts))
    throw std::invalid_argument("'auto' numbers the pairs of at most " + std::to_string(kMostAutoPairStruts) +
                                " struts, the scene has " + std::to_string(struts.size()) + " (list the pairs instead)");
  all_strut_pairs = true;
  listed_pairs.clear();
  pair_struts = struts;
  std::sort(pair_struts.begin(), pair_struts.end());
  strut_rank.assign(bodies.size(), -1);
  for (size_t k = 0; k < pair_struts.size(); ++k)
    strut_rank[static_cast<size_t>(pair_struts[k])] = static_cast<int>(k);
  joined_struts.clear();
  for (const auto& [a, b] : joined)
    if (a != b && strut_rank[static_cast<size_t>(a)] >= 0 && strut_rank[static_cast<size_t>(b)] >= 0)
      joined_struts.push_back(pairKey(a, b));
  std::sort(joined_struts.begin(), joined_struts.end());
  joined_struts.erase(std::unique(joined_struts.begin(), joined_struts.end()), joined_struts.end());
  const long long n = static_cast<long long>(pair_struts.size());
  all_pair_slots_ = static_cast<int>(n * (n - 1) / 2);
}

std::pair<int, int> Model::pairBodies(int slot) const
{
  if (!all_strut_pairs)
  {
    const StrutPair& p = listed_pairs[static_cast<size_t>(slot)];
    return { p.body_a, p.body_b };
  }
  const long long n = static_cast<long long>(pair_struts.size());
  const long long s = slot;
  // the row k with rowStart(k) <= s < rowStart(k + 1), from the root of rowStart(k) = s, then corrected for
  // its rounding
  const double m = static_cast<double>(2 * n - 1);
  long long k = static_cast<long long>((m - std::sqrt(m * m - 8.0 * static_cast<double>(s))) / 2.0);
  k = std::clamp(k, 0LL, n - 2);
  while (k > 0 && rowStart(k, n) > s)
    --k;
  while (k + 1 < n - 1 && rowStart(k + 1, n) <= s)
    ++k;
  const long long l = s - rowStart(k, n) + k + 1;
  return { pair_struts[static_cast<size_t>(k)], pair_struts[static_cast<size_t>(l)] };
}

StrutPair Model::strutPair(int slot) const
{
  if (!all_strut_pairs)
    return listed_pairs[static_cast<size_t>(slot)];
  const auto [a, b] = pairBodies(slot);
  return makeStrutPair(*this, a, b);
}

bool Model::isCheckedPair(int slot) const
{
  if (!all_strut_pairs)
    return true;
  const auto [a, b] = pairBodies(slot);
  return !std::binary_search(joined_struts.begin(), joined_struts.end(), pairKey(a, b));
}

int Model::allPairsSlot(int body_a, int body_b) const
{
  if (!all_strut_pairs || body_a == body_b)
    return -1;
  const long long n = static_cast<long long>(pair_struts.size());
  long long k = strut_rank[static_cast<size_t>(body_a)];
  long long l = strut_rank[static_cast<size_t>(body_b)];
  if (k < 0 || l < 0 || std::binary_search(joined_struts.begin(), joined_struts.end(), pairKey(body_a, body_b)))
    return -1;
  if (k > l)
    std::swap(k, l);
  return static_cast<int>(rowStart(k, n) + l - k - 1);
}

long Model::checkedPairCount() const
{
  return all_strut_pairs ? static_cast<long>(all_pair_slots_) - static_cast<long>(joined_struts.size()) :
                           static_cast<long>(listed_pairs.size());
}

std::vector<StrutPair> Model::checkedPairList(std::vector<int>* slots) const
{
  std::vector<StrutPair> out;
  if (slots)
    slots->clear();
  for (int i = 0; i < pairSlots(); ++i)
    if (isCheckedPair(i))
    {
      out.push_back(strutPair(i));
      if (slots)
        slots->push_back(i);
    }
  return out;
}

namespace
{
template <class T>
int findNamed(const std::vector<T>& items, const std::string& n)
{
  for (size_t i = 0; i < items.size(); ++i)
    if (items[i].name == n)
      return static_cast<int>(i);
  return -1;
}
}  // namespace

int Model::findNode(const std::string& n) const
{
  return findNamed(nodes, n);
}
int Model::findBody(const std::string& n) const
{
  return findNamed(bodies, n);
}
int Model::findActuator(const std::string& n) const
{
  return findNamed(actuators, n);
}

void finalizeModel(Model& model)
{
  int offset = 0;
  for (Body& b : model.bodies)
  {
    b.nq = b.kind == BodyKind::kStrut ? 7 : 3;
    b.offset = offset;
    offset += b.nq;
  }
  model.nq = offset;
  model.n_lambda = 0;
  for (const Constraint& c : model.constraints)
    model.n_lambda += c.rows();
}

bool hasLoadPath(const Model& model)
{
  return model.analysis.type == AnalysisType::kStatic &&
         model.analysis.load_factor_start != model.analysis.load_factor_end;
}

}  // namespace active_tensegrity::core
