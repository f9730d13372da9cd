#include "active_tensegrity/core/scene/scene.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include <sys/stat.h>

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::core
{
namespace
{
// bounds of the integer keys and of the work a scene may ask for
constexpr int kMaxNewtonIterations = 1000;
constexpr int kMaxStepCuts = 60;  // halvings: 2^-60 of a step is far below any dt_min
constexpr int kMaxJacobianAge = 1000000;
constexpr int kMaxLoadSteps = 10000000;
constexpr double kMaxTimeSteps = 1e8;    // duration / dt (fixed steps), duration / output_interval
constexpr double kMaxOutputSteps = 1e8;  // output rows of a dynamic run
// bounds of the tolerances (m): beyond them a run converges to whatever it starts from
constexpr double kMaxNewtonTolerance = 1e-3;
constexpr double kMaxErrorTolerance = 1e-2;
constexpr double kMaxOnsetDepth = 1e-2;
// bounds of the materials: far beyond any solid, and they keep every derived stiffness and mass finite
constexpr double kMaxYoungsModulus = 1e14;  // Pa (diamond: 1.2e12)
constexpr double kMaxDensity = 1e5;         // kg/m^3 (osmium: 22590)
constexpr double kMaxFriction = 10.0;

std::string show(const YAML::Node& n)
{
  if (!n.IsDefined() || n.IsNull())
    return "null";
  if (n.IsScalar())
    return quoted(n.Scalar());
  YAML::Emitter e;
  e << YAML::Flow << n;
  return clipped(e.c_str());
}

std::string showVec3(const Vec3& v)
{
  return "[" + shortestNumber(v.x()) + ", " + shortestNumber(v.y()) + ", " + shortestNumber(v.z()) + "]";
}

/// Where a scene's text came from: the file, and the command-line overrides applied on top of it. A
/// key an override set (or a key under it, or one it created on its way) is blamed on that override.
struct Source
{
  std::string file;
  std::vector<Override> overrides;

  std::string blame(const std::string& key) const
  {
    const auto under = [](const std::string& a, const std::string& b)
    { return a.size() > b.size() && a.compare(0, b.size(), b) == 0 && a[b.size()] == '.'; };
    for (auto o = overrides.rbegin(); o != overrides.rend(); ++o)
      if (!key.empty() && (o->key == key || under(key, o->key) || under(o->key, key)))
        return "--set " + clipped(o->key + "=" + o->value) + " (on " + file + ")";
    return file;
  }
  [[noreturn]] void fail(const std::string& key, const std::string& what) const
  {
    throw SceneError(blame(key), key, what);
  }
};

/// A YAML map read under a dotted path; remembers which keys were used so that unknown ones
/// (typos) are refused. Keys are indexed once, so a lookup does not scan the map.
class Reader
{
public:
  Reader(const YAML::Node& node, std::string path, const Source& source)
    : node_(node), path_(std::move(path)), source_(&source)
  {
    if (!node_.IsMap())
      fail(path_, "expected a map, got " + show(node_));
    for (const auto& kv : node_)
    {
      if (!kv.first.IsScalar())
        fail(path_, "expected names as keys, got the key " + show(kv.first) + " on line " +
                        std::to_string(kv.first.Mark().line + 1));
      const std::string& k = kv.first.Scalar();
      if (index_.emplace(k, kv.second).second)
        order_.push_back(k);
    }
  }

  [[noreturn]] void fail(const std::string& key, const std::string& what) const
  {
    source_->fail(key, what);
  }
  /// The dotted path of key k, k cut like any echoed text (a key can be a whole multi-line scalar).
  std::string key(const std::string& k) const
  {
    return path_.empty() ? clipped(k) : path_ + "." + clipped(k);
  }

  bool has(const std::string& k) const
  {
    const auto it = index_.find(k);
    return it != index_.end() && !it->second.IsNull();
  }
  /// Marks an optional key as known (so an explicit null there is accepted).
  void optional(const std::string& k)
  {
    used_.insert(k);
  }

  YAML::Node raw(const std::string& k)
  {
    used_.insert(k);
    if (!has(k))
    {
      // a key of this map that nothing has read yet and that is one typo away from k: named as the cause
      std::vector<std::string> unread;
      for (const std::string& other : order_)
        if (!used_.count(other))
          unread.push_back(other);
      std::vector<std::string> wanted{ k };
      for (const std::string& other : unread)
        if (nearestMatch(other, wanted) == k)
          fail(key(other), "unknown key (misspelt, or not valid here): did you mean " + quoted(k) +
                               "? (the required key " + key(k) + " is missing)");
      fail(key(k), "missing required key");
    }
    return index_.at(k);
  }
  YAML::Node get(const std::string& k) const
  {
    const auto it = index_.find(k);
    return it == index_.end() ? YAML::Node() : it->second;
  }

  double number(const std::string& k)
  {
    return toNumber(raw(k), key(k));
  }
  double number(const std::string& k, double fallback)
  {
    used_.insert(k);
    return has(k) ? number(k) : fallback;
  }
  double positive(const std::string& k)
  {
    const double v = number(k);
    if (!(v > 0.0))
      fail(key(k), "must be positive, got " + show(get(k)));
    return v;
  }
  double positive(const std::string& k, double fallback)
  {
    return has(k) ? positive(k) : (used_.insert(k), fallback);
  }
  /// A positive number of at most `max_value` (a tolerance: a larger one accepts nonsense), in `unit`.
  double bounded(const std::string& k, double fallback, double max_value, const std::string& unit)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const double v = number(k);
    if (!(v > 0.0 && v <= max_value))
      fail(key(k), "must be positive and at most " + shortestNumber(max_value) + " " + unit + " (the range (0, " +
                       shortestNumber(max_value) + "] " + unit + "), got " + show(get(k)));
    return v;
  }
  double nonNegative(const std::string& k, double fallback)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const double v = number(k);
    if (v < 0.0)
      fail(key(k), "must not be negative, got " + show(get(k)));
    return v;
  }
  int integer(const std::string& k, int fallback, int min_value, int max_value)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const YAML::Node n = get(k);
    const double d = toNumber(n, key(k));
    if (d != std::floor(d))
      fail(key(k), "expected an integer, got " + show(n));
    if (d < min_value)
      fail(key(k), "must be at least " + std::to_string(min_value) + ", got " + show(n));
    if (d > max_value)
      fail(key(k), "must be at most " + std::to_string(max_value) + ", got " + show(n));
    return static_cast<int>(d);
  }
  bool boolean(const std::string& k, bool fallback)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const YAML::Node n = get(k);
    try
    {
      if (n.IsScalar())
        return n.as<bool>();
    }
    catch (const YAML::Exception&)
    {
    }
    fail(key(k), "expected true or false, got " + show(n));
  }
  std::string string(const std::string& k)
  {
    const YAML::Node n = raw(k);
    if (!n.IsScalar() || n.Scalar().empty())
      fail(key(k), "expected a non-empty string, got " + show(n));
    return n.Scalar();
  }
  std::string string(const std::string& k, const std::string& fallback)
  {
    used_.insert(k);
    return has(k) ? string(k) : fallback;
  }
  Vec3 vec3(const std::string& k)
  {
    return toVec3(raw(k), key(k));
  }
  Vec3 vec3(const std::string& k, const Vec3& fallback)
  {
    return has(k) ? vec3(k) : (used_.insert(k), fallback);
  }
  std::vector<std::string> names(const std::string& k)
  {
    const YAML::Node n = raw(k);
    if (!n.IsSequence())
      fail(key(k), "expected a list of names, got " + show(n));
    std::vector<std::string> out;
    for (size_t i = 0; i < n.size(); ++i)
    {
      if (!n[i].IsScalar() || n[i].Scalar().empty())
        fail(key(k), "expected a list of names, got " + show(n));
      out.push_back(n[i].Scalar());
    }
    return out;
  }
  /// A list of names none of which may repeat (an actuator's cables or nodes, output node lists).
  std::vector<std::string> uniqueNames(const std::string& k)
  {
    std::vector<std::string> out = names(k);
    std::set<std::string> seen;
    for (const std::string& n : out)
      if (!seen.insert(n).second)
        fail(key(k), "lists " + quoted(n) + " twice");
    return out;
  }
  Reader map(const std::string& k)
  {
    return Reader(raw(k), key(k), *source_);
  }

  /// Keys of this map in file order.
  const std::vector<std::string>& keys() const
  {
    return order_;
  }

  void finish() const
  {
    for (const std::string& k : order_)
      if (!used_.count(k))
      {
        const std::string near = nearestMatch(k, std::vector<std::string>(used_.begin(), used_.end()));
        fail(key(k), "unknown key (misspelt, or not valid here)" +
                         (near.empty() ? std::string() : ": did you mean " + quoted(near) + "?"));
      }
  }

  double toNumber(const YAML::Node& n, const std::string& full_key) const
  {
    double v = 0.0;
    bool ok = n.IsScalar();
    if (ok)
    {
      try
      {
        v = n.as<double>();
      }
      catch (const YAML::Exception&)
      {
        ok = false;
      }
    }
    if (!ok)
      fail(full_key, "expected a number, got " + show(n));
    if (!std::isfinite(v))
      fail(full_key, "must be a finite number, got " + show(n));
    return v;
  }

  Vec3 toVec3(const YAML::Node& n, const std::string& full_key) const
  {
    if (!n.IsSequence() || n.size() != 3)
      fail(full_key, "expected a list of three numbers [x, y, z], got " + show(n));
    return Vec3(toNumber(n[0], full_key), toNumber(n[1], full_key), toNumber(n[2], full_key));
  }

private:
  YAML::Node node_;
  std::string path_;
  const Source* source_;
  std::unordered_map<std::string, YAML::Node> index_;
  std::vector<std::string> order_;
  std::set<std::string> used_;
};

/// Where a YAML mark is, for a message: "line N" in a scene file; "column N" (of line L when the text has
/// several) in an override's value.
std::string markText(const YAML::Mark& mark, bool in_value)
{
  if (!in_value)
    return "line " + std::to_string(mark.line + 1);
  return "column " + std::to_string(mark.column + 1) +
         (mark.line > 0 ? " of line " + std::to_string(mark.line + 1) : std::string());
}

/// Refuses a key that appears twice in one map, anywhere in the tree, with both places (yaml-cpp keeps
/// both and reads the first). Nodes reached twice through YAML aliases are checked once. `path` is the
/// dotted key of `n`; `in_value`: the tree is an override's value (its places are columns of the value).
void refuseRepeatedKeys(const YAML::Node& n, const std::string& path, const std::string& file,
                        std::unordered_set<int>& seen, bool in_value = false)
{
  const int pos = n.Mark().pos;
  if (pos >= 0 && !seen.insert(pos).second)
    return;
  if (n.IsMap())
  {
    std::unordered_map<std::string, YAML::Mark> marks;
    for (const auto& kv : n)
    {
      if (!kv.first.IsScalar())
        continue;  // refused by name where the map is read
      const std::string& k = kv.first.Scalar();
      const std::string full = path.empty() ? k : path + "." + k;
      const auto [it, fresh] = marks.emplace(k, kv.first.Mark());
      if (!fresh)
        throw SceneError(file, clipped(full),
                         "repeated key: given " + std::string(in_value ? "at " : "on ") +
                             markText(it->second, in_value) + " and again " + (in_value ? "at " : "on ") +
                             markText(kv.first.Mark(), in_value) + (in_value ? " of the --set value" : ""));
      refuseRepeatedKeys(kv.second, full, file, seen, in_value);
    }
  }
  else if (n.IsSequence())
    for (size_t i = 0; i < n.size(); ++i)
      refuseRepeatedKeys(n[i], path + "[" + std::to_string(i) + "]", file, seen, in_value);
}

struct Material
{
  double youngs_modulus = 0.0;
  double poisson_ratio = 0.0;
  double density = 0.0;
  double yield_strength = 0.0;  // Pa, 0 = not given
};

struct NodeInfo
{
  std::string name;
  Vec3 position;
  bool fixed = false;
  double mass = 0.0;
  double radius = 0.0;   // a point mass's sphere (ground contact), m
  std::string material;  // its material (default: the ground's)
  std::vector<PointRef> attachments;
};

/// Builds a Model from a scene's YAML tree, one reader per section, each validating what it reads.
class SceneBuilder
{
public:
  SceneBuilder(const YAML::Node& root, const Source& source) : source_(source), root_(root, "", source) {}

  Model build()
  {
    model_.source = source_.file;
    model_.name = root_.string("name");
    root_.string("description", "");
    readMaterials();
    readNodes();
    readStruts();
    addPointMasses();
    if (model_.bodies.empty())
      root_.fail("struts.members", "nothing to simulate: the scene has no strut and no node with a mass "
                                   "(every node is fixed)");
    finalizeModel(model_);
    placeBodies();
    addNodesAndJoints();
    readTensionFamilies("cables", false);
    readTensionFamilies("springs", true);
    readLoads();
    readActuators();
    readSwitches();
    readContact();
    readGround();
    readSolver();
    readAnalysis();
    readOutputs();
    root_.finish();
    finalizeModel(model_);  // sizes again, now that every constraint is in
    if (model_.analysis.type == AnalysisType::kModal)
      checkModal();
    return std::move(model_);
  }

private:
  NodeInfo& nodeRef(const Reader& r, const std::string& key, const std::string& name)
  {
    const auto it = node_index_.find(name);
    if (it == node_index_.end())
      r.fail(key, "unknown node " + quoted(name));
    return nodes_[it->second];
  }
  void checkName(const Reader& r, const std::string& key, const std::string& name, std::set<std::string>& names,
                 const std::string& what)
  {
    if (!names.insert(name).second)
      r.fail(key, "duplicate " + what + " name " + quoted(name));
  }
  /// `materials` may be left out by a scene that names none (point masses, springs and a ground on the linear law).
  void readMaterials()
  {
    if (!root_.has("materials"))
    {
      root_.optional("materials");
      return;
    }
    Reader mats = root_.map("materials");
    for (const std::string& name : mats.keys())
    {
      Reader m = mats.map(name);
      Material mat;
      mat.youngs_modulus = m.positive("youngs_modulus");
      if (mat.youngs_modulus > kMaxYoungsModulus)
        m.fail(m.key("youngs_modulus"), "must lie in (0, " + shortestNumber(kMaxYoungsModulus) +
                                            "] Pa (beyond any solid), got " + show(m.get("youngs_modulus")));
      mat.poisson_ratio = m.number("poisson_ratio", 0.3);
      if (mat.poisson_ratio < 0.0 || mat.poisson_ratio >= 0.5)
        m.fail(m.key("poisson_ratio"), "must lie in [0, 0.5), got " + shortestNumber(mat.poisson_ratio));
      mat.density = m.nonNegative("density", 0.0);
      if (mat.density > kMaxDensity)
        m.fail(m.key("density"), "must lie in [0, " + shortestNumber(kMaxDensity) +
                                     "] kg/m^3 (beyond any solid), got " + show(m.get("density")));
      mat.yield_strength = m.has("yield_strength") ? m.positive("yield_strength") : 0.0;
      m.finish();
      materials_[name] = mat;
    }
  }

  void readNodes()
  {
    Reader rn = root_.map("nodes");
    for (const std::string& name : rn.keys())
    {
      Reader n = rn.map(name);
      NodeInfo info;
      info.name = name;
      info.position = n.vec3("position");
      info.fixed = n.boolean("fixed", false);
      info.mass = n.nonNegative("mass", 0.0);
      if (info.fixed && info.mass > 0.0)
        n.fail(n.key("mass"), "a fixed node cannot carry a mass");
      if (n.has("radius") || n.has("material"))
      {
        if (!(info.mass > 0.0))
          n.fail(n.key(n.has("radius") ? "radius" : "material"),
                 "only a node with a mass (a point mass) has a radius and a material (for the ground)");
        info.radius = n.positive("radius");
        info.material = n.string("material", "");
        if (!info.material.empty() && !materials_.count(info.material))
          n.fail(n.key("material"), "unknown material " + quoted(info.material));
      }
      n.finish();
      node_index_[name] = static_cast<int>(nodes_.size());
      nodes_.push_back(info);
    }
    if (nodes_.empty())
      rn.fail("nodes", "a scene needs at least one node");
  }

  StrutLayer makeLayer(const Reader& r, const std::string& material_key, const std::string& radius_key,
                       const std::string& material, double inner, double outer)
  {
    const auto it = materials_.find(material);
    if (it == materials_.end())
      r.fail(material_key, "unknown material " + quoted(material));
    if (!(outer > inner))
      r.fail(radius_key, "the outer radius must exceed the inner radius");
    // the section must be representable: pi (r_o^2 - r_i^2) neither underflows to 0 nor overflows
    const double area = M_PI * (outer * outer - inner * inner);
    if (!(area >= std::numeric_limits<double>::min()) || !std::isfinite(area))
      r.fail(radius_key, "a radius of " + shortestNumber(outer) + " m gives a cross-section area of " +
                             shortestNumber(area) + " m^2, which floating point cannot use");
    StrutLayer l;
    l.material = material;
    l.inner_radius = inner;
    l.outer_radius = outer;
    l.density = it->second.density;
    l.youngs_modulus = it->second.youngs_modulus;
    l.poisson_ratio = it->second.poisson_ratio;
    return l;
  }

  void readStruts()
  {
    if (!root_.has("struts"))  // point masses alone (a mass-spring net)
    {
      root_.optional("struts");
      return;
    }
    Reader rs = root_.map("struts");
    const std::string material = rs.string("material");
    const double radius = rs.positive("radius");
    double core_radius = 0.0;
    std::string core_material;
    if (rs.has("core"))
    {
      Reader core = rs.map("core");
      core_material = core.string("material");
      core_radius = core.positive("radius");
      core.finish();
      if (!(core_radius < radius))
        rs.fail(rs.key("core.radius"), "must be smaller than struts.radius (" + shortestNumber(radius) + "), got " +
                                           shortestNumber(core_radius));
    }
    else
      rs.optional("core");
    Reader members = rs.map("members");
    for (const std::string& name : members.keys())
    {
      const std::string key = members.key(name);
      const std::vector<std::string> ends = members.names(name);
      if (ends.size() != 2)
        members.fail(key, "expected two node names [from, to], got " + show(members.get(name)));
      checkName(members, key, name, member_names_, "member");
      if (ends[0] == ends[1])
        members.fail(key, "a strut needs two different nodes, got " + quoted(ends[0]) + " twice");
      NodeInfo& n1 = nodeRef(members, key, ends[0]);
      NodeInfo& n2 = nodeRef(members, key, ends[1]);
      const Vec3 axis = n2.position - n1.position;
      const double length = axis.norm();
      if (!(length > 1e-9) || !std::isfinite(length))
        members.fail(key, std::string(length > 1e-9 ? "the strut's length is not finite" : "the strut has zero length") +
                              ": its nodes " + quoted(ends[0]) + " at " + showVec3(n1.position) + " and " +
                              quoted(ends[1]) + " at " + showVec3(n2.position));

      Body b;
      b.name = name;
      b.kind = BodyKind::kStrut;
      b.length = length;
      if (core_radius > 0.0)
        b.layers.push_back(
            makeLayer(rs, rs.key("core.material"), rs.key("core.radius"), core_material, 0.0, core_radius));
      b.layers.push_back(makeLayer(rs, rs.key("material"), rs.key("radius"), material, core_radius, radius));
      double mass = 0.0, jt = 0.0, ja = 0.0;
      for (const StrutLayer& l : b.layers)
      {
        const double r2 = l.outer_radius * l.outer_radius + l.inner_radius * l.inner_radius;
        const double m =
            l.density * M_PI * (l.outer_radius * l.outer_radius - l.inner_radius * l.inner_radius) * length;
        mass += m;
        jt += m * (3.0 * r2 + length * length) / 12.0;
        ja += m * r2 / 2.0;
      }
      bool any_density = false;
      for (const StrutLayer& l : b.layers)
        any_density = any_density || l.density > 0.0;
      if (!any_density)
        rs.fail(rs.key("material"), "strut " + quoted(name) + " has zero mass (the material's density is 0)");
      if (!(mass >= std::numeric_limits<double>::min() && std::isfinite(mass) && ja > 0.0 && std::isfinite(jt)))
        rs.fail(rs.key("radius"), "strut " + quoted(name) + " of length " + shortestNumber(length) + " m and radius " +
                                      shortestNumber(radius) + " m has a mass of " + shortestNumber(mass) +
                                      " kg and an axial inertia of " + shortestNumber(ja) +
                                      " kg m^2, which floating point cannot use");
      b.mass = mass;
      b.inertia = Vec3(jt, jt, ja);
      const int index = static_cast<int>(model_.bodies.size());
      model_.bodies.push_back(b);
      body_index_[name] = index;
      n1.attachments.push_back(PointRef{ index, Vec3(0.0, 0.0, -0.5 * length) });
      n2.attachments.push_back(PointRef{ index, Vec3(0.0, 0.0, 0.5 * length) });
    }
    members.finish();
    rs.finish();
  }

  /// A body for every free node that carries a mass.
  void addPointMasses()
  {
    for (NodeInfo& n : nodes_)
      if (n.mass > 0.0)
      {
        Body b;
        b.name = n.name;
        b.kind = BodyKind::kPointMass;
        b.mass = n.mass;
        const int index = static_cast<int>(model_.bodies.size());
        model_.bodies.push_back(b);
        n.attachments.insert(n.attachments.begin(), PointRef{ index, Vec3::Zero() });
      }
  }

  /// The initial configuration: point masses at their nodes, strut centres and orientations from their ends.
  void placeBodies()
  {
    model_.q0.setZero(model_.nq);
    std::vector<Vec3> lower(model_.bodies.size()), upper(model_.bodies.size());
    for (const NodeInfo& n : nodes_)
      for (const PointRef& p : n.attachments)
      {
        const Body& b = model_.bodies[p.body];
        if (b.kind == BodyKind::kPointMass)
          model_.q0.segment<3>(b.offset) = n.position;
        else
          (p.local.z() < 0.0 ? lower : upper)[p.body] = n.position;
      }
    for (size_t i = 0; i < model_.bodies.size(); ++i)
    {
      const Body& b = model_.bodies[i];
      if (b.kind != BodyKind::kStrut)
        continue;
      model_.q0.segment<3>(b.offset) = 0.5 * (lower[i] + upper[i]);
      model_.q0.segment<4>(b.offset + 3) = thetaFromZAxis(upper[i] - lower[i]);
    }
  }

  /// Node points, ground pins at fixed nodes, ball joints where bodies share a node, quaternion norms;
  /// the ground level.
  void addNodesAndJoints()
  {
    double ground_sum = 0.0;
    double lowest = std::numeric_limits<double>::infinity();
    for (const NodeInfo& n : nodes_)
    {
      Node node;
      node.name = n.name;
      if (n.attachments.empty())
      {
        if (!n.fixed)
          root_.fail("nodes." + n.name,
                     "the node is attached to nothing: make it fixed, give it a mass, or end a strut there");
        node.point = PointRef{ -1, n.position };
      }
      else
        node.point = n.attachments.front();
      lowest = std::min(lowest, n.position.z());
      if (n.fixed)
      {
        ground_sum += n.position.z();
        ++ground_count_;
      }
      model_.nodes.push_back(node);
      if (n.fixed && !n.attachments.empty())
      {
        Constraint c;
        c.name = n.name + ".pin";
        c.a = n.attachments.front();
        c.b = PointRef{ -1, n.position };
        c.directions = { Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ() };
        c.offsets = { 0.0, 0.0, 0.0 };
        model_.constraints.push_back(c);
      }
      for (size_t k = 1; k < n.attachments.size(); ++k)
      {
        Constraint c;
        c.name = n.name + ".joint" + std::to_string(k);
        c.a = n.attachments.front();
        c.b = n.attachments[k];
        c.directions = { Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ() };
        c.offsets = { 0.0, 0.0, 0.0 };
        model_.constraints.push_back(c);
      }
    }
    // a free-floating scene is fine for dynamics; the ground level is then its lowest node
    model_.ground_level = ground_count_ > 0 ? ground_sum / ground_count_ : lowest;
    if (!std::isfinite(model_.ground_level))
      root_.fail("nodes", "the mean height of the fixed nodes overflows: " + shortestNumber(model_.ground_level));
    for (size_t i = 0; i < model_.bodies.size(); ++i)
      if (model_.bodies[i].kind == BodyKind::kStrut)
      {
        Constraint c;
        c.kind = Constraint::Kind::kQuatNorm;
        c.name = model_.bodies[i].name + ".norm";
        c.body = static_cast<int>(i);
        model_.constraints.push_back(c);
      }
  }

  /// Cables (a material and a radius: k = EA / l0) or springs (a stiffness k), by family.
  void readTensionFamilies(const std::string& section_name, bool springs)
  {
    section(root_, section_name,
            [&](Reader& fams)
            {
              for (const std::string& fam : fams.keys())
              {
                Reader f = fams.map(fam);
                readTensionFamily(f, springs);
                f.finish();
              }
            });
  }

  void readTensionFamily(Reader& f, bool springs)
  {
    double ea = 0.0, k_spring = 0.0, area = 0.0, yield_strength = 0.0;
    if (springs)
      k_spring = f.positive("stiffness");
    else
    {
      const std::string mat = f.string("material");
      const auto it = materials_.find(mat);
      if (it == materials_.end())
        f.fail(f.key("material"), "unknown material " + quoted(mat));
      const double radius = f.positive("radius");
      area = M_PI * radius * radius;
      ea = it->second.youngs_modulus * area;
      yield_strength = it->second.yield_strength;
      if (!(area >= std::numeric_limits<double>::min()) || !(ea >= std::numeric_limits<double>::min()) ||
          !std::isfinite(ea))
        f.fail(f.key("radius"), "a radius of " + shortestNumber(radius) + " m gives a section of " +
                                    shortestNumber(area) + " m^2 and an axial stiffness EA of " + shortestNumber(ea) +
                                    " N, which floating point cannot use");
    }
    const bool has_prestress = f.has("prestress");
    const bool has_rest = f.has("rest_length");
    if (has_prestress && has_rest)
      f.fail(f.key("rest_length"), "give either prestress or rest_length, not both");
    const double prestress = f.nonNegative("prestress", 0.0);
    const double rest = has_rest ? f.positive("rest_length") : (f.optional("rest_length"), 0.0);
    const double damping = f.nonNegative("damping", 0.0);
    const bool tension_only = f.boolean("tension_only", true);
    Reader members = f.map("members");
    for (const std::string& name : members.keys())
    {
      const std::string key = members.key(name);
      const std::vector<std::string> ends = members.names(name);
      if (ends.size() < 2 || ends.size() > static_cast<size_t>(Cable::kMaxPoints))
        members.fail(key, "expected two node names [a, b], or up to " + std::to_string(Cable::kMaxPoints) +
                              " for a sliding cable [a, via..., b], got " + std::to_string(ends.size()));
      checkName(members, key, name, member_names_, "member");
      Cable c;
      c.name = name;
      double l = 0.0;
      for (size_t k = 0; k < ends.size(); ++k)
      {
        const NodeInfo& nk = nodeRef(members, key, ends[k]);
        if (k > 0)
        {
          if (ends[k] == ends[k - 1])
            members.fail(key, "a cable needs two different nodes in a row, got " + quoted(ends[k]) + " twice");
          const double lk = (nk.position - nodes_[node_index_.at(ends[k - 1])].position).norm();
          if (!(lk > 1e-9))
            members.fail(key, "nodes " + quoted(ends[k - 1]) + " and " + quoted(ends[k]) + " coincide");
          l += lk;
        }
        c.points.push_back(model_.nodes[node_index_.at(ends[k])].point);
        std::vector<int> struts_here;
        for (const PointRef& a : nk.attachments)
          if (a.body >= 0 && model_.bodies[a.body].kind == BodyKind::kStrut)
            struts_here.push_back(a.body);
        c.point_struts.push_back(struts_here);
      }
      if (!std::isfinite(l))
        members.fail(key, "the member's length is not finite (" + shortestNumber(l) + ")");
      c.damping = damping;
      c.tension_only = tension_only;
      c.area = area;
      c.yield_strength = yield_strength;
      if (springs)
      {
        c.rest_length = has_rest ? rest : l - prestress / k_spring;  // T = k (l - l0)
        if (!(c.rest_length > 0.0))
          f.fail(f.key("prestress"), "member " + quoted(name) + ": the prestress would need a rest length <= 0");
        c.stiffness = k_spring;
      }
      else
      {
        c.rest_length = has_rest ? rest : l / (1.0 + prestress / ea);
        c.stiffness = ea / c.rest_length;
        if (!(c.rest_length > 0.0) || !std::isfinite(c.stiffness))
          f.fail(f.key(has_rest ? "rest_length" : "prestress"),
                 "member " + quoted(name) + ": rest length " + shortestNumber(c.rest_length) +
                     " m gives a stiffness EA / l0 of " + shortestNumber(c.stiffness) + " N/m");
      }
      cable_index_[name] = static_cast<int>(model_.cables.size());
      model_.cables.push_back(c);
    }
    members.finish();
  }

  void readLoads()
  {
    section(root_, "loads",
            [&](Reader& loads)
            {
              for (const std::string& name : loads.keys())
              {
                Reader l = loads.map(name);
                checkName(loads, loads.key(name), name, member_names_, "member");
                PointLoad load;
                load.name = name;
                const std::string node = l.string("node");
                const NodeInfo& info = nodeRef(l, l.key("node"), node);
                if (info.fixed)
                  l.fail(l.key("node"), "node " + quoted(node) + " is fixed: a load there does nothing");
                load.point = model_.nodes[node_index_.at(node)].point;
                load.force = l.vec3("force");
                l.finish();
                model_.loads.push_back(load);
              }
            });
  }

  void readActuators()
  {
    section(root_, "actuators",
            [&](Reader& acts)
            {
              std::set<std::string> actuator_names;
              for (const std::string& name : acts.keys())
              {
                Reader a = acts.map(name);
                checkName(acts, acts.key(name), name, actuator_names, "actuator");
                readActuator(a, name);
                a.finish();
              }
            });
  }

  void readActuator(Reader& a, const std::string& name)
  {
    Actuator act;
    act.name = name;
    const YAML::Node range = a.raw("range");
    if (!range.IsSequence() || range.size() != 2)
      a.fail(a.key("range"), "expected [min, max], got " + show(range));
    act.min_value = a.toNumber(range[0], a.key("range"));
    act.max_value = a.toNumber(range[1], a.key("range"));
    if (!(act.min_value <= 0.0 && act.max_value > 0.0))
      a.fail(a.key("range"), "expected min <= 0 < max, got " + show(range));
    const int index = static_cast<int>(model_.actuators.size());
    if (a.has("nodes") == a.has("cables"))
      a.fail(a.key(a.has("nodes") ? "cables" : "nodes"),
             "give either nodes (driven along a direction) or cables (pulled in), not both or neither");
    if (a.has("cables"))
    {
      // pull-in: each cable's rest length becomes l0 - s
      a.optional("nodes");
      for (const std::string& cn : a.uniqueNames("cables"))
      {
        const auto it = cable_index_.find(cn);
        if (it == cable_index_.end())
          a.fail(a.key("cables"), "unknown cable " + quoted(cn));
        Cable& cable = model_.cables[it->second];
        if (cable.actuator >= 0)
          a.fail(a.key("cables"), "cable " + quoted(cn) + " is already pulled by actuator " +
                                      quoted(model_.actuators[cable.actuator].name));
        if (!(act.max_value < cable.rest_length))
          a.fail(a.key("range"), "the largest pull-in " + show(range[1]) + " m would leave cable " + quoted(cn) +
                                     " (rest length " + shortestNumber(cable.rest_length) + " m) no length");
        cable.actuator = index;
        act.cables.push_back(it->second);
      }
      for (const char* k : { "direction", "guided" })
        if (a.has(k))
          a.fail(a.key(k), "an actuator that pulls cables in has no direction or guide (those are for nodes)");
    }
    else
    {
      a.optional("cables");
      const Vec3 dir = a.vec3("direction");
      if (!(dir.norm() > 1e-12) || !std::isfinite(dir.norm()))
        a.fail(a.key("direction"), "must be a nonzero vector of finite length, got " + showVec3(dir));
      const Vec3 d = dir.normalized();
      // guided: the node cannot move across the direction either (a slider), e.g. a driven body
      const bool guided = a.boolean("guided", false);
      const Vec3 any = std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
      const Vec3 across1 = d.cross(any).normalized();
      const Vec3 across2 = d.cross(across1);
      for (const std::string& nn : a.uniqueNames("nodes"))
      {
        const NodeInfo& info = nodeRef(a, a.key("nodes"), nn);
        if (info.fixed)
          a.fail(a.key("nodes"), "node " + quoted(nn) + " is fixed and cannot be actuated");
        Constraint c;
        c.name = name + "." + nn;
        c.a = model_.nodes[node_index_.at(nn)].point;
        c.b = PointRef{ -1, Vec3::Zero() };
        c.directions = { d };
        c.offsets = { d.dot(info.position) };
        c.actuator = index;
        act.constraints.push_back(static_cast<int>(model_.constraints.size()));
        model_.constraints.push_back(c);
        if (guided)
        {
          c.name = name + "." + nn + ".guide";
          c.directions = { across1, across2 };
          c.offsets = { across1.dot(info.position), across2.dot(info.position) };
          c.actuator = -1;
          model_.constraints.push_back(c);
        }
      }
    }
    model_.actuators.push_back(act);
  }

  void readSwitches()
  {
    section(root_, "gravity",
            [&](Reader& g)
            {
              model_.gravity_enabled = g.boolean("enabled", false);
              model_.gravity = g.vec3("vector", model_.gravity);
            });
    section(root_, "damping", [&](Reader& d) { model_.damping_enabled = d.boolean("enabled", true); });
  }

  /// Contact settings and the pairs whose gap is measured (forces come with the contact model).
  void readContact()
  {
    std::vector<std::pair<int, int>> pairs;
    bool pairs_given = false;
    section(root_, "contact", [&](Reader& c) { pairs_given = readContactSettings(c, pairs); });
    if (!pairs_given)
    {
      readAllStrutPairs();
      return;
    }
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    for (const auto& [a, b] : pairs)
    {
      const StrutPair p = makeStrutPair(model_, a, b);
      checkPairConstants(p);
      model_.listed_pairs.push_back(p);
    }
  }

  /// Refuses a pair whose contact constants overflow, or (`linear_law_too`) that has layers under the linear law.
  void checkPairConstants(const StrutPair& p, bool linear_law_too = true) const
  {
    const std::string& a = model_.bodies[p.body_a].name;
    const std::string& b = model_.bodies[p.body_b].name;
    if (!std::isfinite(p.stiffness90))
      root_.fail("materials", "the contact stiffness of struts " + quoted(a) + " and " + quoted(b) +
                                  " overflows: " + shortestNumber(p.stiffness90));
    if (linear_law_too && model_.contact.law == ContactLaw::kLinear && p.core_stiffness90 > 0.0)
      root_.fail("contact.law", "'linear' has one spring for every pair, but struts " + quoted(a) + " and " +
                                    quoted(b) + " have layers (a core): use law 'hertz' for layered struts");
    if (!std::isfinite(p.core_stiffness90))
      root_.fail("materials", "the contact stiffness of the cores of struts " + quoted(a) + " and " + quoted(b) +
                                  " overflows: " + shortestNumber(p.core_stiffness90));
  }

  /// `pairs: auto`: every two struts that share no node, numbered by the model and found near contact by the
  /// broad phase (none stored). Their constants are checked once per two kinds of strut (materials and radii).
  void readAllStrutPairs()
  {
    std::vector<int> struts;
    for (size_t i = 0; i < model_.bodies.size(); ++i)
      if (model_.bodies[i].kind == BodyKind::kStrut)
        struts.push_back(static_cast<int>(i));
    try
    {
      model_.checkAllStrutPairs(struts, joinedStruts());
    }
    catch (const std::invalid_argument& e)
    {
      root_.fail("contact.pairs", e.what());
    }
    // one strut of each kind, with a second one when the kind has two (a pair within the kind)
    std::map<std::vector<double>, std::vector<int>> kinds;
    for (int b : struts)
    {
      std::vector<double> key;
      for (const StrutLayer& l : model_.bodies[b].layers)
        key.insert(key.end(), { l.outer_radius, l.youngs_modulus, l.poisson_ratio });
      std::vector<int>& members = kinds[key];
      if (members.size() < 2)
        members.push_back(b);
    }
    std::vector<const std::vector<int>*> kind_list;
    for (const auto& kind : kinds)
      kind_list.push_back(&kind.second);
    for (size_t x = 0; x < kind_list.size(); ++x)
    {
      const std::vector<int>& kx = *kind_list[x];
      if (kx.size() == 2)
        checkPairConstants(makeStrutPair(model_, kx[0], kx[1]), false);
      for (size_t y = x + 1; y < kind_list.size(); ++y)
        checkPairConstants(makeStrutPair(model_, kx[0], kind_list[y]->front()), false);
    }
    // the linear law and layers: the first checked pair with a layered strut (a strut shares nodes with few others)
    if (model_.contact.law == ContactLaw::kLinear)
      for (int a : struts)
        if (model_.bodies[a].layers.size() > 1)
          for (int b : struts)
            if (model_.allPairsSlot(a, b) >= 0)
            {
              checkPairConstants(makeStrutPair(model_, std::min(a, b), std::max(a, b)));
              break;
            }
  }

  /// The pairs of struts that end at a common node: every two of them, not only those the loader joined directly
  /// (at a node where k struts meet it joins the first to each other one; joints are made at nodes only, so this
  /// covers every jointed pair).
  std::vector<std::pair<int, int>> joinedStruts() const
  {
    std::vector<std::pair<int, int>> joined;
    for (const NodeInfo& n : nodes_)
    {
      const std::vector<PointRef>& at = n.attachments;
      for (size_t x = 0; x < at.size(); ++x)
        for (size_t y = x + 1; y < at.size(); ++y)
          if (at[x].body >= 0 && at[y].body >= 0 && at[x].body != at[y].body)
            joined.emplace_back(std::min(at[x].body, at[y].body), std::max(at[x].body, at[y].body));
    }
    return joined;
  }

  /// A contact law: `law` (hertz, the default, or linear), the hertz law's restitution ([0, 1]) or the linear law's
  /// stiffness (N/m, required) and damping (N s/m), friction (>= 0) and the modified Coulomb law's v0 < v1 (m/s; v0
  /// may be 0 for the ground, whose law is then linear from rest), each kept at its default when not given. A key of
  /// the other law is refused (it would be ignored).
  static void readContactLaw(Reader& r, ContactLaw& law, double& stiffness, double& damping, double& restitution,
                             double& friction, double& stick, double& slip, bool stick_may_be_zero,
                             const std::vector<std::string>& hertz_only)
  {
    const std::string name = r.string("law", "hertz");
    if (name == "hertz")
      law = ContactLaw::kHertz;
    else if (name == "linear")
      law = ContactLaw::kLinear;
    else
      r.fail(r.key("law"), "expected 'hertz' or 'linear', got " + quoted(name));
    if (law == ContactLaw::kLinear)
    {
      for (const std::string& k : hertz_only)
        if (r.has(k))
          r.fail(r.key(k),
                 "applies to law 'hertz' only (the linear law is set by stiffness and damping), got " + show(r.get(k)));
      if (!r.has("stiffness"))
        r.fail(r.key("stiffness"), "is required by law 'linear' (N/m)");
      stiffness = r.positive("stiffness");  // (numbers are finite: the reader refuses .nan and .inf)
      damping = r.nonNegative("damping", 0.0);
    }
    else
    {
      for (const char* k : { "stiffness", "damping" })
        if (r.has(k))
          r.fail(r.key(k), std::string("applies to law 'linear' only (the hertz law's stiffness comes from the "
                                       "materials and its damping from the restitution), got ") +
                               show(r.get(k)));
    }
    restitution = r.nonNegative("restitution", restitution);
    if (restitution > 1.0)
      r.fail(r.key("restitution"), "must be in [0, 1], got " + show(r.get("restitution")));
    friction = r.nonNegative("friction", friction);
    if (friction > kMaxFriction)
      r.fail(r.key("friction"), "must lie in [0, " + shortestNumber(kMaxFriction) + "], got " + show(r.get("friction")));
    stick = stick_may_be_zero ? r.nonNegative("stick_velocity", stick) : r.positive("stick_velocity", stick);
    slip = r.positive("slip_velocity", slip);
    if (slip <= stick)
      r.fail(r.key("slip_velocity"),
             "must exceed stick_velocity (" + shortestNumber(stick) + " m/s), got " + shortestNumber(slip));
  }

  /// The ground (`ground`): its plane and material; a contact sphere at every strut end and every point mass with
  /// a radius, except at fixed nodes (held there anyway). A sphere that starts pressed into the ground by more
  /// than a tenth of its radius is refused (a scene placed with its nodes, not its surfaces, on the ground).
  void readGround()
  {
    GroundSettings& g = model_.ground;
    section(root_, "ground",
            [&](Reader& r)
            {
              g.enabled = r.boolean("enabled", false);
              g.height = r.number("height", 0.0);
              readContactLaw(r, g.law, g.linear_stiffness, g.linear_damping, g.restitution, g.friction,
                             g.stick_velocity, g.slip_velocity, true, { "restitution", "material" });
              if (g.law == ContactLaw::kLinear)
                return;
              g.material = r.string("material");
              const auto it = materials_.find(g.material);
              if (it == materials_.end())
                r.fail(r.key("material"), "unknown material " + quoted(g.material));
              g.youngs_modulus = it->second.youngs_modulus;
              g.poisson_ratio = it->second.poisson_ratio;
            });
    if (!g.enabled)
      return;
    model_.ground_level = g.height;
    StrutLayer ground_layer;
    ground_layer.youngs_modulus = g.youngs_modulus;
    ground_layer.poisson_ratio = g.poisson_ratio;
    const Eigen::VectorXd& q0 = model_.q0;
    for (const NodeInfo& n : nodes_)
    {
      if (n.fixed)
        continue;
      for (const PointRef& p : n.attachments)
      {
        const Body& b = model_.bodies[p.body];
        GroundContact c;
        c.body = p.body;
        c.local = p.local;
        c.node = n.name;
        StrutLayer layer;
        if (b.kind == BodyKind::kStrut)
        {
          c.radius = b.radius();
          layer = b.layers.back();
        }
        else
        {
          if (!(n.radius > 0.0))
            continue;  // a point mass without a radius does not touch the ground
          c.radius = n.radius;
          layer = n.material.empty() ? ground_layer :
                                       makeLayer(root_, "nodes." + n.name + ".material", "nodes." + n.name + ".radius",
                                                 n.material, 0.0, n.radius);
        }
        c.stiffness = g.law == ContactLaw::kLinear ?
                          g.linear_stiffness :
                          4.0 / 3.0 * effectiveModulus(layer, ground_layer) * std::sqrt(c.radius);
        if (!std::isfinite(c.stiffness))
          root_.fail("ground.material", "the ground contact stiffness at node " + quoted(n.name) +
                                            " overflows: " + shortestNumber(c.stiffness));
        const double depth = g.height + c.radius - pointPosition(model_, PointRef{ c.body, c.local }, q0).z();
        if (depth > 0.1 * c.radius)
          root_.fail("nodes." + n.name, "starts " + roundedNumber(depth) +
                                            " m deep in the ground (its sphere of radius " + shortestNumber(c.radius) +
                                            " m must rest on ground.height " + shortestNumber(g.height) +
                                            ": place the node at z >= " + roundedNumber(g.height + c.radius) + ")");
        model_.ground_contacts.push_back(c);
      }
    }
  }

  /// Returns whether the pairs were listed (else they are found automatically).
  bool readContactSettings(Reader& c, std::vector<std::pair<int, int>>& pairs)
  {
    ContactSettings& cs = model_.contact;
    cs.enabled = c.boolean("enabled", false);
    readContactLaw(c, cs.law, cs.linear_stiffness, cs.linear_damping, cs.restitution, cs.friction, cs.stick_velocity,
                   cs.slip_velocity, false, { "restitution", "min_crossing_angle", "min_impact_speed" });
    const double min_angle_deg = c.positive("min_crossing_angle", cs.min_crossing_angle * 180.0 / M_PI);
    if (min_angle_deg >= 90.0)
      c.fail(c.key("min_crossing_angle"), "must be below 90 degrees, got " + show(c.get("min_crossing_angle")));
    cs.min_crossing_angle = min_angle_deg * M_PI / 180.0;
    cs.min_impact_speed = c.positive("min_impact_speed", cs.min_impact_speed);
    if (!c.has("pairs"))
    {
      c.optional("pairs");
      return false;
    }
    const YAML::Node p = c.raw("pairs");
    if (p.IsScalar() && p.Scalar() == "auto")
      return false;
    if (!p.IsSequence())
      c.fail(c.key("pairs"), "expected 'auto' or a list of [strut, strut] pairs, got " + show(p));
    const auto strut = [&](const YAML::Node& n)
    {
      const auto it = n.IsScalar() ? body_index_.find(n.Scalar()) : body_index_.end();
      if (it == body_index_.end())
        c.fail(c.key("pairs"), "unknown strut " + (n.IsScalar() ? quoted(n.Scalar()) : show(n)));
      return it->second;
    };
    for (size_t i = 0; i < p.size(); ++i)
    {
      if (!p[i].IsSequence() || p[i].size() != 2)
        c.fail(c.key("pairs"), "expected 'auto' or a list of [strut, strut] pairs, got " + show(p[i]));
      const int a = strut(p[i][0]);
      const int b = strut(p[i][1]);
      if (a == b)
        c.fail(c.key("pairs"), "a strut cannot be paired with itself: " + show(p[i]));
      pairs.emplace_back(std::min(a, b), std::max(a, b));
    }
    return true;
  }

  void readSolver()
  {
    section(root_, "solver", [&](Reader& s) { readSolverOptions(s); });
  }

  void readSolverOptions(Reader& s)
  {
    SolverOptions& o = model_.solver;
    o.dt = s.positive("dt", o.dt);
    const std::string integrator = s.string("integrator", "newmark");
    if (integrator == "newmark")
      o.integrator = Integrator::kNewmark;
    else if (integrator == "generalized_alpha")
      o.integrator = Integrator::kGeneralizedAlpha;
    else
      s.fail(s.key("integrator"), "expected 'newmark' or 'generalized_alpha', got " + quoted(integrator));
    if (s.has("newmark"))
    {
      Reader n = s.map("newmark");
      o.newmark_gamma = n.number("gamma", o.newmark_gamma);
      o.newmark_beta = n.number("beta", o.newmark_beta);
      n.finish();
      if (o.newmark_gamma < 0.5)
        s.fail(s.key("newmark.gamma"),
               "must be at least 0.5 (Newmark is unstable below), got " + shortestNumber(o.newmark_gamma));
      if (o.newmark_gamma > 1.0)
        s.fail(s.key("newmark.gamma"),
               "must be at most 1 (beyond, the damping swamps the motion), got " + shortestNumber(o.newmark_gamma));
      const double beta_min = 0.25 * (o.newmark_gamma + 0.5) * (o.newmark_gamma + 0.5);
      if (o.newmark_beta < beta_min - 1e-12)
        s.fail(s.key("newmark.beta"), "must be at least (gamma + 1/2)^2 / 4 = " + shortestNumber(beta_min) +
                                          " for unconditional stability, got " + shortestNumber(o.newmark_beta));
      if (o.newmark_beta > 1.0)
        s.fail(s.key("newmark.beta"), "must lie in [(gamma + 1/2)^2 / 4, 1] = [" + roundedNumber(beta_min) +
                                          ", 1], got " + shortestNumber(o.newmark_beta));
    }
    else
      s.optional("newmark");
    o.rho_infinity = s.number("rho_infinity", o.rho_infinity);
    if (o.rho_infinity < 0.0 || o.rho_infinity > 1.0)
      s.fail(s.key("rho_infinity"), "must lie in [0, 1], got " + shortestNumber(o.rho_infinity));
    o.newton_tolerance = s.bounded("newton_tolerance", o.newton_tolerance, kMaxNewtonTolerance, "m");
    o.max_iterations = s.integer("max_iterations", o.max_iterations, 1, kMaxNewtonIterations);
    o.max_step_cuts = s.integer("max_step_cuts", o.max_step_cuts, 0, kMaxStepCuts);
    o.reuse_jacobian = s.boolean("reuse_jacobian", o.reuse_jacobian);
    o.max_jacobian_age = s.integer("max_jacobian_age", o.max_jacobian_age, 1, kMaxJacobianAge);
    o.adaptive = s.boolean("adaptive", o.adaptive);
    o.error_tolerance = s.bounded("error_tolerance", o.error_tolerance, kMaxErrorTolerance, "m");
    o.dt_min = s.positive("dt_min", o.dt_min);
    o.dt_max = s.positive("dt_max", o.dt_max);
    o.onset_depth = s.bounded("onset_depth", o.onset_depth, kMaxOnsetDepth, "m");
    o.energy_tolerance = s.bounded("energy_tolerance", o.energy_tolerance, 1.0, "of the kinetic and elastic energy");
    if (o.dt_min > o.dt_max)
      s.fail(s.key("dt_min"),
             "must not exceed dt_max = " + shortestNumber(o.dt_max) + ", got " + shortestNumber(o.dt_min));
    if (o.dt < o.dt_min)
      s.fail(s.key("dt"),
             "must be at least solver.dt_min = " + shortestNumber(o.dt_min) + " s, got " + shortestNumber(o.dt));
  }

  void readAnalysis()
  {
    Reader a = root_.map("analysis");
    AnalysisSettings& an = model_.analysis;
    const std::string type = a.string("type");
    if (type == "static")
      an.type = AnalysisType::kStatic;
    else if (type == "dynamic")
      an.type = AnalysisType::kDynamic;
    else if (type == "modal")
      an.type = AnalysisType::kModal;
    else
      a.fail(a.key("type"), "expected 'static', 'dynamic' or 'modal', got " + quoted(type));
    // a scene without actuators (free motion, e.g. a drop) needs no actuation travel or speed; the modes are
    // about the start unless an actuation is given
    const bool actuated = !model_.actuators.empty();
    // a dynamic run with actuation.sequence moves each actuator on its own: no common max_actuation
    const bool sequenced = root_.has("actuation") && root_.map("actuation").has("sequence");
    if (sequenced && a.has("max_actuation"))
      a.fail(a.key("max_actuation"), "give either analysis.max_actuation (every actuator ramps to it) or "
                                     "actuation.sequence (each actuator's own ramps), not both");
    an.max_actuation = actuated && an.type != AnalysisType::kModal && !sequenced ? a.positive("max_actuation") :
                                                                                   a.nonNegative("max_actuation", 0.0);
    an.steps = a.integer("steps", an.steps, 1, kMaxLoadSteps);
    an.modes = a.integer("modes", an.modes, 1, kMaxModes);
    an.output_interval = a.nonNegative("output_interval", 0.0);
    an.schedule.final_value = an.max_actuation;
    if (root_.has("actuation"))
    {
      Reader s = root_.map("actuation");
      an.schedule.speed = s.positive("speed");
      an.schedule.start_time = s.nonNegative("start_time", 0.0);
      an.schedule.blend_time = s.nonNegative("blend_time", 0.0);
      if (sequenced)
        readSequence(s);
      s.finish();
    }
    else
    {
      root_.optional("actuation");
      if (an.type == AnalysisType::kDynamic && actuated)
        root_.fail("actuation", "a dynamic analysis needs actuation.speed (m/s)");
    }
    // a dynamic run without a duration runs the actuation ramp to its end and settle_time after it
    if (a.has("settle_time") && an.type != AnalysisType::kDynamic)
      a.fail(a.key("settle_time"), "sets the duration of a dynamic analysis; this analysis is not dynamic");
    if (a.has("settle_time") && a.has("duration"))
      a.fail(a.key("settle_time"), "sets the derived duration; this analysis gives analysis.duration itself");
    an.settle_time = a.positive("settle_time", 1.0);
    if (a.has("duration"))
      an.duration = a.positive("duration");
    else
    {
      const double ramp_end = actuated && an.type == AnalysisType::kDynamic ? actuationEndTime(model_) : 0.0;
      an.duration = ramp_end + an.settle_time;
      if (!std::isfinite(an.duration))
        a.fail(a.key("settle_time"), "the derived duration (the ramp's end " + shortestNumber(ramp_end) + " s plus " +
                                         shortestNumber(an.settle_time) + " s) is not finite");
      if (an.type == AnalysisType::kDynamic)
        an.duration_note = actuated ?
                               "analysis.duration not given: the actuation ramp ends at " + roundedNumber(ramp_end) +
                                   " s, plus analysis.settle_time " + shortestNumber(an.settle_time) + " s" :
                               "analysis.duration not given: analysis.settle_time " + shortestNumber(an.settle_time) +
                                   " s (no actuation)";
    }
    if (an.type == AnalysisType::kStatic && ground_count_ == 0)
      a.fail(a.key("type"), "a static analysis needs at least one fixed node (this structure floats freely)");
    for (const Actuator& act : model_.actuators)
      if (an.max_actuation > act.max_value + 1e-12)
        a.fail(a.key("max_actuation"), "exceeds the range of actuator " + quoted(act.name) + " (max " +
                                           shortestNumber(act.max_value) + " m), got " +
                                           shortestNumber(an.max_actuation));
    if (an.type == AnalysisType::kDynamic)
      checkDynamicWork(a);
    readLoadPath(a);
    a.finish();
  }

  /// actuation.sequence: a list of {time, targets: {actuator: value}}, times ascending; each named actuator ramps
  /// from its value then (0 at the start) to its target at actuation.speed, blended by actuation.blend_time.
  void readSequence(Reader& s)
  {
    AnalysisSettings& an = model_.analysis;
    if (an.type != AnalysisType::kDynamic)
      s.fail(s.key("sequence"), "is for dynamic analyses (a static path ramps every actuator to max_actuation)");
    if (s.has("start_time"))
      s.fail(s.key("start_time"), "a sequence gives each step its own time; start_time is for the common ramp");
    const YAML::Node list = s.raw("sequence");
    if (!list.IsSequence() || list.size() == 0)
      s.fail(s.key("sequence"), "expected a list of {time: s, targets: {actuator: m}}, got " + show(list));
    std::vector<double> busy_until(model_.actuators.size(), 0.0), value(model_.actuators.size(), 0.0);
    double last_time = -1.0;
    for (size_t i = 0; i < list.size(); ++i)
    {
      const std::string key = s.key("sequence") + "[" + std::to_string(i) + "]";
      Reader r(list[i], key, source_);
      ActuationStep step;
      step.time = r.nonNegative("time", -1.0);
      if (!r.has("time"))
        r.fail(key + ".time", "missing required key");
      if (step.time <= last_time)
        r.fail(r.key("time"), "steps must come in increasing time, got " + shortestNumber(step.time) + " s after " +
                                  shortestNumber(last_time) + " s");
      last_time = step.time;
      Reader targets = r.map("targets");
      if (targets.keys().empty())
        r.fail(r.key("targets"), "names no actuator");
      for (const std::string& name : targets.keys())
      {
        const int a = model_.findActuator(name);
        if (a < 0)
          targets.fail(targets.key(name), "unknown actuator " + quoted(name));
        const double target = targets.number(name);
        const Actuator& act = model_.actuators[a];
        if (target < act.min_value || target > act.max_value)
          targets.fail(targets.key(name), "must lie in the actuator's range [" + shortestNumber(act.min_value) + ", " +
                                              shortestNumber(act.max_value) + "], got " + shortestNumber(target));
        if (step.time < busy_until[a])
          targets.fail(targets.key(name), "actuator " + quoted(name) + " is still moving until " +
                                              roundedNumber(busy_until[a]) + " s (its ramp before ends there)");
        busy_until[a] = an.schedule.startingAt(step.time, std::abs(target - value[a])).endTime();
        value[a] = target;
        step.actuators.push_back(a);
        step.targets.push_back(target);
      }
      targets.finish();
      r.finish();
      an.sequence.push_back(step);
    }
  }

  /// analysis.load_factor: [start, end] scales the point loads along a static path; analysis.arc_length
  /// switches the static path to arc-length continuation.
  void readLoadPath(Reader& a)
  {
    AnalysisSettings& an = model_.analysis;
    const bool is_static = an.type == AnalysisType::kStatic;
    if (a.has("load_factor"))
    {
      const YAML::Node n = a.raw("load_factor");
      if (!n.IsSequence() || n.size() != 2)
        a.fail(a.key("load_factor"), "expected a list of two numbers [start, end], got " + show(n));
      an.load_factor_start = a.toNumber(n[0], a.key("load_factor"));
      an.load_factor_end = a.toNumber(n[1], a.key("load_factor"));
      if (!is_static)
        a.fail(a.key("load_factor"), "scales the loads of a static path only; this analysis is not static");
      if (model_.loads.empty() && an.load_factor_start != an.load_factor_end)
        a.fail(a.key("load_factor"), "the scene has no loads to scale");
      if (std::abs(an.load_factor_start) > 1e6 || std::abs(an.load_factor_end) > 1e6)
        a.fail(a.key("load_factor"), "must lie within [-1e6, 1e6], got [" + shortestNumber(an.load_factor_start) +
                                         ", " + shortestNumber(an.load_factor_end) + "]");
    }
    else
      a.optional("load_factor");
    an.arc_length = a.boolean("arc_length", false);
    if (an.arc_length && !is_static)
      a.fail(a.key("arc_length"), "arc-length continuation is for static paths only; this analysis is not static");
  }

  /// A modal analysis is dense (core/solvers/modal.h): bounded in size, and it needs a coordinate to vibrate.
  void checkModal() const
  {
    const std::string modal = quoted("modal");
    if (model_.nq > kMaxStructureCoordinates)
      root_.fail("analysis.type", "a modal analysis takes at most " + std::to_string(kMaxStructureCoordinates) +
                                      " coordinates, the scene has " + std::to_string(model_.nq) + ", got " + modal);
    const int free = freeCoordinates(model_, model_.q0);
    if (free == 0)
      root_.fail("analysis.type", "a modal analysis needs a node that the pins and struts leave free to move; they "
                                  "hold every node, got " +
                                      modal);
  }

  /// A dynamic run's steps and output rows stay countable, and no step is shorter than solver.dt_min.
  void checkDynamicWork(const Reader& a) const
  {
    const AnalysisSettings& an = model_.analysis;
    const SolverOptions& o = model_.solver;
    if (an.duration < o.dt_min)
      a.fail(a.key("duration"),
             "must be at least solver.dt_min = " + shortestNumber(o.dt_min) + " s, got " + shortestNumber(an.duration));
    // a step longer than the whole run (it ran no step at all and said converged)
    if (o.dt > an.duration)
      root_.fail("solver.dt", std::string(o.adaptive ? "the first step " : "the time step ") + shortestNumber(o.dt) +
                                  " s is longer than the run: analysis.duration " +
                                  (an.duration_note.empty() ? "" : "(derived) ") + roundedNumber(an.duration) +
                                  " s; give a solver.dt of at most the duration");
    if (o.adaptive && an.duration / o.dt_max > kMaxTimeSteps)
      root_.fail("solver.dt_max",
                 "analysis.duration " + shortestNumber(an.duration) + " s / solver.dt_max " + shortestNumber(o.dt_max) +
                     " s = " + shortestNumber(std::ceil(an.duration / o.dt_max)) +
                     " time steps at least, more than the " + shortestNumber(kMaxTimeSteps) + " a run may take");
    if (!o.adaptive && an.duration / o.dt > kMaxTimeSteps)
      root_.fail("solver.dt", "analysis.duration " + shortestNumber(an.duration) + " s / solver.dt " +
                                  shortestNumber(o.dt) + " s = " + shortestNumber(std::ceil(an.duration / o.dt)) +
                                  " time steps, more than the " + shortestNumber(kMaxTimeSteps) + " a run may take");
    if (an.output_interval > 0.0 && an.output_interval < o.dt_min)
      a.fail(a.key("output_interval"), "must be 0 (a row per step) or at least solver.dt_min = " +
                                           shortestNumber(o.dt_min) + " s, got " + shortestNumber(an.output_interval));
    if (an.output_interval > 0.0 && an.duration / an.output_interval > kMaxOutputSteps)
      a.fail(a.key("output_interval"), "analysis.duration " + shortestNumber(an.duration) + " s / output_interval " +
                                           shortestNumber(an.output_interval) +
                                           " s = " + shortestNumber(std::ceil(an.duration / an.output_interval)) +
                                           " output rows, more than the " + shortestNumber(kMaxOutputSteps) +
                                           " a run may write");
  }

  void readOutputs()
  {
    section(root_, "outputs",
            [&](Reader& o)
            {
              if (o.has("height_nodes"))
                for (const std::string& n : o.uniqueNames("height_nodes"))
                {
                  nodeRef(o, o.key("height_nodes"), n);
                  model_.height_nodes.push_back(node_index_.at(n));
                }
              else
                o.optional("height_nodes");
              section(o, "layers",
                      [&](Reader& layers)
                      {
                        for (const std::string& name : layers.keys())
                        {
                          OutputLayer layer;
                          layer.name = name;
                          for (const std::string& n : layers.uniqueNames(name))
                          {
                            nodeRef(layers, layers.key(name), n);
                            layer.nodes.push_back(node_index_.at(n));
                          }
                          if (layer.nodes.empty())
                            layers.fail(layers.key(name), "expected a list of node names, got []");
                          model_.layers.push_back(layer);
                        }
                      });
            });
    // the height is that of the free nodes; of every node when all are fixed (a strut pinned at both ends)
    if (model_.height_nodes.empty())
      for (size_t i = 0; i < nodes_.size(); ++i)
        if (!nodes_[i].fixed)
          model_.height_nodes.push_back(static_cast<int>(i));
    if (model_.height_nodes.empty())
      for (size_t i = 0; i < nodes_.size(); ++i)
        model_.height_nodes.push_back(static_cast<int>(i));
  }
  /// Reads the optional map `name` of `parent` with `read`, or marks it as known when it is absent.
  template <typename F>
  static void section(Reader& parent, const std::string& name, F read)
  {
    if (!parent.has(name))
    {
      parent.optional(name);
      return;
    }
    Reader r = parent.map(name);
    read(r);
    r.finish();
  }

  const Source& source_;
  Reader root_;
  Model model_;
  std::map<std::string, Material> materials_;
  std::vector<NodeInfo> nodes_;  // in file order, as Model::nodes
  std::unordered_map<std::string, int> node_index_, body_index_, cable_index_;
  std::set<std::string> member_names_;
  int ground_count_ = 0;
};

/// The dotted parts of an override's key; every part non-empty ("a..b", ".a" and "a." are refused).
std::vector<std::string> keyParts(const Override& o)
{
  std::vector<std::string> parts;
  size_t begin = 0;
  while (true)
  {
    const size_t dot = o.key.find('.', begin);
    const std::string part = o.key.substr(begin, dot == std::string::npos ? std::string::npos : dot - begin);
    if (part.empty())
      throw SceneError("--set " + clipped(o.key + "=" + o.value), clipped(o.key),
                       "override: malformed key (an empty part between dots)");
    parts.push_back(part);
    if (dot == std::string::npos)
      return parts;
    begin = dot + 1;
  }
}

int secondDocumentLine(const std::string& yaml, const std::string& name);

void applyOverride(const YAML::Node& root, const Override& o, const Source& source)
{
  const std::vector<std::string> parts = keyParts(o);
  YAML::Node value;
  try
  {
    value = YAML::Load(o.value);
  }
  catch (const YAML::Exception&)
  {
    source.fail(o.key, "override: cannot parse value " + quoted(o.value));
  }
  // the value is held to the file's rules: one document, no key twice in a map
  const int second = secondDocumentLine(o.value, source.blame(o.key));
  if (second > 0)
    source.fail(o.key, "override: the value " + quoted(o.value) + " holds a second YAML document (from line " +
                           std::to_string(second) + "); a value is one YAML node");
  std::unordered_set<int> seen;
  refuseRepeatedKeys(value, o.key, source.blame(o.key), seen, true);
  // the maps on the way, each a new handle (assigning one YAML::Node to another would rebind the first's
  // content); a missing intermediate map is created: the schema check refuses it later if it is not a key
  std::vector<YAML::Node> chain{ root };
  for (size_t i = 0; i + 1 < parts.size(); ++i)
  {
    YAML::Node parent = chain.back();
    if (!parent[parts[i]].IsDefined() || parent[parts[i]].IsNull())
      parent[parts[i]] = YAML::Node(YAML::NodeType::Map);
    chain.push_back(parent[parts[i]]);
    if (!chain.back().IsMap())
      source.fail(o.key, "override: " + quoted(parts[i]) + " is not a map");
  }
  chain.back()[parts.back()] = value;
}

/// Counts the documents of a YAML text without building them: YAML::LoadAll does not end on some
/// malformed texts (a lone ',' yields empty documents for ever), so the parser is driven here, at most
/// twice, and a "document" that starts where the first one did (no progress) is not one.
class DocumentCounter : public YAML::EventHandler
{
public:
  std::vector<YAML::Mark> starts;
  void OnDocumentStart(const YAML::Mark& mark) override
  {
    starts.push_back(mark);
  }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t, const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

/// The line (1-based) where a second YAML document starts in `yaml`, 0 when there is none; a syntax
/// error after the first document is refused as such.
int secondDocumentLine(const std::string& yaml, const std::string& name)
{
  std::istringstream in(yaml);
  YAML::Parser parser(in);
  DocumentCounter counter;
  try
  {
    for (int k = 0; k < 2 && parser.HandleNextDocument(counter); ++k) {}
  }
  catch (const YAML::Exception& e)
  {
    throw SceneError(name, "", std::string("YAML syntax error: ") + clipped(e.what()));
  }
  if (counter.starts.size() < 2 || counter.starts[1].pos <= counter.starts[0].pos)
    return 0;
  return counter.starts[1].line + 1;
}

Model loadFromNode(YAML::Node root, const Source& source)
{
  if (!root.IsMap())
    throw SceneError(source.file, "",
                     "the scene must be a YAML map (name, materials, nodes, struts, ...), got " +
                         (root.IsNull() || !root.IsDefined() ? "no content" : show(root)));
  std::unordered_set<int> seen;
  refuseRepeatedKeys(root, "", source.file, seen);
  for (const Override& o : source.overrides)
    applyOverride(root, o, source);
  return SceneBuilder(root, source).build();
}
}  // namespace

Override parseOverride(const std::string& text)
{
  const size_t eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    throw SceneError("--set", clipped(text), "expected key=value, got " + quoted(text));
  return Override{ text.substr(0, eq), text.substr(eq + 1) };
}

std::string readSceneFile(const std::string& path)
{
  struct stat st;
  if (::stat(path.c_str(), &st) != 0)
    throw SceneError(path, "", std::string("cannot open the scene file (") + std::strerror(errno) + ")");
  if (S_ISDIR(st.st_mode))
    throw SceneError(path, "", "is a directory, not a scene file");
  if (!S_ISREG(st.st_mode))
    throw SceneError(path, "",
                     std::string("is not a regular file (") +
                         (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device" :
                          S_ISFIFO(st.st_mode)                       ? "a pipe" :
                          S_ISSOCK(st.st_mode)                       ? "a socket" :
                                                                       "not a file") +
                         "): a scene is read from a file of at most " + std::to_string(kMaxSceneBytes) +
                         " bytes (64 MiB)");
  const auto tooLarge = [&](const std::string& size)
  {
    return SceneError(path, "",
                      "the file has " + size + " bytes, more than the " + std::to_string(kMaxSceneBytes) +
                          " bytes (64 MiB) a scene may have");
  };
  const auto size = static_cast<std::uintmax_t>(st.st_size);
  if (size > kMaxSceneBytes)
    throw tooLarge(std::to_string(size));
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw SceneError(path, "", "cannot open the scene file");
  // read with a bound all the same: the file may grow while it is read
  std::string text;
  text.reserve(static_cast<size_t>(size));
  char chunk[1 << 16];
  while (in.read(chunk, sizeof chunk) || in.gcount() > 0)
  {
    text.append(chunk, static_cast<size_t>(in.gcount()));
    if (text.size() > kMaxSceneBytes)
      throw tooLarge("more than " + std::to_string(kMaxSceneBytes));
  }
  if (in.bad())
    throw SceneError(path, "", "cannot read the scene file");
  return text;
}

Model loadScene(const std::string& path, const std::vector<Override>& overrides)
{
  return loadSceneFromString(readSceneFile(path), path, overrides);
}

Model loadSceneFromString(const std::string& yaml, const std::string& name, const std::vector<Override>& overrides)
{
  if (yaml.size() > kMaxSceneBytes)
    throw SceneError(name, "",
                     "the scene text has " + std::to_string(yaml.size()) + " bytes, more than the " +
                         std::to_string(kMaxSceneBytes) + " bytes (64 MiB) a scene may have");
  YAML::Node root;
  try
  {
    root = YAML::Load(yaml);
  }
  catch (const YAML::Exception& e)
  {
    throw SceneError(name, "", std::string("YAML syntax error: ") + clipped(e.what()));
  }
  const int second = secondDocumentLine(yaml, name);
  if (second > 0)
    throw SceneError(name, "",
                     "a second YAML document starts on line " + std::to_string(second) + "; a scene is one document");
  const Source source{ name, overrides };
  return loadFromNode(root, source);
}

}  // namespace active_tensegrity::core
