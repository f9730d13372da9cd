#include "active_tensegrity/design/form_finding.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>

#include <Eigen/Dense>
#include <yaml-cpp/yaml.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/linalg/svd.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::design
{
using namespace core;

namespace
{
constexpr double kCollapsedLength = 1e-9;  // times the mean member length: a member that short has collapsed
constexpr double kSlackTension = 1e-9;     // times the largest member force: a cable below it is slack
constexpr double kSameTension = 1e-9;      // relative: members of one family within it share a prestress
constexpr double kTargetFit = 1e-6;        // relative: how closely prestress mode must meet a target tension
// what else lets a form exist when the iterations find none: the struts' force densities (a sliding cable
// that runs inside some struts adds to their force only) and the supports
constexpr const char* kOtherWays =
    " (or let each strut have its own force density, --struts free, or the supports react, --supports react)";
constexpr int kMaxNamed = 10;                 // names a message lists
constexpr double kStepRankTolerance = 1e-10;  // relative: smaller pivots of the scaled Jacobian count as zero
constexpr int kPolishIterations = 30;  // Gauss-Newton iterations past the tolerance while they halve the residual
constexpr int kMaxStepCuts = 40;       // halvings of a Gauss-Newton step that does not reduce the residual
constexpr double kFlat = 1e-3;         // times the mean member length: a scene thinner than it is flat
constexpr double kMaxMove = 0.1;       // times the mean member length: the largest node move of one iteration

/// The spread of the nodes across their flattest direction (m): the root mean square distance from the
/// best-fitting plane.
double thickness(const std::vector<Vec3>& x)
{
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& v : x)
    centroid += v / static_cast<double>(x.size());
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  for (const Vec3& v : x)
    c += (v - centroid) * (v - centroid).transpose() / static_cast<double>(x.size());
  return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(c).eigenvalues()[0]));
}

std::string joinNames(const std::vector<std::string>& names)
{
  std::string out;
  for (size_t i = 0; i < names.size() && i < static_cast<size_t>(kMaxNamed); ++i)
    out += (i ? ", " : "") + quoted(names[i]);
  if (names.size() > static_cast<size_t>(kMaxNamed))
    out += " and " + std::to_string(names.size() - kMaxNamed) + " more";
  return out;
}

double meanMemberLength(const FormTopology& t, const std::vector<Vec3>& x, bool struts_only)
{
  double sum = 0.0;
  int count = 0;
  for (const FormTopology::Member& m : t.members)
  {
    if (struts_only && m.family >= 0)
      continue;
    for (size_t j = 0; j + 1 < m.nodes.size(); ++j, ++count)
      sum += (x[m.nodes[j + 1]] - x[m.nodes[j]]).norm();
  }
  return count ? sum / count : 0.0;
}

double memberLength(const FormTopology::Member& m, const std::vector<Vec3>& x)
{
  double l = 0.0;
  for (size_t j = 0; j + 1 < m.nodes.size(); ++j)
    l += (x[m.nodes[j + 1]] - x[m.nodes[j]]).norm();
  return l;
}

/// The equilibrium matrix (rows: 3 per node in equilibrium, as `rows` gives them; one column per member,
/// the forces a unit tension puts on the nodes).
Eigen::MatrixXd equilibriumMatrix(const FormTopology& t, const std::vector<Vec3>& x, const std::vector<int>& rows,
                                  int n_rows)
{
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n_rows, static_cast<Eigen::Index>(t.members.size()));
  for (size_t e = 0; e < t.members.size(); ++e)
  {
    const std::vector<int>& n = t.members[e].nodes;
    for (size_t j = 0; j + 1 < n.size(); ++j)
    {
      const Vec3 u = (x[n[j + 1]] - x[n[j]]).normalized();
      if (rows[n[j]] >= 0)
        a.block<3, 1>(rows[n[j]], static_cast<Eigen::Index>(e)) += u;
      if (rows[n[j + 1]] >= 0)
        a.block<3, 1>(rows[n[j + 1]], static_cast<Eigen::Index>(e)) -= u;
    }
  }
  return a;
}

std::vector<int> equilibriumRows(const FormTopology& t, bool supports_react, int& n_rows)
{
  std::vector<char> attached(t.node_names.size(), 0);
  for (const FormTopology::Member& m : t.members)
    for (int n : m.nodes)
      attached[n] = 1;
  std::vector<int> rows(t.node_names.size(), -1);
  n_rows = 0;
  for (size_t i = 0; i < rows.size(); ++i)
    if (attached[i] && !(supports_react && t.fixed[i]))
    {
      rows[i] = n_rows;
      n_rows += 3;
    }
  return rows;
}

}  // namespace

FormTopology readFormTopology(const std::string& yaml, const std::string& name)
{
  loadSceneFromString(yaml, name);  // refuses what the loader refuses, with its messages
  const YAML::Node root = YAML::Load(yaml);
  FormTopology t;
  std::map<std::string, int> index;
  for (const auto& kv : root["nodes"])
  {
    const std::string n = kv.first.as<std::string>();
    index[n] = static_cast<int>(t.node_names.size());
    t.node_names.push_back(n);
    const YAML::Node p = kv.second["position"];
    t.positions.emplace_back(p[0].as<double>(), p[1].as<double>(), p[2].as<double>());
    t.fixed.push_back(kv.second["fixed"] && kv.second["fixed"].as<bool>() ? 1 : 0);
  }
  const auto nodesOf = [&](const YAML::Node& list)
  {
    std::vector<int> out;
    for (const auto& n : list)
      out.push_back(index.at(n.as<std::string>()));
    return out;
  };
  if (root["struts"] && root["struts"]["members"])
    for (const auto& kv : root["struts"]["members"])
      t.members.push_back({ kv.first.as<std::string>(), -1, nodesOf(kv.second) });
  for (const char* section : { "cables", "springs" })
  {
    if (!root[section])
      continue;
    for (const auto& fam : root[section])
    {
      FormTopology::Family f;
      f.name = fam.first.as<std::string>();
      f.section = section;
      if (fam.second["prestress"])
        f.prestress = fam.second["prestress"].as<double>();
      const int fi = static_cast<int>(t.families.size());
      for (const auto& kv : fam.second["members"])
      {
        f.members.push_back(static_cast<int>(t.members.size()));
        t.members.push_back({ kv.first.as<std::string>(), fi, nodesOf(kv.second) });
      }
      t.families.push_back(f);
    }
  }
  return t;
}

std::vector<std::string> formChanges(const FormTopology& t, const std::vector<Vec3>& form)
{
  std::vector<std::string> out;
  const std::vector<Vec3>& given = t.positions;
  const double size = meanMemberLength(t, given, false);
  if (!(size > 0.0) || form.size() != given.size())
    return out;
  const double tol = 1e-6 * size;
  const auto number = [&](double v) { return roundedNumber(std::abs(v) < 1e-12 * size ? 0.0 : v, 6); };
  const auto value = [&](double v) { return number(v) + " m"; };
  const auto changed = [&](const std::string& what, double before, double after)
  {
    if (std::abs(after - before) > tol)
      out.push_back(what + ": " + value(before) + " in the scene, " + value(after) + " in the form");
  };
  const auto names = [&](const std::vector<int>& items, bool nodes)
  {
    std::vector<std::string> n;
    for (int i : items)
      n.push_back(nodes ? t.node_names[i] : t.members[i].name);
    std::string text;
    for (size_t i = 0; i < n.size() && i < 3; ++i)
      text += (i ? ", " : "") + quoted(n[i]);
    return n.size() > 3 ? text + " ..." : text;
  };
  // the structure's height
  double lo = std::numeric_limits<double>::infinity(), hi = -lo, lo_f = lo, hi_f = hi;
  for (size_t i = 0; i < given.size(); ++i)
  {
    lo = std::min(lo, given[i].z());
    hi = std::max(hi, given[i].z());
    lo_f = std::min(lo_f, form[i].z());
    hi_f = std::max(hi_f, form[i].z());
  }
  if (hi - lo > tol)
    changed("height (the nodes' z extent)", hi - lo, hi_f - lo_f);
  // levels: at least three nodes at one height in the scene, lowest first
  std::vector<int> order(given.size());
  for (size_t i = 0; i < order.size(); ++i)
    order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return given[a].z() < given[b].z(); });
  std::vector<std::vector<int>> levels;
  std::vector<int> level_of(given.size(), -1);
  for (size_t k = 0; k < order.size();)
  {
    size_t end = k + 1;
    while (end < order.size() && given[order[end]].z() - given[order[k]].z() <= tol)
      ++end;
    if (end - k >= 3)
    {
      for (size_t j = k; j < end; ++j)
        level_of[order[j]] = static_cast<int>(levels.size());
      levels.emplace_back(order.begin() + static_cast<long>(k), order.begin() + static_cast<long>(end));
      std::sort(levels.back().begin(), levels.back().end());  // named in the scene's order
    }
    k = end;
  }
  const auto meanZ = [&](const std::vector<Vec3>& x, int level)
  {
    double z = 0.0;
    for (int i : levels[level])
      z += x[i].z() / static_cast<double>(levels[level].size());
    return z;
  };
  for (size_t l = 0; l < levels.size(); ++l)
  {
    const int li = static_cast<int>(l);
    const std::string level = "level of nodes " + names(levels[l], true) + " (z = " + value(meanZ(given, li)) + ")";
    const auto radius = [&](const std::vector<Vec3>& x)
    {
      Vec3 c = Vec3::Zero();
      for (int i : levels[l])
        c += x[i] / static_cast<double>(levels[l].size());
      double r = 0.0;
      for (int i : levels[l])
        r += (x[i] - c).head<2>().norm() / static_cast<double>(levels[l].size());
      return r;
    };
    changed("radius of the " + level, radius(given), radius(form));
    double zmin = std::numeric_limits<double>::infinity(), zmax = -zmin;
    for (int i : levels[l])
    {
      zmin = std::min(zmin, form[i].z());
      zmax = std::max(zmax, form[i].z());
    }
    if (zmax - zmin > tol)
      out.push_back("flatness of the " + level + ": its nodes at one height in the scene, spread over z " +
                    number(zmin) + " to " + value(zmax) + " in the form");
  }
  // stages: the struts between the same two levels
  std::map<std::pair<int, int>, std::vector<int>> stage_struts;
  for (size_t e = 0; e < t.members.size(); ++e)
  {
    const FormTopology::Member& m = t.members[e];
    if (m.family >= 0 || m.nodes.size() != 2)
      continue;
    const int a = level_of[m.nodes[0]], b = level_of[m.nodes[1]];
    if (a >= 0 && b >= 0 && a != b)
      stage_struts[{ std::min(a, b), std::max(a, b) }].push_back(static_cast<int>(e));
  }
  struct Stage
  {
    int lower, upper;
    std::vector<int> struts;
  };
  std::vector<Stage> stages;
  for (const auto& [levels_of, struts] : stage_struts)
    stages.push_back({ levels_of.first, levels_of.second, struts });
  const auto stageName = [&](const Stage& s)
  {
    return "stage " + names(s.struts, false) + " (z " + number(meanZ(given, s.lower)) + " to " +
           value(meanZ(given, s.upper)) + ")";
  };
  // a stage's twist: the mean turn about z of its struts, from the lower end to the upper one, each end's
  // azimuth taken about the centroid of its level
  const auto twist = [&](const Stage& s, const std::vector<Vec3>& x)
  {
    const auto centroid = [&](int level)
    {
      Vec3 c = Vec3::Zero();
      for (int i : levels[level])
        c += x[i] / static_cast<double>(levels[level].size());
      return c;
    };
    const Vec3 c_lo = centroid(s.lower), c_hi = centroid(s.upper);
    double sum = 0.0;
    for (int e : s.struts)
    {
      const std::vector<int>& n = t.members[e].nodes;
      const bool first_low = level_of[n[0]] == s.lower;
      const Vec3 a = x[first_low ? n[0] : n[1]] - c_lo, b = x[first_low ? n[1] : n[0]] - c_hi;
      sum += std::remainder(std::atan2(b.y(), b.x()) - std::atan2(a.y(), a.x()), 2.0 * M_PI);
    }
    return sum / static_cast<double>(s.struts.size()) * 180.0 / M_PI;
  };
  for (const Stage& s : stages)
  {
    changed("height of " + stageName(s), meanZ(given, s.upper) - meanZ(given, s.lower),
            meanZ(form, s.upper) - meanZ(form, s.lower));
    const double before = twist(s, given), after = twist(s, form);
    if (std::abs(after - before) > 1e-6 * 180.0 / M_PI)
      out.push_back("twist of " + stageName(s) + ": " + roundedNumber(before, 6) + " degrees in the scene, " +
                    roundedNumber(after, 6) + " degrees in the form");
  }
  for (const Stage& a : stages)
    for (const Stage& b : stages)
    {
      // b starts inside a and ends above it (levels are in ascending height)
      if (!(a.lower < b.lower && b.lower < a.upper && a.upper < b.upper))
        continue;
      changed("overlap of " + stageName(a) + " and " + stageName(b), meanZ(given, a.upper) - meanZ(given, b.lower),
              meanZ(form, a.upper) - meanZ(form, b.lower));
    }
  // struts' lengths
  int strut_changes = 0;
  for (const FormTopology::Member& m : t.members)
  {
    if (m.family >= 0)
      continue;
    const double before = memberLength(m, given), after = memberLength(m, form);
    if (std::abs(after - before) <= tol)
      continue;
    if (++strut_changes <= kMaxNamed)
      changed("length of strut " + quoted(m.name), before, after);
  }
  if (strut_changes > kMaxNamed)
    out.push_back("the lengths of " + std::to_string(strut_changes - kMaxNamed) + " more struts");
  return out;
}

FormEquations::FormEquations(const FormTopology& topology, const std::map<int, std::pair<Kind, double>>& held,
                             bool supports_react, bool uniform_struts, double length_weight)
  : topology_(topology), length_weight_(length_weight)
{
  const size_t n = topology_.node_names.size();
  column_.assign(n, -1);
  for (size_t i = 0; i < n; ++i)
    if (!topology_.fixed[i])
    {
      column_[i] = position_columns_;
      position_columns_ += 3;
    }
  row_ = equilibriumRows(topology_, supports_react, rows_);
  int next = position_columns_;
  std::vector<int> family_column(topology_.families.size(), -1);
  for (size_t f = 0; f < topology_.families.size(); ++f)
    if (!held.count(static_cast<int>(f)))
    {
      family_column[f] = next++;
      parameter_names_.push_back("tension " + topology_.families[f].name);
    }
  int struts_column = -1;
  for (const FormTopology::Member& m : topology_.members)
  {
    if (m.family < 0)
    {
      kind_.push_back(Kind::kDensity);
      held_value_.push_back(0.0);
      if (uniform_struts && struts_column >= 0)
      {
        parameter_.push_back(struts_column);
        continue;
      }
      struts_column = next;
      parameter_.push_back(next++);
      parameter_names_.push_back(uniform_struts ? std::string("struts") : "strut " + m.name);
    }
    else if (const auto it = held.find(m.family); it != held.end())
    {
      kind_.push_back(it->second.first);
      parameter_.push_back(-1);
      held_value_.push_back(it->second.second);
    }
    else
    {
      kind_.push_back(Kind::kTension);
      parameter_.push_back(family_column[m.family]);
      held_value_.push_back(0.0);
    }
  }
  if (length_weight_ > 0.0)
    for (size_t e = 0; e < topology_.members.size(); ++e)
      if (topology_.members[e].family < 0)
      {
        kept_struts_.push_back(static_cast<int>(e));
        kept_lengths_.push_back(memberLength(topology_.members[e], topology_.positions));
      }
}

int FormEquations::unknowns() const
{
  return position_columns_ + static_cast<int>(parameter_names_.size());
}

int FormEquations::equations() const
{
  return rows_ + static_cast<int>(kept_struts_.size());
}

Eigen::VectorXd FormEquations::pack(const std::vector<Vec3>& positions, const Eigen::VectorXd& parameters) const
{
  Eigen::VectorXd z(unknowns());
  for (size_t i = 0; i < column_.size(); ++i)
    if (column_[i] >= 0)
      z.segment<3>(column_[i]) = positions[i];
  z.tail(parameters.size()) = parameters;
  return z;
}

std::vector<Vec3> FormEquations::positions(const Eigen::VectorXd& z) const
{
  std::vector<Vec3> x = topology_.positions;
  for (size_t i = 0; i < column_.size(); ++i)
    if (column_[i] >= 0)
      x[i] = z.segment<3>(column_[i]);
  return x;
}

Eigen::VectorXd FormEquations::tensions(const Eigen::VectorXd& z) const
{
  const std::vector<Vec3> x = positions(z);
  Eigen::VectorXd t(static_cast<Eigen::Index>(topology_.members.size()));
  for (size_t e = 0; e < topology_.members.size(); ++e)
  {
    const double p = parameter_[e] >= 0 ? z[parameter_[e]] : held_value_[e];
    t[static_cast<Eigen::Index>(e)] = kind_[e] == Kind::kDensity ? p * memberLength(topology_.members[e], x) : p;
  }
  return t;
}

Eigen::VectorXd FormEquations::residual(const Eigen::VectorXd& z) const
{
  const std::vector<Vec3> x = positions(z);
  const Eigen::VectorXd t = tensions(z);
  Eigen::VectorXd r = Eigen::VectorXd::Zero(equations());
  for (size_t e = 0; e < topology_.members.size(); ++e)
  {
    const std::vector<int>& n = topology_.members[e].nodes;
    for (size_t j = 0; j + 1 < n.size(); ++j)
    {
      const Vec3 f = t[static_cast<Eigen::Index>(e)] * (x[n[j + 1]] - x[n[j]]).normalized();
      if (row_[n[j]] >= 0)
        r.segment<3>(row_[n[j]]) += f;
      if (row_[n[j + 1]] >= 0)
        r.segment<3>(row_[n[j + 1]]) -= f;
    }
  }
  for (size_t k = 0; k < kept_struts_.size(); ++k)
    r[rows_ + static_cast<Eigen::Index>(k)] =
        length_weight_ * (memberLength(topology_.members[kept_struts_[k]], x) - kept_lengths_[k]);
  return r;
}

Eigen::MatrixXd FormEquations::jacobian(const Eigen::VectorXd& z) const
{
  const std::vector<Vec3> x = positions(z);
  const Eigen::VectorXd t = tensions(z);
  Eigen::MatrixXd jac = Eigen::MatrixXd::Zero(equations(), unknowns());
  // adds s * block to the rows of `row_node` and the columns of `col_node` (when both are unknown/equations)
  const auto add = [&](int row_node, int col_node, const Eigen::Matrix3d& block)
  {
    if (row_[row_node] >= 0 && column_[col_node] >= 0)
      jac.block<3, 3>(row_[row_node], column_[col_node]) += block;
  };
  for (size_t e = 0; e < topology_.members.size(); ++e)
  {
    const std::vector<int>& n = topology_.members[e].nodes;
    const size_t segments = n.size() - 1;
    std::vector<Vec3> u(segments);
    std::vector<double> l(segments);
    for (size_t j = 0; j < segments; ++j)
    {
      const Vec3 d = x[n[j + 1]] - x[n[j]];
      l[j] = d.norm();
      u[j] = d / l[j];
    }
    const double te = t[static_cast<Eigen::Index>(e)];
    const double p = parameter_[e] >= 0 ? z[parameter_[e]] : held_value_[e];
    const bool density = kind_[e] == Kind::kDensity;
    const double dt_dp = density ? memberLength(topology_.members[e], x) : 1.0;
    for (size_t j = 0; j < segments; ++j)
    {
      // the force T u_j acts on n[j] (sign +1) and n[j + 1] (sign -1)
      const Eigen::Matrix3d du = (Eigen::Matrix3d::Identity() - u[j] * u[j].transpose()) / l[j];
      for (const auto& [node, sign] : { std::pair<int, double>{ n[j], 1.0 }, std::pair<int, double>{ n[j + 1], -1.0 } })
      {
        add(node, n[j + 1], sign * te * du);
        add(node, n[j], -sign * te * du);
        if (density)  // T = p L: dT/dx along every segment of the member
          for (size_t k = 0; k < segments; ++k)
          {
            const Eigen::Matrix3d b = sign * p * u[j] * u[k].transpose();
            add(node, n[k + 1], b);
            add(node, n[k], -b);
          }
        if (parameter_[e] >= 0 && row_[node] >= 0)
          jac.block<3, 1>(row_[node], parameter_[e]) += sign * dt_dp * u[j];
      }
    }
  }
  for (size_t k = 0; k < kept_struts_.size(); ++k)
  {
    const std::vector<int>& n = topology_.members[kept_struts_[k]].nodes;
    const Eigen::Index row = rows_ + static_cast<Eigen::Index>(k);
    for (size_t j = 0; j + 1 < n.size(); ++j)
    {
      const Vec3 u = (x[n[j + 1]] - x[n[j]]).normalized();
      if (column_[n[j + 1]] >= 0)
        jac.block<1, 3>(row, column_[n[j + 1]]) += length_weight_ * u.transpose();
      if (column_[n[j]] >= 0)
        jac.block<1, 3>(row, column_[n[j]]) -= length_weight_ * u.transpose();
    }
  }
  return jac;
}

namespace
{
using Held = std::map<int, std::pair<FormEquations::Kind, double>>;

int familyIndex(const FormTopology& t, const std::string& name, const std::string& option)
{
  for (size_t f = 0; f < t.families.size(); ++f)
    if (t.families[f].name == name)
      return static_cast<int>(f);
  std::vector<std::string> names;
  for (const FormTopology::Family& f : t.families)
    names.push_back(f.name);
  throw FormFindingError(option + ": no cable or spring family " + quoted(name) + " in the scene" +
                         (names.empty() ? std::string(" (it has none)") : " (its families: " + joinNames(names) + ")"));
}

Held heldFamilies(const FormTopology& t, const FormFindingOptions& o)
{
  Held held;
  for (const auto& [name, value] : o.tension)
  {
    if (!(std::isfinite(value) && value > 0.0))
      throw FormFindingError("--prestress " + name + ": the tension must be positive and finite, got " +
                             shortestNumber(value));
    held[familyIndex(t, name, "--prestress " + name)] = { FormEquations::Kind::kTension, value };
  }
  for (const auto& [name, value] : o.force_density)
  {
    if (o.mode == FormFindingMode::kPrestress)
      throw FormFindingError("--force-density " + name +
                             ": prestress mode keeps the geometry; it takes tensions "
                             "(--prestress FAMILY=T), not force densities");
    if (!(std::isfinite(value) && value > 0.0))
      throw FormFindingError("--force-density " + name + ": the force density must be positive and finite, got " +
                             shortestNumber(value));
    const int f = familyIndex(t, name, "--force-density " + name);
    if (held.count(f))
      throw FormFindingError("--force-density " + name + ": the family's tension is held already (--prestress " + name +
                             ")");
    held[f] = { FormEquations::Kind::kDensity, value };
  }
  return held;
}

/// Gauss-Newton with minimum-norm steps on the equations; returns the iterations taken. Once the residual is
/// within the tolerance the iterations go on while each still halves it (at most kPolishIterations): along a
/// mechanism of the form the residual is second order in the distance from it, so a residual at the
/// tolerance leaves the geometry only to about its square root, and Newton converges there linearly.
int solveForm(const FormEquations& eq, Eigen::VectorXd& z, const Eigen::VectorXd& column_scale, double force_scale,
              double length, const FormFindingOptions& o, double& residual)
{
  const Eigen::Index n_positions = z.size() - static_cast<Eigen::Index>(eq.parameterNames().size());
  Eigen::VectorXd r = eq.residual(z);
  const auto largestForce = [&](const Eigen::VectorXd& v)
  {
    double m = 0.0;
    for (Eigen::Index i = 0; i + 2 < eq.forceRows(); i += 3)
      m = std::max(m, v.segment<3>(i).norm());
    for (Eigen::Index i = eq.forceRows(); i < v.size(); ++i)
      m = std::max(m, std::abs(v[i]));
    return m;
  };
  int polish = 0;
  double previous = std::numeric_limits<double>::infinity();
  for (int it = 0;; ++it)
  {
    const double largest = std::max(force_scale, eq.tensions(z).cwiseAbs().maxCoeff());
    residual = largestForce(r);
    if (!std::isfinite(residual))
      throw FormFindingError("form-finding diverged (a non-finite force after " + std::to_string(it) +
                             " iterations): start nearer a form, or hold more families" + kOtherWays);
    const bool converged = residual <= o.tolerance * largest;
    if (converged && (polish == kPolishIterations || !(residual < 0.5 * previous)))
      return it;
    if (converged)
      ++polish;
    else if (it >= o.max_iterations)
      throw FormFindingError("form-finding did not converge in " + std::to_string(o.max_iterations) +
                             " iterations: force residual " + roundedNumber(residual, 3) + " N (tolerance " +
                             roundedNumber(o.tolerance * largest, 3) + " N)" + kOtherWays);
    previous = residual;
    const Eigen::MatrixXd j = eq.jacobian(z) * column_scale.asDiagonal() / force_scale;
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
    cod.setThreshold(kStepRankTolerance);
    cod.compute(j);
    const Eigen::VectorXd step = column_scale.cwiseProduct(cod.solve(-r / force_scale));
    // a trust region on the nodes: no node moves by more than kMaxMove of the mean member length in one
    // iteration, so the iterations follow the given geometry to the nearest form instead of jumping to a
    // distant (often flat) one
    double largest_move = 0.0;
    for (Eigen::Index i = 0; i + 2 < n_positions; i += 3)
      largest_move = std::max(largest_move, step.segment<3>(i).norm());
    double alpha = largest_move > kMaxMove * length ? kMaxMove * length / largest_move : 1.0;
    const double norm = r.norm();
    for (int cut = 0;; ++cut, alpha *= 0.5)
    {
      const Eigen::VectorXd trial = z + alpha * step;
      const Eigen::VectorXd rt = eq.residual(trial);
      if (rt.allFinite() && rt.norm() < norm)
      {
        z = trial;
        r = rt;
        break;
      }
      if (converged)  // round-off: nothing left to gain
        return it;
      if (cut == kMaxStepCuts)
        throw FormFindingError("form-finding stalled at a force residual of " + roundedNumber(residual, 3) +
                               " N after " + std::to_string(it) +
                               " iterations (no step reduces it): start nearer a form, or hold other families" +
                               kOtherWays);
    }
  }
}

/// The states of self-stress of a geometry (columns, member tensions), fitted to the held tensions.
Eigen::VectorXd fitSelfStress(const FormTopology& t, const Held& held, bool supports_react, int& states)
{
  int n_rows = 0;
  const std::vector<int> rows = equilibriumRows(t, supports_react, n_rows);
  const Eigen::MatrixXd a = equilibriumMatrix(t, t.positions, rows, n_rows);
  const Eigen::Index m = a.cols();
  const Svd d = svd(a, Eigen::ComputeFullV);
  const Eigen::VectorXd& sv = d.singular;
  const double largest = sv.size() ? sv[0] : 0.0;
  Eigen::Index rank = 0;
  while (rank < sv.size() && sv[rank] > kRankTolerance * largest)
    ++rank;
  states = static_cast<int>(m - rank);
  if (states == 0)
    throw FormFindingError("the geometry has no state of self-stress (" + std::to_string(m) + " members, rank " +
                           std::to_string(rank) +
                           " of the equilibrium matrix): it is no tensegrity form; find one with --mode free");
  const Eigen::MatrixXd s = d.v.rightCols(states);
  std::vector<Eigen::Index> target_rows;
  std::vector<double> targets;
  for (const auto& [f, kv] : held)
    for (int e : t.families[f].members)
    {
      target_rows.push_back(e);
      targets.push_back(kv.second);
    }
  Eigen::MatrixXd fit(static_cast<Eigen::Index>(target_rows.size()), states);
  for (size_t i = 0; i < target_rows.size(); ++i)
    fit.row(static_cast<Eigen::Index>(i)) = s.row(target_rows[i]);
  const Eigen::VectorXd want =
      Eigen::Map<const Eigen::VectorXd>(targets.data(), static_cast<Eigen::Index>(targets.size()));
  const Eigen::VectorXd c = fit.completeOrthogonalDecomposition().solve(want);
  const Eigen::VectorXd tension = s * c;
  for (const auto& [f, kv] : held)
  {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int e : t.families[f].members)
    {
      lo = std::min(lo, tension[e]);
      hi = std::max(hi, tension[e]);
    }
    if (std::max(std::abs(lo - kv.second), std::abs(hi - kv.second)) > kTargetFit * kv.second)
      throw FormFindingError("--prestress " + t.families[f].name + "=" + shortestNumber(kv.second) +
                             ": no state of self-stress of this geometry gives every member of the family that "
                             "tension together with the other targets (the nearest gives " +
                             roundedNumber(lo, 6) + " to " + roundedNumber(hi, 6) + " N; " + std::to_string(states) +
                             " states of self-stress)");
  }
  return tension;
}

/// The members of a family grouped by equal tension (relative kSameTension), in the family's order.
std::vector<std::vector<int>> equalTensionGroups(const FormTopology::Family& f, const Eigen::VectorXd& tension)
{
  double largest = 0.0;
  for (int e : f.members)
    largest = std::max(largest, std::abs(tension[e]));
  std::vector<std::vector<int>> groups;
  for (int e : f.members)
  {
    bool placed = false;
    for (std::vector<int>& g : groups)
      if (std::abs(tension[g.front()] - tension[e]) <= kSameTension * largest)
      {
        g.push_back(e);
        placed = true;
        break;
      }
    if (!placed)
      groups.push_back({ e });
  }
  return groups;
}

std::string writeScene(const std::string& yaml, const FormTopology& t, const std::vector<Vec3>& x,
                       const Eigen::VectorXd& tension, const std::string& header, std::vector<std::string>& notes)
{
  YAML::Node root = YAML::Load(yaml);
  for (size_t i = 0; i < t.node_names.size(); ++i)
  {
    YAML::Node p(YAML::NodeType::Sequence);
    for (int k = 0; k < 3; ++k)
      p.push_back(shortestNumber(x[i][k] == 0.0 ? 0.0 : x[i][k]));
    p.SetStyle(YAML::EmitterStyle::Flow);
    root["nodes"][t.node_names[i]]["position"] = p;
  }
  std::set<std::string> used;
  for (const FormTopology::Family& f : t.families)
    used.insert(f.name);
  for (const FormTopology::Family& f : t.families)
  {
    YAML::Node section = root[f.section];
    const YAML::Node original = YAML::Clone(section[f.name]);
    const std::vector<std::vector<int>> groups = equalTensionGroups(f, tension);
    for (size_t g = 0; g < groups.size(); ++g)
    {
      YAML::Node fam = g == 0 ? section[f.name] : YAML::Clone(original);
      double sum = 0.0;
      YAML::Node members(YAML::NodeType::Map);
      for (int e : groups[g])
      {
        sum += tension[e];
        members[t.members[e].name] = YAML::Clone(original["members"][t.members[e].name]);
      }
      fam.remove("rest_length");
      fam["prestress"] = shortestNumber(sum / static_cast<double>(groups[g].size()));
      fam["members"] = members;
      if (g > 0)
      {
        std::string name;
        for (size_t k = g + 1; name.empty() || used.count(name); ++k)
          name = f.name + "_" + std::to_string(k);
        used.insert(name);
        section[name] = fam;
      }
    }
    if (groups.size() > 1)
      notes.push_back(f.section + "." + f.name + ": its members carry " + std::to_string(groups.size()) +
                      " different tensions; the written scene splits it into families of equal prestress (" +
                      quoted(f.name) + " and its suffixed copies)");
  }
  YAML::Emitter out;
  out << root;
  return header + out.c_str() + "\n";
}

FormCheck checkWritten(const std::string& scene, const std::string& name, bool supported)
{
  FormCheck c;
  const Model model = loadSceneFromString(scene, name);
  const State start = initialState(model);
  try
  {
    const StructureReport report = checkStructure(model, start);
    c.checked = report.checked;
    c.equilibrium_residual = report.equilibrium_residual;
    c.prestress_stable = report.prestress_stable;
    c.self_stress_states = report.self_stress_states;
    c.mechanisms = report.mechanisms;
    c.slack_cables = report.slack_cables;
  }
  catch (const std::invalid_argument&)
  {
    c.checked = false;
  }
  for (const ContactPairState& p : activeContacts(model, start))
  {
    c.overlapping.push_back(contactBodyName(model, p.body_a) + "-" + contactBodyName(model, p.body_b) + " (gap " +
                            roundedNumber(p.gap, 3) + " m)");
  }
  if (supported)  // a static solve needs a support
  {
    State state = start;
    StaticSolver solver(model, model.solver);
    c.newton_converged = solver.solve(state, start.u).ok();
    for (const Node& n : model.nodes)
      c.newton_move = std::max(
          c.newton_move, (pointPosition(model, n.point, state.q) - pointPosition(model, n.point, start.q)).norm());
  }
  return c;
}

}  // namespace

FormFindingResult findForm(const std::string& yaml, const std::string& name, const FormFindingOptions& o)
{
  const FormTopology t = readFormTopology(yaml, name);
  if (t.families.empty())
    throw FormFindingError(name + ": the scene has no cable or spring: there is no prestress to find a form for");
  Held held = heldFamilies(t, o);
  FormFindingResult result;
  result.node_names = t.node_names;
  std::vector<Vec3> x = t.positions;
  Eigen::VectorXd tension;
  std::string how;
  if (o.mode == FormFindingMode::kPrestress)
  {
    if (held.empty())
      throw FormFindingError("prestress mode needs a target tension for at least one family: --prestress FAMILY=T");
    if (o.keep_strut_lengths)
      throw FormFindingError("--strut-lengths keep: prestress mode keeps the whole geometry; the option is for "
                             "--mode free");
    tension = fitSelfStress(t, held, o.supports_react, result.self_stress_states);
    how = "prestress design at the given geometry";
  }
  else
  {
    if (held.empty())
    {
      for (size_t f = 0; f < t.families.size() && held.empty(); ++f)
        if (t.families[f].prestress > 0.0)
        {
          held[static_cast<int>(f)] = { FormEquations::Kind::kTension, t.families[f].prestress };
          result.notes.push_back("the tension of " + t.families[f].section + "." + t.families[f].name +
                                 " is held at the scene's prestress " + shortestNumber(t.families[f].prestress) +
                                 " N (no --prestress or --force-density given)");
        }
      if (held.empty())
        throw FormFindingError("nothing sets the level of the prestress: hold a family with --prestress FAMILY=T or "
                               "--force-density FAMILY=q (no family of the scene gives a prestress)");
    }
    const double length = meanMemberLength(t, x, false);
    double force = 0.0;
    for (const auto& [f, kv] : held)
      force = std::max(force, kv.first == FormEquations::Kind::kTension ? kv.second : kv.second * length);
    const FormEquations eq(t, held, o.supports_react, o.uniform_struts, o.keep_strut_lengths ? force / length : 0.0);
    // the free parameters from linear least squares at the given positions (the equations are linear in them)
    const int n_params = static_cast<int>(eq.parameterNames().size());
    Eigen::VectorXd z = eq.pack(x, Eigen::VectorXd::Zero(n_params));
    const Eigen::MatrixXd jp = eq.jacobian(z).rightCols(n_params);
    Eigen::VectorXd p = jp.completeOrthogonalDecomposition().solve(-eq.residual(z));
    for (int k = 0; k < n_params; ++k)  // a start on the wrong side: cables pull, struts push
    {
      const bool strut = eq.parameterNames()[k].rfind("strut", 0) == 0;
      if (strut && !(p[k] < 0.0))
        p[k] = -force / length;
      if (!strut && !(p[k] > 0.0))
        p[k] = force;
    }
    z = eq.pack(x, p);
    Eigen::VectorXd scale(eq.unknowns());
    scale.head(eq.unknowns() - n_params).setConstant(length);
    for (int k = 0; k < n_params; ++k)
      scale[eq.unknowns() - n_params + k] = std::max(std::abs(p[k]), 1e-6 * force);
    result.iterations = solveForm(eq, z, scale, force, length, o, result.residual);
    x = eq.positions(z);
    tension = eq.tensions(z);
    const double mean_length = meanMemberLength(t, x, false);
    for (size_t e = 0; e < t.members.size(); ++e)
      for (size_t j = 0; j + 1 < t.members[e].nodes.size(); ++j)
        if ((x[t.members[e].nodes[j + 1]] - x[t.members[e].nodes[j]]).norm() < kCollapsedLength * mean_length)
          throw FormFindingError("the form found collapses member " + quoted(t.members[e].name) +
                                 " to zero length: start nearer a form, or hold other families" + kOtherWays);
    if (thickness(t.positions) > kFlat * length && thickness(x) < kCollapsedLength * mean_length)
      throw FormFindingError(std::string("the form found is flat (every node in one plane) though the scene is not: "
                                         "keep the strut lengths (--strut-lengths keep), start nearer a form, or "
                                         "hold other families") +
                             kOtherWays);
    // a free-standing form whose equations are homogeneous in scale keeps the given mean strut length
    bool any_fixed = false, tensions_held = false, densities_held = false;
    for (char f : t.fixed)
      any_fixed = any_fixed || f;
    for (const auto& [f, kv] : held)
      (kv.first == FormEquations::Kind::kTension ? tensions_held : densities_held) = true;
    const double strut_length = meanMemberLength(t, t.positions, true);
    const double found_length = meanMemberLength(t, x, true);
    if (!any_fixed && !o.keep_strut_lengths && !(tensions_held && densities_held) && strut_length > 0.0 &&
        found_length > 0.0)
    {
      result.scale = strut_length / found_length;
      Vec3 centroid = Vec3::Zero();
      for (const Vec3& v : x)
        centroid += v / static_cast<double>(x.size());
      for (Vec3& v : x)
        v = centroid + result.scale * (v - centroid);
      if (densities_held)
        tension *= result.scale;
      if (std::abs(result.scale - 1.0) > 1e-12)
        result.notes.push_back("the free-standing form is scaled by " + roundedNumber(result.scale, 9) +
                               " about its centroid to keep the mean strut length " + roundedNumber(strut_length, 9) +
                               " m");
    }
    how = "free form-finding";
  }
  // cables pull; a strut that pulls is possible (a rigid strut carries tension) but worth a word
  const double largest = tension.cwiseAbs().maxCoeff();
  std::vector<std::string> slack, pulling;
  for (size_t e = 0; e < t.members.size(); ++e)
  {
    if (t.members[e].family >= 0 && tension[static_cast<Eigen::Index>(e)] <= kSlackTension * largest)
      slack.push_back(t.members[e].name);
    if (t.members[e].family < 0 && tension[static_cast<Eigen::Index>(e)] > kSlackTension * largest)
      pulling.push_back(t.members[e].name);
  }
  if (!slack.empty())
    throw FormFindingError("the form found leaves " + std::to_string(slack.size()) + " cable" +
                           (slack.size() > 1 ? "s" : "") + " slack or in compression (" + joinNames(slack) +
                           "): hold their families' tensions (--prestress FAMILY=T) or start nearer a tensegrity form");
  if (!pulling.empty())
    result.notes.push_back("struts in tension in the form: " + joinNames(pulling));
  for (size_t e = 0; e < t.members.size(); ++e)
  {
    const FormTopology::Member& m = t.members[e];
    result.members.push_back({ m.name, m.family < 0 ? std::string("struts") : t.families[m.family].name, m.family < 0,
                               tension[static_cast<Eigen::Index>(e)], memberLength(m, x) });
  }
  result.positions = x;
  for (size_t i = 0; i < x.size(); ++i)
    result.max_move = std::max(result.max_move, (x[i] - t.positions[i]).norm());
  if (o.mode == FormFindingMode::kPrestress)  // the residual of the fitted self-stress at the given geometry
  {
    int n_rows = 0;
    const std::vector<int> rows = equilibriumRows(t, o.supports_react, n_rows);
    const Eigen::VectorXd r = equilibriumMatrix(t, x, rows, n_rows) * tension;
    for (Eigen::Index i = 0; i + 2 < r.size(); i += 3)
      result.residual = std::max(result.residual, r.segment<3>(i).norm());
  }
  bool loaded = false;
  {
    const YAML::Node root = YAML::Load(yaml);
    loaded = (root["loads"] && root["loads"].size() > 0) ||
             (root["gravity"] && root["gravity"]["enabled"] && root["gravity"]["enabled"].as<bool>());
  }
  if (loaded)
    result.notes.push_back("the form is self-equilibrated: the scene's loads and gravity are not part of it, and "
                           "its start is not in equilibrium under them");
  result.changes = formChanges(t, x);
  const std::string header = "# " + how + " (tensegrity_formfind) of " + clipped(name) + "\n";
  result.scene = writeScene(yaml, t, x, tension, header, result.notes);
  result.check = checkWritten(result.scene, name, std::find(t.fixed.begin(), t.fixed.end(), char(1)) != t.fixed.end());
  if (!result.check.overlapping.empty())
    result.notes.push_back(
        "struts overlap in the form (form-finding takes no account of their thickness): " +
        joinNames(result.check.overlapping) +
        "; the scene starts with them in contact: start from another geometry, or check fewer pairs");
  return result;
}

}  // namespace active_tensegrity::design
