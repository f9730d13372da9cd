#include "active_tensegrity/core/scene.h"

#include "active_tensegrity/core/contact.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "active_tensegrity/core/mechanics.h"

namespace active_tensegrity::core
{
namespace
{
std::string show(const YAML::Node& n)
{
  if (!n.IsDefined() || n.IsNull())
    return "null";
  if (n.IsScalar())
    return "'" + n.Scalar() + "'";
  YAML::Emitter e;
  e << YAML::Flow << n;
  return e.c_str();
}

/// A YAML map read under a dotted path; remembers which keys were used so that unknown ones
/// (typos) are refused.
class Reader
{
public:
  Reader(const YAML::Node& node, std::string path, std::string file)
    : node_(node), path_(std::move(path)), file_(std::move(file))
  {
    if (!node_.IsMap())
      fail(path_, "expected a map, got " + show(node_));
  }

  [[noreturn]] void fail(const std::string& key, const std::string& what) const
  {
    throw SceneError(file_, key, what);
  }
  std::string key(const std::string& k) const
  {
    return path_.empty() ? k : path_ + "." + k;
  }
  const std::string& file() const
  {
    return file_;
  }
  const std::string& path() const
  {
    return path_;
  }

  bool has(const std::string& k) const
  {
    return node_[k].IsDefined() && !node_[k].IsNull();
  }
  /// Marks an optional key as known (so an explicit null there is accepted).
  void optional(const std::string& k)
  {
    used_.insert(k);
  }

  YAML::Node raw(const std::string& k)
  {
    used_.insert(k);
    const YAML::Node n = node_[k];
    if (!n.IsDefined() || n.IsNull())
      fail(key(k), "missing required key");
    return n;
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
      fail(key(k), "must be positive, got " + show(node_[k]));
    return v;
  }
  double positive(const std::string& k, double fallback)
  {
    return has(k) ? positive(k) : (used_.insert(k), fallback);
  }
  double nonNegative(const std::string& k, double fallback)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const double v = number(k);
    if (v < 0.0)
      fail(key(k), "must not be negative, got " + show(node_[k]));
    return v;
  }
  int integer(const std::string& k, int fallback, int min_value)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const YAML::Node n = node_[k];
    int v = 0;
    try
    {
      const double d = toNumber(n, key(k));
      if (d != std::floor(d) || std::abs(d) > 1e9)
        fail(key(k), "expected an integer, got " + show(n));
      v = static_cast<int>(d);
    }
    catch (const YAML::Exception&)
    {
      fail(key(k), "expected an integer, got " + show(n));
    }
    if (v < min_value)
      fail(key(k), "must be at least " + std::to_string(min_value) + ", got " + show(n));
    return v;
  }
  bool boolean(const std::string& k, bool fallback)
  {
    used_.insert(k);
    if (!has(k))
      return fallback;
    const YAML::Node n = node_[k];
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
  Reader map(const std::string& k)
  {
    return Reader(raw(k), key(k), file_);
  }

  /// Keys of this map in file order.
  std::vector<std::string> keys() const
  {
    std::vector<std::string> out;
    for (const auto& kv : node_)
      out.push_back(kv.first.Scalar());
    return out;
  }

  void finish() const
  {
    for (const auto& kv : node_)
    {
      const std::string k = kv.first.Scalar();
      if (!used_.count(k))
        fail(key(k), "unknown key (misspelt, or not valid here)");
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
  std::string file_;
  std::set<std::string> used_;
};

struct Material
{
  double youngs_modulus = 0.0;
  double poisson_ratio = 0.0;
  double density = 0.0;
};

struct NodeInfo
{
  Vec3 position;
  bool fixed = false;
  double mass = 0.0;
  std::vector<PointRef> attachments;
};

void checkName(const Reader& r, const std::string& key, const std::string& name, std::set<std::string>& names,
               const std::string& what)
{
  if (!names.insert(name).second)
    r.fail(key, "duplicate " + what + " name '" + name + "'");
}

StrutLayer makeLayer(const Reader& r, const std::string& key, const std::map<std::string, Material>& materials,
                     const std::string& material, double inner, double outer)
{
  const auto it = materials.find(material);
  if (it == materials.end())
    r.fail(key, "unknown material '" + material + "'");
  if (!(outer > inner))
    r.fail(key, "the outer radius must exceed the inner radius");
  StrutLayer l;
  l.material = material;
  l.inner_radius = inner;
  l.outer_radius = outer;
  l.density = it->second.density;
  l.youngs_modulus = it->second.youngs_modulus;
  l.poisson_ratio = it->second.poisson_ratio;
  return l;
}

Model buildModel(const YAML::Node& root_node, const std::string& file)
{
  Reader root(root_node, "", file);
  Model model;
  model.source = file;
  model.name = root.string("name");
  root.string("description", "");

  // materials
  std::map<std::string, Material> materials;
  {
    Reader mats = root.map("materials");
    for (const std::string& name : mats.keys())
    {
      Reader m = mats.map(name);
      Material mat;
      mat.youngs_modulus = m.positive("youngs_modulus");
      mat.poisson_ratio = m.number("poisson_ratio", 0.3);
      if (mat.poisson_ratio < 0.0 || mat.poisson_ratio >= 0.5)
        m.fail(m.key("poisson_ratio"), "must lie in [0, 0.5), got " + std::to_string(mat.poisson_ratio));
      mat.density = m.nonNegative("density", 0.0);
      m.finish();
      materials[name] = mat;
    }
  }

  // nodes
  std::map<std::string, NodeInfo> nodes;
  std::vector<std::string> node_order;
  {
    Reader rn = root.map("nodes");
    for (const std::string& name : rn.keys())
    {
      Reader n = rn.map(name);
      NodeInfo info;
      info.position = n.vec3("position");
      info.fixed = n.boolean("fixed", false);
      info.mass = n.nonNegative("mass", 0.0);
      if (info.fixed && info.mass > 0.0)
        n.fail(n.key("mass"), "a fixed node cannot carry a mass");
      n.finish();
      nodes[name] = info;
      node_order.push_back(name);
    }
    if (nodes.empty())
      rn.fail("nodes", "a scene needs at least one node");
  }
  auto nodeRef = [&](const Reader& r, const std::string& key, const std::string& name) -> NodeInfo&
  {
    const auto it = nodes.find(name);
    if (it == nodes.end())
      r.fail(key, "unknown node '" + name + "'");
    return it->second;
  };
  std::set<std::string> member_names;

  // struts
  {
    Reader rs = root.map("struts");
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
        rs.fail(rs.key("core.radius"), "must be smaller than struts.radius (" + std::to_string(radius) + ")");
    }
    Reader members = rs.map("members");
    for (const std::string& name : members.keys())
    {
      const std::string key = members.key(name);
      const std::vector<std::string> ends = members.names(name);
      if (ends.size() != 2)
        members.fail(key, "expected two node names [from, to]");
      checkName(members, key, name, member_names, "member");
      if (ends[0] == ends[1])
        members.fail(key, "a strut needs two different nodes, got '" + ends[0] + "' twice");
      NodeInfo& n1 = nodeRef(members, key, ends[0]);
      NodeInfo& n2 = nodeRef(members, key, ends[1]);
      const Vec3 axis = n2.position - n1.position;
      const double length = axis.norm();
      if (!(length > 1e-9))
        members.fail(key, "the strut has zero length (its nodes coincide)");

      Body b;
      b.name = name;
      b.kind = BodyKind::kStrut;
      b.length = length;
      if (core_radius > 0.0)
        b.layers.push_back(makeLayer(rs, rs.key("core.material"), materials, core_material, 0.0, core_radius));
      b.layers.push_back(makeLayer(rs, rs.key("material"), materials, material, core_radius, radius));
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
      if (!(mass > 0.0))
        rs.fail(rs.key("material"), "strut '" + name + "' has zero mass (the material's density is 0)");
      b.mass = mass;
      b.inertia = Vec3(jt, jt, ja);
      const int index = static_cast<int>(model.bodies.size());
      model.bodies.push_back(b);
      n1.attachments.push_back(PointRef{ index, Vec3(0.0, 0.0, -0.5 * length) });
      n2.attachments.push_back(PointRef{ index, Vec3(0.0, 0.0, 0.5 * length) });
    }
    members.finish();
    rs.finish();
  }

  // point masses for free nodes that carry one
  for (const std::string& name : node_order)
  {
    NodeInfo& n = nodes[name];
    if (n.mass > 0.0)
    {
      Body b;
      b.name = name;
      b.kind = BodyKind::kPointMass;
      b.mass = n.mass;
      const int index = static_cast<int>(model.bodies.size());
      model.bodies.push_back(b);
      n.attachments.insert(n.attachments.begin(), PointRef{ index, Vec3::Zero() });
    }
  }
  finalizeModel(model);

  // initial configuration
  model.q0.setZero(model.nq);
  for (const std::string& name : node_order)
    for (const PointRef& p : nodes[name].attachments)
    {
      const Body& b = model.bodies[p.body];
      if (b.kind == BodyKind::kPointMass)
        model.q0.segment<3>(b.offset) = nodes[name].position;
    }
  {
    // strut centres and orientations from their end nodes
    std::map<int, Vec3> lower, upper;
    for (const std::string& name : node_order)
      for (const PointRef& p : nodes[name].attachments)
        if (model.bodies[p.body].kind == BodyKind::kStrut)
          (p.local.z() < 0.0 ? lower : upper)[p.body] = nodes[name].position;
    for (size_t i = 0; i < model.bodies.size(); ++i)
    {
      const Body& b = model.bodies[i];
      if (b.kind != BodyKind::kStrut)
        continue;
      const Vec3 a = lower[static_cast<int>(i)], c = upper[static_cast<int>(i)];
      model.q0.segment<3>(b.offset) = 0.5 * (a + c);
      model.q0.segment<4>(b.offset + 3) = thetaFromZAxis(c - a);
    }
  }

  // node points, joints, pins
  double ground_sum = 0.0;
  int ground_count = 0;
  for (const std::string& name : node_order)
  {
    const NodeInfo& n = nodes[name];
    Node node;
    node.name = name;
    if (n.attachments.empty())
    {
      if (!n.fixed)
        root.fail("nodes." + name,
                  "the node is attached to nothing: make it fixed, give it a mass, or end a strut there");
      node.point = PointRef{ -1, n.position };
    }
    else
      node.point = n.attachments.front();
    if (n.fixed)
    {
      ground_sum += n.position.z();
      ++ground_count;
    }
    model.nodes.push_back(node);
    if (n.fixed && !n.attachments.empty())
    {
      Constraint c;
      c.name = name + ".pin";
      c.a = n.attachments.front();
      c.b = PointRef{ -1, n.position };
      c.directions = { Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ() };
      c.offsets = { 0.0, 0.0, 0.0 };
      model.constraints.push_back(c);
    }
    for (size_t k = 1; k < n.attachments.size(); ++k)
    {
      Constraint c;
      c.name = name + ".joint" + std::to_string(k);
      c.a = n.attachments.front();
      c.b = n.attachments[k];
      c.directions = { Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ() };
      c.offsets = { 0.0, 0.0, 0.0 };
      model.constraints.push_back(c);
    }
  }
  // a free-floating scene is fine for dynamics; the ground level is then its lowest node
  double lowest = std::numeric_limits<double>::infinity();
  for (const std::string& name : node_order)
    lowest = std::min(lowest, nodes[name].position.z());
  model.ground_level = ground_count > 0 ? ground_sum / ground_count : lowest;
  for (size_t i = 0; i < model.bodies.size(); ++i)
    if (model.bodies[i].kind == BodyKind::kStrut)
    {
      Constraint c;
      c.kind = Constraint::Kind::kQuatNorm;
      c.name = model.bodies[i].name + ".norm";
      c.body = static_cast<int>(i);
      model.constraints.push_back(c);
    }

  // cables and springs, by family
  auto readTensionFamilies = [&](const std::string& section, bool springs)
  {
    if (!root.has(section))
    {
      root.optional(section);
      return;
    }
    Reader fams = root.map(section);
    for (const std::string& fam : fams.keys())
    {
      Reader f = fams.map(fam);
      double ea = 0.0, k_spring = 0.0, area = 0.0;
      if (springs)
        k_spring = f.positive("stiffness");
      else
      {
        const std::string mat = f.string("material");
        const auto it = materials.find(mat);
        if (it == materials.end())
          f.fail(f.key("material"), "unknown material '" + mat + "'");
        const double radius = f.positive("radius");
        area = M_PI * radius * radius;
        ea = it->second.youngs_modulus * area;
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
        checkName(members, key, name, member_names, "member");
        Cable c;
        c.name = name;
        double l = 0.0;
        for (size_t k = 0; k < ends.size(); ++k)
        {
          const NodeInfo& nk = nodeRef(members, key, ends[k]);
          if (k > 0)
          {
            if (ends[k] == ends[k - 1])
              members.fail(key, "a cable needs two different nodes in a row, got '" + ends[k] + "' twice");
            const double lk = (nk.position - nodes[ends[k - 1]].position).norm();
            if (!(lk > 1e-9))
              members.fail(key, "nodes '" + ends[k - 1] + "' and '" + ends[k] + "' coincide");
            l += lk;
          }
          c.points.push_back(model.nodes[model.findNode(ends[k])].point);
        }
        c.damping = damping;
        c.tension_only = tension_only;
        c.area = area;
        if (springs)
        {
          c.rest_length = has_rest ? rest : l - prestress / k_spring;  // T = k (l - l0)
          if (!(c.rest_length > 0.0))
            f.fail(f.key("prestress"), "member '" + name + "': the prestress would need a rest length <= 0");
          c.stiffness = k_spring;
        }
        else
        {
          c.rest_length = has_rest ? rest : l / (1.0 + prestress / ea);
          c.stiffness = ea / c.rest_length;
        }
        model.cables.push_back(c);
      }
      members.finish();
      f.finish();
    }
  };
  readTensionFamilies("cables", false);
  readTensionFamilies("springs", true);

  // constant point loads
  if (root.has("loads"))
  {
    Reader loads = root.map("loads");
    for (const std::string& name : loads.keys())
    {
      Reader l = loads.map(name);
      checkName(loads, loads.key(name), name, member_names, "member");
      PointLoad load;
      load.name = name;
      const std::string node = l.string("node");
      const NodeInfo& info = nodeRef(l, l.key("node"), node);
      if (info.fixed)
        l.fail(l.key("node"), "node '" + node + "' is fixed: a load there does nothing");
      load.point = model.nodes[model.findNode(node)].point;
      load.force = l.vec3("force");
      l.finish();
      model.loads.push_back(load);
    }
  }
  else
    root.optional("loads");

  // actuators
  if (root.has("actuators"))
  {
    Reader acts = root.map("actuators");
    std::set<std::string> actuator_names;
    for (const std::string& name : acts.keys())
    {
      Reader a = acts.map(name);
      checkName(acts, acts.key(name), name, actuator_names, "actuator");
      Actuator act;
      act.name = name;
      const YAML::Node range = a.raw("range");
      if (!range.IsSequence() || range.size() != 2)
        a.fail(a.key("range"), "expected [min, max], got " + show(range));
      act.min_value = a.toNumber(range[0], a.key("range"));
      act.max_value = a.toNumber(range[1], a.key("range"));
      if (!(act.min_value <= 0.0 && act.max_value > 0.0))
        a.fail(a.key("range"), "expected min <= 0 < max, got " + show(range));
      const int index = static_cast<int>(model.actuators.size());
      if (a.has("nodes") == a.has("cables"))
        a.fail(a.key(a.has("nodes") ? "cables" : "nodes"),
               "give either nodes (driven along a direction) or cables (pulled in), not both or neither");
      if (a.has("cables"))
      {
        // pull-in: each cable's rest length becomes l0 - s
        for (const std::string& cn : a.names("cables"))
        {
          int ci = -1;
          for (size_t k = 0; k < model.cables.size(); ++k)
            if (model.cables[k].name == cn)
              ci = static_cast<int>(k);
          if (ci < 0)
            a.fail(a.key("cables"), "unknown cable '" + cn + "'");
          Cable& cable = model.cables[ci];
          if (cable.actuator >= 0)
            a.fail(a.key("cables"),
                   "cable '" + cn + "' is already pulled by actuator '" + model.actuators[cable.actuator].name + "'");
          if (!(act.max_value < cable.rest_length))
            a.fail(a.key("range"), "the largest pull-in " + show(range[1]) + " m would leave cable '" + cn +
                                       "' (rest length " + std::to_string(cable.rest_length) + " m) no length");
          cable.actuator = index;
          act.cables.push_back(ci);
        }
        for (const char* k : { "direction", "guided" })
          if (a.has(k))
            a.fail(a.key(k), "an actuator that pulls cables in has no direction or guide (those are for nodes)");
      }
      else
      {
        const Vec3 dir = a.vec3("direction");
        if (!(dir.norm() > 1e-12))
          a.fail(a.key("direction"), "must not be the zero vector");
        const Vec3 d = dir.normalized();
        // guided: the node cannot move across the direction either (a slider), e.g. a driven body
        const bool guided = a.boolean("guided", false);
        const Vec3 any = std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
        const Vec3 across1 = d.cross(any).normalized();
        const Vec3 across2 = d.cross(across1);
        for (const std::string& nn : a.names("nodes"))
        {
          const NodeInfo& info = nodeRef(a, a.key("nodes"), nn);
          if (info.fixed)
            a.fail(a.key("nodes"), "node '" + nn + "' is fixed and cannot be actuated");
          Constraint c;
          c.name = name + "." + nn;
          c.a = model.nodes[model.findNode(nn)].point;
          c.b = PointRef{ -1, Vec3::Zero() };
          c.directions = { d };
          c.offsets = { d.dot(info.position) };
          c.actuator = index;
          act.constraints.push_back(static_cast<int>(model.constraints.size()));
          model.constraints.push_back(c);
          if (guided)
          {
            c.name = name + "." + nn + ".guide";
            c.directions = { across1, across2 };
            c.offsets = { across1.dot(info.position), across2.dot(info.position) };
            c.actuator = -1;
            model.constraints.push_back(c);
          }
        }
      }
      a.finish();
      model.actuators.push_back(act);
    }
    acts.finish();
  }
  else
    root.optional("actuators");

  // switches
  if (root.has("gravity"))
  {
    Reader g = root.map("gravity");
    model.gravity_enabled = g.boolean("enabled", false);
    model.gravity = g.vec3("vector", model.gravity);
    g.finish();
  }
  else
    root.optional("gravity");
  if (root.has("damping"))
  {
    Reader d = root.map("damping");
    model.damping_enabled = d.boolean("enabled", true);
    d.finish();
  }
  else
    root.optional("damping");

  // contact: pairs whose gap is measured (forces come with the contact model)
  {
    std::vector<std::pair<int, int>> pairs;
    bool pairs_given = false;
    if (root.has("contact"))
    {
      Reader c = root.map("contact");
      ContactSettings& cs = model.contact;
      cs.enabled = c.boolean("enabled", false);
      cs.restitution = c.nonNegative("restitution", cs.restitution);
      if (cs.restitution > 1.0)
        c.fail(c.key("restitution"), "must be in [0, 1], got " + show(c.raw("restitution")));
      cs.friction = c.nonNegative("friction", cs.friction);
      cs.stick_velocity = c.positive("stick_velocity", cs.stick_velocity);
      cs.slip_velocity = c.positive("slip_velocity", cs.slip_velocity);
      if (cs.slip_velocity <= cs.stick_velocity)
        c.fail(c.key("slip_velocity"), "must exceed stick_velocity (" + std::to_string(cs.stick_velocity) +
                                           " m/s), got " + show(c.raw("slip_velocity")));
      const double min_angle_deg = c.positive("min_crossing_angle", cs.min_crossing_angle * 180.0 / M_PI);
      if (min_angle_deg >= 90.0)
        c.fail(c.key("min_crossing_angle"), "must be below 90 degrees, got " + show(c.raw("min_crossing_angle")));
      cs.min_crossing_angle = min_angle_deg * M_PI / 180.0;
      cs.min_impact_speed = c.positive("min_impact_speed", cs.min_impact_speed);
      if (c.has("pairs"))
      {
        const YAML::Node p = c.raw("pairs");
        if (p.IsScalar() && p.Scalar() == "auto")
          pairs_given = false;
        else if (p.IsSequence())
        {
          pairs_given = true;
          for (size_t i = 0; i < p.size(); ++i)
          {
            if (!p[i].IsSequence() || p[i].size() != 2)
              c.fail(c.key("pairs"), "expected 'auto' or a list of [strut, strut] pairs, got " + show(p[i]));
            const int a = model.findBody(p[i][0].Scalar());
            const int b = model.findBody(p[i][1].Scalar());
            if (a < 0 || model.bodies[a].kind != BodyKind::kStrut)
              c.fail(c.key("pairs"), "unknown strut '" + p[i][0].Scalar() + "'");
            if (b < 0 || model.bodies[b].kind != BodyKind::kStrut)
              c.fail(c.key("pairs"), "unknown strut '" + p[i][1].Scalar() + "'");
            if (a == b)
              c.fail(c.key("pairs"), "a strut cannot be paired with itself: " + show(p[i]));
            pairs.emplace_back(std::min(a, b), std::max(a, b));
          }
        }
        else
          c.fail(c.key("pairs"), "expected 'auto' or a list of [strut, strut] pairs, got " + show(p));
      }
      else
        c.optional("pairs");
      c.finish();
    }
    else
      root.optional("contact");
    if (!pairs_given)
    {
      // every pair of struts that share no node
      for (size_t i = 0; i < model.bodies.size(); ++i)
        for (size_t j = i + 1; j < model.bodies.size(); ++j)
          if (model.bodies[i].kind == BodyKind::kStrut && model.bodies[j].kind == BodyKind::kStrut)
            pairs.emplace_back(static_cast<int>(i), static_cast<int>(j));
      // struts that end at a common node: every two of them, not only those the loader joined directly
      // (at a node where k struts meet it joins the first to each other one; joints are made at nodes
      // only, so this covers every jointed pair)
      std::set<std::pair<int, int>> jointed;
      for (const auto& entry : nodes)
      {
        const std::vector<PointRef>& at = entry.second.attachments;
        for (size_t x = 0; x < at.size(); ++x)
          for (size_t y = x + 1; y < at.size(); ++y)
            if (at[x].body >= 0 && at[y].body >= 0 && at[x].body != at[y].body)
              jointed.insert({ std::min(at[x].body, at[y].body), std::max(at[x].body, at[y].body) });
      }
      std::vector<std::pair<int, int>> kept;
      for (const auto& p : pairs)
        if (!jointed.count(p))
          kept.push_back(p);
      pairs = kept;
    }
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    for (const auto& [a, b] : pairs)
      model.checked_pairs.push_back(makeStrutPair(model, a, b));
  }

  // solver
  if (root.has("solver"))
  {
    Reader s = root.map("solver");
    SolverOptions& o = model.solver;
    o.dt = s.positive("dt", o.dt);
    const std::string integrator = s.string("integrator", "newmark");
    if (integrator == "newmark")
      o.integrator = Integrator::kNewmark;
    else if (integrator == "generalized_alpha")
      o.integrator = Integrator::kGeneralizedAlpha;
    else
      s.fail(s.key("integrator"), "expected 'newmark' or 'generalized_alpha', got '" + integrator + "'");
    if (s.has("newmark"))
    {
      Reader n = s.map("newmark");
      o.newmark_gamma = n.number("gamma", o.newmark_gamma);
      o.newmark_beta = n.number("beta", o.newmark_beta);
      n.finish();
      if (o.newmark_gamma < 0.5)
        s.fail(s.key("newmark.gamma"),
               "must be at least 0.5 (Newmark is unstable below), got " + std::to_string(o.newmark_gamma));
      const double beta_min = 0.25 * (o.newmark_gamma + 0.5) * (o.newmark_gamma + 0.5);
      if (o.newmark_beta < beta_min - 1e-12)
        s.fail(s.key("newmark.beta"), "must be at least (gamma + 1/2)^2 / 4 = " + std::to_string(beta_min) +
                                          " for unconditional stability, got " + std::to_string(o.newmark_beta));
    }
    else
      s.optional("newmark");
    o.rho_infinity = s.number("rho_infinity", o.rho_infinity);
    if (o.rho_infinity < 0.0 || o.rho_infinity > 1.0)
      s.fail(s.key("rho_infinity"), "must lie in [0, 1], got " + std::to_string(o.rho_infinity));
    o.newton_tolerance = s.positive("newton_tolerance", o.newton_tolerance);
    o.max_iterations = s.integer("max_iterations", o.max_iterations, 1);
    o.max_step_cuts = s.integer("max_step_cuts", o.max_step_cuts, 0);
    o.reuse_jacobian = s.boolean("reuse_jacobian", o.reuse_jacobian);
    o.max_jacobian_age = s.integer("max_jacobian_age", o.max_jacobian_age, 1);
    o.adaptive = s.boolean("adaptive", o.adaptive);
    o.error_tolerance = s.positive("error_tolerance", o.error_tolerance);
    o.dt_min = s.positive("dt_min", o.dt_min);
    o.dt_max = s.positive("dt_max", o.dt_max);
    o.onset_depth = s.positive("onset_depth", o.onset_depth);
    if (o.dt_min > o.dt_max)
      s.fail(s.key("dt_min"),
             "must not exceed dt_max = " + std::to_string(o.dt_max) + ", got " + std::to_string(o.dt_min));
    s.finish();
  }
  else
    root.optional("solver");

  // analysis
  {
    Reader a = root.map("analysis");
    AnalysisSettings& an = model.analysis;
    const std::string type = a.string("type");
    if (type == "static")
      an.type = AnalysisType::kStatic;
    else if (type == "dynamic")
      an.type = AnalysisType::kDynamic;
    else
      a.fail(a.key("type"), "expected 'static' or 'dynamic', got '" + type + "'");
    // a scene without actuators (free motion, e.g. a drop) needs no actuation travel or speed
    const bool actuated = !model.actuators.empty();
    an.max_actuation = actuated ? a.positive("max_actuation") : a.nonNegative("max_actuation", 0.0);
    an.steps = a.integer("steps", an.steps, 1);
    an.duration = a.positive("duration", 1.0);
    an.output_interval = a.nonNegative("output_interval", 0.0);
    an.schedule.final_value = an.max_actuation;
    if (root.has("actuation"))
    {
      Reader s = root.map("actuation");
      an.schedule.speed = s.positive("speed");
      an.schedule.start_time = s.nonNegative("start_time", 0.0);
      an.schedule.blend_time = s.nonNegative("blend_time", 0.0);
      s.finish();
    }
    else
    {
      root.optional("actuation");
      if (an.type == AnalysisType::kDynamic && actuated)
        root.fail("actuation", "a dynamic analysis needs actuation.speed (m/s)");
    }
    if (an.type == AnalysisType::kStatic && ground_count == 0)
      a.fail(a.key("type"), "a static analysis needs at least one fixed node (this structure floats freely)");
    for (const Actuator& act : model.actuators)
      if (an.max_actuation > act.max_value + 1e-12)
        a.fail(a.key("max_actuation"), "exceeds the range of actuator '" + act.name + "' (max " +
                                           std::to_string(act.max_value) + " m), got " +
                                           std::to_string(an.max_actuation));
    a.finish();
  }

  // outputs
  if (root.has("outputs"))
  {
    Reader o = root.map("outputs");
    if (o.has("height_nodes"))
      for (const std::string& n : o.names("height_nodes"))
      {
        nodeRef(o, o.key("height_nodes"), n);
        model.height_nodes.push_back(model.findNode(n));
      }
    else
      o.optional("height_nodes");
    if (o.has("layers"))
    {
      Reader layers = o.map("layers");
      for (const std::string& name : layers.keys())
      {
        OutputLayer layer;
        layer.name = name;
        for (const std::string& n : layers.names(name))
        {
          nodeRef(layers, layers.key(name), n);
          layer.nodes.push_back(model.findNode(n));
        }
        if (layer.nodes.empty())
          layers.fail(layers.key(name), "expected a list of node names");
        model.layers.push_back(layer);
      }
      layers.finish();
    }
    else
      o.optional("layers");
    o.finish();
  }
  else
    root.optional("outputs");
  if (model.height_nodes.empty())
    for (size_t i = 0; i < model.nodes.size(); ++i)
      if (!nodes[model.nodes[i].name].fixed)
        model.height_nodes.push_back(static_cast<int>(i));

  root.finish();
  finalizeModel(model);  // sizes again, now that every constraint is in
  return model;
}

void setPath(YAML::Node node, const std::vector<std::string>& parts, size_t i, const YAML::Node& value,
             const std::string& file, const std::string& key)
{
  if (!node.IsMap())
    throw SceneError(file, key, "override: '" + parts[i - 1] + "' is not a map");
  if (i + 1 == parts.size())
  {
    node[parts[i]] = value;
    return;
  }
  // a missing intermediate map is created: the schema check refuses it later if it is not a valid key
  if (!node[parts[i]].IsDefined() || node[parts[i]].IsNull())
    node[parts[i]] = YAML::Node(YAML::NodeType::Map);
  setPath(node[parts[i]], parts, i + 1, value, file, key);
}

Model loadFromNode(YAML::Node root, const std::string& name, const std::vector<Override>& overrides)
{
  if (!root.IsMap())
    throw SceneError(name, "", "the scene must be a YAML map");
  for (const Override& o : overrides)
  {
    std::vector<std::string> parts;
    std::stringstream ss(o.key);
    std::string part;
    while (std::getline(ss, part, '.'))
    {
      if (part.empty())
        throw SceneError(name, o.key, "override: malformed key");
      parts.push_back(part);
    }
    if (parts.empty())
      throw SceneError(name, o.key, "override: empty key");
    YAML::Node value;
    try
    {
      value = YAML::Load(o.value);
    }
    catch (const YAML::Exception& e)
    {
      throw SceneError(name, o.key, "override: cannot parse value '" + o.value + "'");
    }
    setPath(root, parts, 0, value, name, o.key);
  }
  return buildModel(root, name);
}
}  // namespace

Override parseOverride(const std::string& text)
{
  const size_t eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    throw SceneError("--set", text, "expected key=value");
  return Override{ text.substr(0, eq), text.substr(eq + 1) };
}

Model loadScene(const std::string& path, const std::vector<Override>& overrides)
{
  std::ifstream in(path);
  if (!in)
    throw SceneError(path, "", "cannot open the scene file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  return loadSceneFromString(buffer.str(), path, overrides);
}

Model loadSceneFromString(const std::string& yaml, const std::string& name, const std::vector<Override>& overrides)
{
  YAML::Node root;
  try
  {
    root = YAML::Load(yaml);
  }
  catch (const YAML::ParserException& e)
  {
    throw SceneError(name, "", std::string("YAML syntax error: ") + e.what());
  }
  return loadFromNode(root, name, overrides);
}

}  // namespace active_tensegrity::core
