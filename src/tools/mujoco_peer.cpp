#include "mujoco_peer.h"

#include <mujoco/mujoco.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::tools
{
namespace
{
using core::Vec3;

// the peer whose forces MuJoCo's control callback evaluates (MuJoCo's callbacks are global)
thread_local MujocoPeer* g_active = nullptr;
// the last warning MuJoCo printed, instead of stdout and MUJOCO_LOG.TXT
thread_local std::string g_warning;
// armature of a carrier's slide along its drive, per kg of the driven strut: the connect's forces then move
// it by a negligible amount within a step
constexpr double kDriveArmature = 1e6;

void controlCallback(const mjModel*, mjData*)
{
  if (g_active)
    g_active->evaluateForces();
}

void warningHandler(const char* text)
{
  g_warning = text;
}

// makes `peer` the one the callback serves for the lifetime of this object
class Active
{
public:
  explicit Active(MujocoPeer* peer) : previous_(g_active)
  {
    g_active = peer;
    mjcb_control = controlCallback;
  }
  ~Active()
  {
    g_active = previous_;
  }

private:
  MujocoPeer* previous_;
};

std::string num(double v)
{
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

std::string vec(const Vec3& v)
{
  return num(v.x()) + " " + num(v.y()) + " " + num(v.z());
}

bool samePoint(const core::PointRef& a, const core::PointRef& b)
{
  return a.body == b.body && (a.local - b.local).norm() < 1e-12;
}

const char* const kWarningNames[mjNWARNING] = { "near-singular inertia",
                                                "contact list full",
                                                "constraint list full",
                                                "visual geoms full",
                                                "bad qpos",
                                                "bad qvel",
                                                "bad qacc",
                                                "bad ctrl" };

// whether constraint g guides constraint c's driven point: a ground constraint of the same point, not driven,
// holding it on the line along c's direction (two rows across it)
bool isGuideOf(const core::Constraint& g, const core::Constraint& c)
{
  if (g.kind != core::Constraint::Kind::kPoints || g.actuator >= 0 || g.rows() != 2 || g.b.body >= 0 ||
      !samePoint(g.a, c.a))
    return false;
  const Vec3 d = c.directions[0];
  return std::abs(g.directions[0].dot(d)) < 1e-9 && std::abs(g.directions[1].dot(d)) < 1e-9;
}

// Refuses MJCF text with a number that is not finite (std::invalid_argument naming the element and the attribute):
// every value of the translation is derived from the scene, and MuJoCo reads "inf" or "nan" as it likes.
void refuseNonFinite(const std::string& xml)
{
  for (size_t at = xml.find("=\""); at != std::string::npos; at = xml.find("=\"", at + 2))
  {
    const size_t end = xml.find('"', at + 2);
    if (end == std::string::npos)
      return;
    const size_t attr = xml.find_last_of(" \n", at) + 1;
    const std::string attribute = xml.substr(attr, at - attr);
    // names (the scene's own, which may be "inf") and references to them hold no numbers
    if (attribute == "name" || attribute == "model" || attribute == "tendon" || attribute.rfind("body", 0) == 0 ||
        attribute.rfind("geom", 0) == 0 || attribute == "joint" || attribute == "site")
      continue;
    std::istringstream tokens(xml.substr(at + 2, end - at - 2));
    for (std::string t; tokens >> t;)
    {
      std::string lower = t;
      std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
      if (lower.find("nan") == std::string::npos && lower.find("inf") == std::string::npos)
        continue;
      // a number that did not come out finite ("inf", "-nan"), not a name that holds the letters
      if (lower != "inf" && lower != "-inf" && lower != "nan" && lower != "-nan" && lower != "+inf")
        continue;
      const size_t open = xml.rfind('<', at);
      const size_t name_end = xml.find_first_of(" \n/>", open);
      const size_t named = xml.find(" name=\"", open);
      const std::string element = xml.substr(open + 1, name_end - open - 1) +
                                  (named != std::string::npos && named < at ?
                                       " '" + xml.substr(named + 7, xml.find('"', named + 7) - named - 7) + "'" :
                                       std::string());
      throw std::invalid_argument("MuJoCo peer: the translation's <" + element + "> " + attribute + "=\"" +
                                  xml.substr(at + 2, end - at - 2) +
                                  "\" is not finite (a value derived from the scene overflowed)");
    }
  }
}

// MuJoCo's model from the MJCF text, loaded through a virtual file (std::runtime_error with MuJoCo's message)
mjModel* loadMjcf(const std::string& xml)
{
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), "scene.xml", static_cast<int>(xml.size())) != 0)
    throw std::runtime_error("MuJoCo peer: cannot make the virtual file");
  const int file = mj_findFileVFS(vfs.get(), "scene.xml");
  std::copy(xml.begin(), xml.end(), static_cast<char*>(vfs->filedata[file]));
  char error[1000] = "";
  mju_user_warning = warningHandler;
  mjModel* m = mj_loadXML("scene.xml", vfs.get(), error, sizeof(error));
  mj_deleteVFS(vfs.get());
  if (!m)
    throw std::runtime_error(std::string("MuJoCo peer: MuJoCo refused the model: ") + error);
  return m;
}

// MuJoCo's model from an MJCF file (std::runtime_error with MuJoCo's message)
mjModel* loadMjcfFile(const std::string& path)
{
  char error[1000] = "";
  mju_user_warning = warningHandler;
  mjModel* m = mj_loadXML(path.c_str(), nullptr, error, sizeof(error));
  if (!m)
    throw std::runtime_error("MuJoCo peer: MuJoCo refused '" + path + "': " + error);
  return m;
}
}  // namespace

const char* toString(MujocoIntegrator integrator)
{
  switch (integrator)
  {
    case MujocoIntegrator::kEuler:
      return "euler";
    case MujocoIntegrator::kImplicit:
      return "implicit";
    case MujocoIntegrator::kRk4:
      return "rk4";
  }
  return "?";
}

MujocoIntegrator parseMujocoIntegrator(const std::string& name)
{
  if (name == "euler")
    return MujocoIntegrator::kEuler;
  if (name == "implicit")
    return MujocoIntegrator::kImplicit;
  if (name == "rk4")
    return MujocoIntegrator::kRk4;
  throw std::invalid_argument("unknown MuJoCo integrator '" + name + "' (euler, implicit, rk4)");
}

// The translation's state: what the constructor's builder functions (below the struct) find in our model, and
// what the force evaluation and the queries use once MuJoCo has compiled it.
struct MujocoPeer::Impl
{
  // a point mass moved kinematically by a guided node actuator
  struct DrivenMass
  {
    int body = -1, actuator = -1;
    Vec3 p0 = Vec3::Zero(), direction = Vec3::Zero();
    double mass = 0.0;
  };
  // a driven strut end: a carrier body on a slide along the drive (with a huge armature, pushed by
  // (m + armature) s_dd and put back on s(t), s_dot(t) before every step: a kinematic driver whose velocity
  // MuJoCo sees) and slides across it, connected to the strut end
  struct Carrier
  {
    int constraint = -1, actuator = -1;
    Vec3 p0 = Vec3::Zero(), direction = Vec3::Zero();
    bool guided = false;                  // a guide of ours holds the end on the drive's line (no cross slides)
    int drive_qpos = -1, drive_dof = -1;  // the slide along the drive
    double drive_inertia = 0.0;           // carrier mass + armature
    int equality = -1;
    double mass = 0.0;
  };
  // one end of a cable segment computed here: a site (on a MuJoCo body or the world) or a driven mass
  struct End
  {
    int site = -1;    // MuJoCo site id
    int driven = -1;  // index into driven
  };
  struct Segment
  {
    End a, b;
    Vec3 n = Vec3::Zero();  // unit vector from a to b, last evaluation
    double length = 0.0;
  };
  struct CableMap
  {
    std::vector<int> tendons, actuators;  // MuJoCo ids
    std::vector<Segment> segments;        // segments that touch a driven mass
    double length = 0.0, tension = 0.0;   // last evaluation
  };

  // What the translation writes into the MJCF and then looks up by name in the compiled model.
  struct Connect  // a ground pin or a ball joint
  {
    int a_body;
    Vec3 a_local;
    int b_body;  // -1: world (then a point that coincides with a's at the start)
    std::string name;
  };
  struct TendonSpec
  {
    std::string name;
    std::vector<std::string> sites;
  };
  struct SegmentSpec
  {
    core::PointRef a, b;
  };
  struct Translation
  {
    std::vector<Connect> connects;
    std::vector<TendonSpec> tendons;
    std::vector<std::vector<int>> tendons_of_cable;  // per cable: indices into tendons
    std::vector<std::vector<SegmentSpec>> segments_of_cable;
  };

  const core::Model& model;
  MujocoOptions options;
  std::vector<core::StrutPair> checked;  // the model's checked strut pairs (a MuJoCo <pair> each with contact)
  std::vector<int> body_id;              // ours -> MuJoCo body (-1: driven mass)
  std::vector<int> driven_of_body;
  std::vector<DrivenMass> driven;
  std::vector<Carrier> carriers;
  std::vector<CableMap> cables;
  std::vector<int> pair_of_checked;                    // checked pair -> MuJoCo pair (-1 without contact)
  std::vector<std::pair<double, double>> text_solref;  // each <pair>'s solref, in the text's order
  std::vector<double> pair_stiffness, pair_damping;
  std::vector<std::pair<core::PointRef, std::string>> site_names;  // sites made, by point
  std::vector<int> site_ids;                                       // parallel to site_names after compile
  std::vector<std::string> cable_tendon_names, cable_actuator_names;
  core::ActuationValues u;  // at the last force evaluation

  Impl(const core::Model& m, const MujocoOptions& o) : model(m), options(o), checked(checkedPairs(m)) {}

  /// The model's checked pairs, refused past a million (a <pair> element each: a file of hundreds of MB that
  /// MuJoCo checks every step).
  static std::vector<core::StrutPair> checkedPairs(const core::Model& m)
  {
    constexpr long kMostPairs = 1000000;
    if (m.contact.enabled && m.checkedPairCount() > kMostPairs)
      throw std::invalid_argument("MuJoCo peer: contact.pairs: " + std::to_string(m.checkedPairCount()) +
                                  " checked strut pairs, more than the " + std::to_string(kMostPairs) +
                                  " this translation writes (a <pair> each): list the pairs that can touch");
    return m.contact.enabled ? m.checkedPairList() : std::vector<core::StrutPair>{};
  }

  const std::string& siteFor(const core::PointRef& p)
  {
    for (const auto& [point, name] : site_names)
      if (samePoint(point, p))
        return name;
    site_names.emplace_back(p, "site" + std::to_string(site_names.size()));
    return site_names.back().second;
  }

  core::ActuationValue value(int actuator, double t) const
  {
    if (actuator < 0 || actuator >= static_cast<int>(model.actuators.size()))
      return {};
    return core::scheduledActuation(model, t)[actuator];
  }

  Vec3 drivenPosition(int k, double t) const
  {
    return driven[k].p0 + value(driven[k].actuator, t).value * driven[k].direction;
  }

  bool drivenPoint(const core::PointRef& p) const
  {
    return p.body >= 0 && driven_of_body[p.body] >= 0;
  }
  bool hasContact() const
  {
    return model.contact.enabled && !checked.empty();
  }
  bool hasFriction() const
  {
    return model.contact.friction > 0.0;
  }
  /// The bodies that touch the ground (ascending; empty without a ground), one MuJoCo pair each, after the
  /// strut pairs.
  std::vector<int> groundBodies() const
  {
    std::vector<int> out;
    for (const core::GroundContact& g : model.ground_contacts)
      if (driven_of_body[g.body] < 0)
        out.push_back(g.body);
    std::sort(out.begin(), out.end());  // (a strut's two spheres come at its two nodes, far apart in the list)
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }
  /// The ground contact of a body (its first sphere; a strut's two have the same radius and stiffness).
  const core::GroundContact& groundContactOf(int body) const
  {
    for (const core::GroundContact& g : model.ground_contacts)
      if (g.body == body)
        return g;
    throw std::logic_error("no ground contact");
  }
  int pairCount() const
  {
    return (hasContact() ? static_cast<int>(checked.size()) : 0) + static_cast<int>(groundBodies().size());
  }

  std::vector<bool> mapDrivenNodes();
  void mapConnects(const std::vector<bool>& used, Translation& tr);
  void mapCables(Translation& tr);
  std::string mjcf(const Translation& tr) const;
  void writeHeader(std::ostream& x, const Translation& tr) const;
  void writeSites(std::ostream& x, int body, const std::string& indent) const;
  void writeBodies(std::ostream& x) const;
  void writeCarriers(std::ostream& x) const;
  void writeEqualities(std::ostream& x, const Translation& tr) const;
  void writeTendons(std::ostream& x, const Translation& tr) const;
  void writeContactPairs(std::ostream& x) const;
  void findIds(const mjModel* m, const Translation& tr);
  void setUpCarriers(mjModel* m);
  void setContactParameters(mjModel* m);
};

// Driven nodes: driven point masses (moved kinematically) or carriers of driven strut ends; returns the
// constraints that need nothing more (the quaternion norms, the driven nodes and their guides).
std::vector<bool> MujocoPeer::Impl::mapDrivenNodes()
{
  const int n_bodies = static_cast<int>(model.bodies.size());
  body_id.assign(n_bodies, -1);
  driven_of_body.assign(n_bodies, -1);
  std::vector<bool> used(model.constraints.size(), false);
  for (size_t i = 0; i < model.constraints.size(); ++i)
  {
    const core::Constraint& c = model.constraints[i];
    if (c.kind == core::Constraint::Kind::kQuatNorm)
    {
      used[i] = true;  // the free joint's quaternion
      continue;
    }
    if (c.kind == core::Constraint::Kind::kSpinLock)
      throw std::invalid_argument("MuJoCo peer: spin locks are for statics (constraint '" + c.name + "')");
    if (c.actuator < 0)
      continue;  // pins, joints and guides: mapConnects
    if (c.rows() != 1 || c.b.body >= 0 || c.a.body < 0)
      throw std::invalid_argument("MuJoCo peer: unsupported driven constraint '" + c.name +
                                  "' (one row of a body point against the ground expected)");
    used[i] = true;
    const Vec3 d = c.directions[0];
    int guide = -1;
    for (size_t j = 0; j < model.constraints.size(); ++j)
      if (j != i && isGuideOf(model.constraints[j], c))
        guide = static_cast<int>(j);
    const core::Body& body = model.bodies[c.a.body];
    const Vec3 p0 = core::pointPosition(model, c.a, model.q0);
    if (body.kind == core::BodyKind::kPointMass)
    {
      if (guide < 0)
        throw std::invalid_argument("MuJoCo peer: driven point mass '" + body.name +
                                    "' must be guided (it is moved kinematically)");
      used[guide] = true;
      DrivenMass dm;
      dm.body = c.a.body;
      dm.actuator = c.actuator;
      dm.p0 = p0 - c.a.local;
      dm.direction = d;
      dm.mass = body.mass;
      driven_of_body[c.a.body] = static_cast<int>(driven.size());
      driven.push_back(dm);
    }
    else
    {
      if (guide >= 0)
        used[guide] = true;
      Carrier cr;
      cr.constraint = static_cast<int>(i);
      cr.actuator = c.actuator;
      cr.p0 = p0;
      cr.direction = d;
      cr.guided = guide >= 0;
      cr.mass = options.carrier_mass_fraction * body.mass;
      carriers.push_back(cr);
    }
  }
  return used;
}

// The other constraints: ground pins and ball joints become connects; anything else is refused.
void MujocoPeer::Impl::mapConnects(const std::vector<bool>& used, Translation& tr)
{
  for (size_t i = 0; i < model.constraints.size(); ++i)
  {
    if (used[i])
      continue;
    const core::Constraint& c = model.constraints[i];
    const bool identity = c.rows() == 3 && c.directions[0] == Vec3::UnitX() && c.directions[1] == Vec3::UnitY() &&
                          c.directions[2] == Vec3::UnitZ() && c.offsets[0] == 0.0 && c.offsets[1] == 0.0 &&
                          c.offsets[2] == 0.0;
    if (!identity || c.a.body < 0)
      throw std::invalid_argument("MuJoCo peer: unsupported constraint '" + c.name +
                                  "' (ground pins, ball joints and driven nodes only)");
    if (driven_of_body[c.a.body] >= 0 || (c.b.body >= 0 && driven_of_body[c.b.body] >= 0))
      throw std::invalid_argument("MuJoCo peer: constraint '" + c.name + "' holds a driven point mass");
    tr.connects.push_back({ c.a.body, c.a.local, c.b.body, c.name });
  }
}

// Cables: runs of points between driven masses become tendons through sites, segments touching a driven mass
// (or fixed in space) are computed here.
void MujocoPeer::Impl::mapCables(Translation& tr)
{
  tr.tendons_of_cable.resize(model.cables.size());
  tr.segments_of_cable.resize(model.cables.size());
  for (size_t ci = 0; ci < model.cables.size(); ++ci)
  {
    const core::Cable& cable = model.cables[ci];
    std::vector<core::PointRef> run;
    const auto flush = [&]()
    {
      bool moving = false;
      for (const core::PointRef& p : run)
        moving = moving || p.body >= 0;
      if (run.size() >= 2 && moving)
      {
        TendonSpec t;
        t.name = "tendon" + std::to_string(tr.tendons.size());
        for (const core::PointRef& p : run)
          t.sites.push_back(siteFor(p));
        tr.tendons_of_cable[ci].push_back(static_cast<int>(tr.tendons.size()));
        tr.tendons.push_back(t);
      }
      else
        for (size_t k = 0; k + 1 < run.size(); ++k)
          tr.segments_of_cable[ci].push_back({ run[k], run[k + 1] });  // fixed in space: a constant length
      run.clear();
    };
    for (size_t k = 0; k < cable.points.size(); ++k)
    {
      const core::PointRef& p = cable.points[k];
      if (k > 0 && (drivenPoint(p) || drivenPoint(cable.points[k - 1])))
        tr.segments_of_cable[ci].push_back({ cable.points[k - 1], p });
      if (drivenPoint(p))
        flush();
      else
      {
        siteFor(p);
        run.push_back(p);
      }
    }
    flush();
  }
}

// The MJCF text of the translated scene.
std::string MujocoPeer::Impl::mjcf(const Translation& tr) const
{
  std::ostringstream x;
  x << "<mujoco model=\"" << (model.name.empty() ? "scene" : model.name) << "\">\n";
  writeHeader(x, tr);
  x << "  <worldbody>\n";
  writeBodies(x);
  writeCarriers(x);
  x << "  </worldbody>\n";
  writeEqualities(x, tr);
  writeTendons(x, tr);
  writeContactPairs(x);
  x << "</mujoco>\n";
  return x.str();
}

// Compiler, sizes, options (timestep, integrator, gravity, solver) and defaults.
void MujocoPeer::Impl::writeHeader(std::ostream& x, const Translation& tr) const
{
  const bool friction = hasFriction();
  const Vec3 gravity = model.gravity_enabled ? model.gravity : Vec3::Zero();
  const int n_pairs = pairCount();
  const int ncon_max = 2 * n_pairs + 4;
  const int njmax = 3 * static_cast<int>(tr.connects.size() + carriers.size()) +
                    (friction || model.ground.friction > 0.0 ? 3 : 1) * ncon_max + 16;
  const char* integrator = options.integrator == MujocoIntegrator::kEuler    ? "Euler" :
                           options.integrator == MujocoIntegrator::kImplicit ? "implicit" :
                                                                               "RK4";
  x << "  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n";
  x << "  <size njmax=\"" << njmax << "\" nconmax=\"" << ncon_max << "\"/>\n";
  x << "  <option timestep=\"" << num(options.timestep) << "\" integrator=\"" << integrator << "\" gravity=\""
    << vec(gravity) << "\" cone=\"elliptic\" solver=\"Newton\" iterations=\"" << options.solver_iterations
    << "\" tolerance=\"" << num(options.solver_tolerance) << "\"/>\n";
  x << "  <default><geom contype=\"0\" conaffinity=\"0\"/><site size=\"0.005\"/></default>\n";
}

// The sites on our body `body` (-1: the world).
void MujocoPeer::Impl::writeSites(std::ostream& x, int body, const std::string& indent) const
{
  for (const auto& [p, name] : site_names)
    if (p.body == body)
      x << indent << "<site name=\"" << name << "\" pos=\"" << vec(p.local) << "\"/>\n";
}

// The world's sites, then our bodies: struts (free joint, capsule) and point masses not driven (three slides),
// with their sites.
void MujocoPeer::Impl::writeBodies(std::ostream& x) const
{
  writeSites(x, -1, "    ");
  if (!groundBodies().empty())
    x << "    <geom name=\"ground\" type=\"plane\" size=\"0 0 1\" pos=\"0 0 " << num(model.ground.height) << "\"/>\n";
  const std::vector<int> on_ground = groundBodies();
  for (int i = 0; i < static_cast<int>(model.bodies.size()); ++i)
  {
    const core::Body& b = model.bodies[i];
    if (driven_of_body[i] >= 0)
      continue;
    const Vec3 r = model.q0.segment<3>(b.offset);
    x << "    <body name=\"body" << i << "\" pos=\"" << vec(r) << "\"";
    if (b.kind == core::BodyKind::kStrut)
    {
      const core::Vec4 th = model.q0.segment<4>(b.offset + 3);
      x << " quat=\"" << num(th(0)) << " " << num(th(1)) << " " << num(th(2)) << " " << num(th(3)) << "\">\n";
      x << "      <freejoint name=\"free" << i << "\"/>\n";
      x << "      <inertial pos=\"0 0 0\" mass=\"" << num(b.mass) << "\" diaginertia=\"" << vec(b.inertia) << "\"/>\n";
      x << "      <geom name=\"geom" << i << "\" type=\"capsule\" size=\"" << num(b.radius()) << " "
        << num(0.5 * b.length) << "\"/>\n";
    }
    else
    {
      x << ">\n";
      for (const char* axis : { "1 0 0", "0 1 0", "0 0 1" })
        x << "      <joint type=\"slide\" axis=\"" << axis << "\"/>\n";
      const double j = 1e-6 * b.mass;
      x << "      <inertial pos=\"0 0 0\" mass=\"" << num(b.mass) << "\" diaginertia=\"" << num(j) << " " << num(j)
        << " " << num(j) << "\"/>\n";
      if (std::binary_search(on_ground.begin(), on_ground.end(), i))
        x << "      <geom name=\"geom" << i << "\" type=\"sphere\" size=\"" << num(groundContactOf(i).radius)
          << "\"/>\n";
    }
    writeSites(x, i, "      ");
    x << "    </body>\n";
  }
}

// The carriers of driven strut ends: a slide along the drive, two across it when no guide holds the end.
void MujocoPeer::Impl::writeCarriers(std::ostream& x) const
{
  for (size_t k = 0; k < carriers.size(); ++k)
  {
    const Carrier& cr = carriers[k];
    const core::Constraint& c = model.constraints[cr.constraint];
    const Vec3 d = cr.direction;
    x << "    <body name=\"carrier" << k << "\" pos=\"" << vec(cr.p0) << "\">\n";
    x << "      <joint name=\"drive" << k << "\" type=\"slide\" axis=\"" << vec(d) << "\" armature=\""
      << num(kDriveArmature * model.bodies[c.a.body].mass) << "\"/>\n";
    if (!cr.guided)
    {
      const Vec3 any = std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
      const Vec3 across1 = d.cross(any).normalized(), across2 = d.cross(across1);
      x << "      <joint type=\"slide\" axis=\"" << vec(across1) << "\"/>\n";
      x << "      <joint type=\"slide\" axis=\"" << vec(across2) << "\"/>\n";
    }
    const double j = 1e-6 * std::max(cr.mass, 1e-9);
    x << "      <inertial pos=\"0 0 0\" mass=\"" << num(std::max(cr.mass, 1e-9)) << "\" diaginertia=\"" << num(j) << " "
      << num(j) << " " << num(j) << "\"/>\n";
    x << "    </body>\n";
  }
}

// Equality connects: pins and joints, then each driven strut end to its carrier (near-hard, solref from the
// timestep).
void MujocoPeer::Impl::writeEqualities(std::ostream& x, const Translation& tr) const
{
  if (tr.connects.empty() && carriers.empty())
    return;
  const std::string eq_sol = " solref=\"" + num(options.equality_timeconst * options.timestep) + " 1\" solimp=\"" +
                             num(options.equality_impedance) + " " + num(options.equality_impedance) + " 0.001 0.5 2\"";
  x << "  <equality>\n";
  for (const Connect& c : tr.connects)
  {
    x << "    <connect name=\"" << c.name << "\" body1=\"body" << c.a_body << "\"";
    if (c.b_body >= 0)
      x << " body2=\"body" << c.b_body << "\"";
    x << " anchor=\"" << vec(c.a_local) << "\"" << eq_sol << "/>\n";
  }
  for (size_t k = 0; k < carriers.size(); ++k)
  {
    const core::Constraint& c = model.constraints[carriers[k].constraint];
    x << "    <connect name=\"drive" << k << "\" body1=\"body" << c.a.body << "\" body2=\"carrier" << k
      << "\" anchor=\"" << vec(c.a.local) << "\"" << eq_sol << "/>\n";
  }
  x << "  </equality>\n";
}

// Spatial tendons through the sites, each with a motor whose control the force evaluation sets to -T.
void MujocoPeer::Impl::writeTendons(std::ostream& x, const Translation& tr) const
{
  if (tr.tendons.empty())
    return;
  x << "  <tendon>\n";
  for (const TendonSpec& t : tr.tendons)
  {
    x << "    <spatial name=\"" << t.name << "\" limited=\"false\" width=\"0.003\">\n";
    for (const std::string& s : t.sites)
      x << "      <site site=\"" << s << "\"/>\n";
    x << "    </spatial>\n";
  }
  x << "  </tendon>\n  <actuator>\n";
  for (const TendonSpec& t : tr.tendons)
    x << "    <motor name=\"pull_" << t.name << "\" tendon=\"" << t.name << "\" gear=\"1\" ctrllimited=\"false\"/>\n";
  x << "  </actuator>\n";
}

// Capsule pairs for the checked pairs only; their solref is set after compiling (setContactParameters).
void MujocoPeer::Impl::writeContactPairs(std::ostream& x) const
{
  if (pairCount() == 0)
    return;
  const auto pair = [&](const std::string& geom1, int body, double mu)
  {
    x << "    <pair geom1=\"" << geom1 << "\" geom2=\"geom" << body << "\" condim=\"" << (mu > 0.0 ? 3 : 1)
      << "\" friction=\"" << num(mu) << " " << num(mu) << " 0 0 0\" solref=\"-1 -1\" solimp=\""
      << num(options.contact_impedance) << " " << num(options.contact_impedance)
      << " 0.001 0.5 2\" margin=\"0\" gap=\"0\"/>\n";
  };
  x << "  <contact>\n";
  if (hasContact())
    for (const core::StrutPair& p : checked)
      pair("geom" + std::to_string(p.body_a), p.body_b, model.contact.friction);
  for (int body : groundBodies())
    pair("ground", body, model.ground.friction);
  x << "  </contact>\n";
}

// MuJoCo's ids of our bodies, the sites, and each cable's tendons, motors and computed segments.
void MujocoPeer::Impl::findIds(const mjModel* m, const Translation& tr)
{
  for (int i = 0; i < static_cast<int>(model.bodies.size()); ++i)
    if (driven_of_body[i] < 0)
      body_id[i] = mj_name2id(m, mjOBJ_BODY, ("body" + std::to_string(i)).c_str());
  for (const auto& [p, name] : site_names)
    site_ids.push_back(mj_name2id(m, mjOBJ_SITE, name.c_str()));
  const auto siteId = [&](const core::PointRef& p)
  {
    for (size_t k = 0; k < site_names.size(); ++k)
      if (samePoint(site_names[k].first, p))
        return site_ids[k];
    return -1;
  };
  cables.resize(model.cables.size());
  for (size_t ci = 0; ci < model.cables.size(); ++ci)
  {
    for (int t : tr.tendons_of_cable[ci])
    {
      cables[ci].tendons.push_back(mj_name2id(m, mjOBJ_TENDON, tr.tendons[t].name.c_str()));
      cables[ci].actuators.push_back(mj_name2id(m, mjOBJ_ACTUATOR, ("pull_" + tr.tendons[t].name).c_str()));
    }
    for (const SegmentSpec& s : tr.segments_of_cable[ci])
    {
      Segment seg;
      for (int e = 0; e < 2; ++e)
      {
        const core::PointRef& p = e == 0 ? s.a : s.b;
        End& end = e == 0 ? seg.a : seg.b;
        if (drivenPoint(p))
          end.driven = driven_of_body[p.body];
        else
          end.site = siteId(p);
      }
      cables[ci].segments.push_back(seg);
    }
  }
}

// The carriers' drive slides (ids, inertia along the drive) and the constraint weights of the struts they carry.
void MujocoPeer::Impl::setUpCarriers(mjModel* m)
{
  for (size_t k = 0; k < carriers.size(); ++k)
  {
    const int joint = mj_name2id(m, mjOBJ_JOINT, ("drive" + std::to_string(k)).c_str());
    carriers[k].drive_qpos = m->jnt_qposadr[joint];
    carriers[k].drive_dof = m->jnt_dofadr[joint];
    carriers[k].drive_inertia = m->dof_armature[carriers[k].drive_dof] + std::max(carriers[k].mass, 1e-9);
    carriers[k].equality = mj_name2id(m, mjOBJ_EQUALITY, ("drive" + std::to_string(k)).c_str());
    // MuJoCo regularizes a constraint row with R = (1 - d) / d * diagApprox, diagApprox from the bodies'
    // mean inverse weights at qpos0; a light carrier's (1 / m_c, and it cannot even move along the drive)
    // would make the drive soft along it, so the carrier takes the weights of the strut it carries
    const int carrier = mj_name2id(m, mjOBJ_BODY, ("carrier" + std::to_string(k)).c_str());
    const int strut = body_id[model.constraints[carriers[k].constraint].a.body];
    m->body_invweight0[2 * carrier] = m->body_invweight0[2 * strut];
    m->body_invweight0[2 * carrier + 1] = m->body_invweight0[2 * strut + 1];
  }
}

// Contact: linear spring-dashpot through the direct solref, per unit of MuJoCo's approximate mass, and the
// friction rows' impratio.
void MujocoPeer::Impl::setContactParameters(mjModel* m)
{
  pair_of_checked.assign(checked.size(), -1);
  pair_stiffness.assign(checked.size(), 0.0);
  pair_damping.assign(checked.size(), 0.0);
  // a linear oscillator rebounds with e = exp(-zeta pi / sqrt(1 - zeta^2))
  const auto dampingRatio = [](double restitution)
  {
    const double ce = std::clamp(restitution, 0.0, 1.0);
    return ce <= 0.0 ? 1.0 : -std::log(ce) / std::sqrt(M_PI * M_PI + std::log(ce) * std::log(ce));
  };
  double impratio = 1.0;
  // the compiler sorts the pairs (by body): pair k of the text is found by its geoms
  const auto compiled = [&](const std::string& geom1, int body)
  {
    const int g1 = mj_name2id(m, mjOBJ_GEOM, geom1.c_str());
    const int g2 = mj_name2id(m, mjOBJ_GEOM, ("geom" + std::to_string(body)).c_str());
    for (int j = 0; j < m->npair; ++j)
      if ((m->pair_geom1[j] == g1 && m->pair_geom2[j] == g2) || (m->pair_geom1[j] == g2 && m->pair_geom2[j] == g1))
        return j;
    throw std::logic_error("MuJoCo has no pair of " + geom1 + " and geom" + std::to_string(body));
  };
  text_solref.clear();
  // a pair's linear spring-dashpot (K_lin, C_lin): our linear law's own k and c (MuJoCo's contact is then ours,
  // friction aside), or the secant of a Hertz stiffness k (N/m^1.5) at the force scale f with our restitution
  const auto linearOf = [&](core::ContactLaw law, double k, double f, double inv_mass, double restitution,
                            double linear_k, double linear_c)
  {
    if (law == core::ContactLaw::kLinear)
      return std::make_pair(linear_k, linear_c);
    const double k_lin = std::cbrt(k * k * f);  // K^(2/3) F*^(1/3)
    return std::make_pair(k_lin, 2.0 * dampingRatio(restitution) * std::sqrt(k_lin / inv_mass));
  };
  // one pair's solref for (K_lin, C_lin). Friction rows damp the slip with impratio * C_lin (elliptic cone, no
  // friction solref in 2.2.2): our regularized Coulomb reaches mu F_N at v1, so that slope is matched at the force
  // scale f (the largest impratio any pair needs)
  // (a value MuJoCo cannot take is refused, naming the contact and where it comes from: the text would hold
  // "-inf nan", which MuJoCo reads as it likes)
  const auto set = [&](int j, std::pair<double, double> linear, double f, double inv_mass, double mu, double v_ramp,
                       const std::string& what, const std::string& source)
  {
    const auto [k_lin, c_lin] = linear;
    const double k_ref = -k_lin * inv_mass, c_ref = -c_lin * inv_mass;
    if (!std::isfinite(k_ref) || !std::isfinite(c_ref))
      throw std::invalid_argument("MuJoCo peer: " + what + ": its solref (-K/m, -C/m) = (" +
                                  core::shortestNumber(k_ref) + ", " + core::shortestNumber(c_ref) +
                                  ") is not finite: stiffness K = " + core::shortestNumber(k_lin) +
                                  " N/m, damping C = " + core::shortestNumber(c_lin) + " N s/m from " + source +
                                  ", over the mass " + core::roundedNumber(1.0 / inv_mass, 6) + " kg");
    m->pair_solref[2 * j] = k_ref;
    m->pair_solref[2 * j + 1] = c_ref;
    text_solref.emplace_back(k_ref, c_ref);
    if (mu > 0.0 && c_lin > 0.0)
      impratio = std::max(impratio, mu * f / (std::max(1e-6, v_ramp) * c_lin));
    if (!std::isfinite(impratio))
      throw std::invalid_argument("MuJoCo peer: " + what +
                                  ": the friction rows' impratio mu F / (v C) = " + core::shortestNumber(mu) + " * " +
                                  core::shortestNumber(f) + " N / (" + core::shortestNumber(std::max(1e-6, v_ramp)) +
                                  " m/s * " + core::shortestNumber(c_lin) + " N s/m) is not finite");
    return std::make_pair(k_lin, c_lin);
  };
  // where a pair's (K, C) come from, for a refusal
  const auto sourceOf = [](core::ContactLaw law, const std::string& section, double k, double f)
  {
    return law == core::ContactLaw::kLinear ?
               section + ".stiffness and " + section + ".damping (law 'linear')" :
               "the Hertz stiffness " + core::roundedNumber(k, 6) +
                   " N/m^1.5 (the materials' youngs_modulus) at the force scale F* = " + core::shortestNumber(f) + " N";
  };
  if (hasContact())
    for (int i = 0; i < static_cast<int>(checked.size()); ++i)
    {
      const core::StrutPair& p = checked[i];
      const int j = compiled("geom" + std::to_string(p.body_a), p.body_b);
      const double inv_mass = m->body_invweight0[2 * body_id[p.body_a]] + m->body_invweight0[2 * body_id[p.body_b]];
      const core::ContactSettings& c = model.contact;
      const auto [k_lin, c_lin] =
          set(j,
              linearOf(c.law, p.stiffness90, options.contact_force, inv_mass, c.restitution, c.linear_stiffness,
                       c.linear_damping),
              options.contact_force, inv_mass, c.friction, c.slip_velocity - c.stick_velocity,
              "the contact of struts '" + model.bodies[p.body_a].name + "' and '" + model.bodies[p.body_b].name + "'",
              sourceOf(c.law, "contact", p.stiffness90, options.contact_force));
      pair_of_checked[i] = j;
      pair_stiffness[i] = k_lin;
      pair_damping[i] = c_lin;
    }
  double weight = 0.0;
  for (const core::Body& b : model.bodies)
    weight += b.mass * model.gravity.norm();
  const double ground_force = options.ground_force > 0.0            ? options.ground_force :
                              model.gravity_enabled && weight > 0.0 ? weight / 3.0 :
                                                                      options.contact_force;
  for (int body : groundBodies())
  {
    const core::GroundContact& g = groundContactOf(body);
    const core::GroundSettings& gs = model.ground;
    const double inv_mass = m->body_invweight0[2 * body_id[body]];
    set(compiled("ground", body),
        linearOf(gs.law, g.stiffness, ground_force, inv_mass, gs.restitution, gs.linear_stiffness, gs.linear_damping),
        ground_force, inv_mass, gs.friction, gs.slip_velocity - gs.stick_velocity,
        "the ground contact of '" + model.bodies[body].name + "'",
        sourceOf(gs.law, "ground", g.stiffness, ground_force));
  }
  m->opt.impratio = impratio;
}

// Our model mapped (constraints, then cables), written as MJCF, compiled by MuJoCo, then completed in the
// compiled model (ids, carriers, contact parameters) and put in its initial state.
MujocoPeer::MujocoPeer(const core::Model& model, const MujocoOptions& options)
  : impl_(std::make_unique<Impl>(model, options))
{
  Impl& im = *impl_;
  Impl::Translation tr;
  im.mapConnects(im.mapDrivenNodes(), tr);
  im.mapCables(tr);
  xml_ = im.mjcf(tr);
  refuseNonFinite(xml_);
  m_ = options.xml_file.empty() ? loadMjcf(xml_) : loadMjcfFile(options.xml_file);
  d_ = mj_makeData(m_);
  im.findIds(m_, tr);
  im.setUpCarriers(m_);
  im.setContactParameters(m_);
  reset();
}

std::string MujocoPeer::exportXml() const
{
  // the compiled model's contact parameters written into the text: each pair's solref in its <pair> (in the
  // order of the pairs), the friction rows' impratio in <option>
  std::string out = xml_;
  const std::string placeholder = "solref=\"-1 -1\"";
  size_t at = 0;
  for (const auto& [k, c] : impl_->text_solref)
  {
    at = out.find(placeholder, at);
    if (at == std::string::npos)
      break;
    const std::string solref = "solref=\"" + num(k) + " " + num(c) + "\"";
    out.replace(at, placeholder.size(), solref);
    at += solref.size();
  }
  const size_t option = out.find("<option ");
  if (option != std::string::npos)
    out.insert(option + 8, "impratio=\"" + num(m_->opt.impratio) + "\" ");
  std::string name = impl_->model.name;  // "--" may not appear in an XML comment
  for (size_t dash = name.find("--"); dash != std::string::npos; dash = name.find("--", dash))
    name.replace(dash, 2, "- ");
  const std::string header =
      "<!-- active_tensegrity's MuJoCo translation of the scene '" + name +
      "' (tensegrity_export).\n"
      "  Struts are capsules on free joints with our masses and inertias; pins and ball joints are equality\n"
      "  connects; contact is a linear spring-dashpot per checked pair and per body on the ground plane (solref in\n"
      "  MuJoCo's direct format).\n"
      "  Cables and springs are spatial tendons, each carrying a motor actuator whose control must be set to\n"
      "  -T every step, T = k (l - l0) + c l_dot when positive (tension only; l0, k and c from the scene).\n"
      "  Driven strut ends ride on carrier bodies whose drive joint follows the actuation; driven point\n"
      "  masses are not bodies here. Loaded alone, with no controls, the cables carry nothing and the\n"
      "  drives hold still. -->\n";
  const size_t root = out.find("<mujoco");
  refuseNonFinite(out);
  out.insert(root == std::string::npos ? 0 : root, header);
  return out;
}

MujocoPeer::~MujocoPeer()
{
  if (d_)
    mj_deleteData(d_);
  if (m_)
    mj_deleteModel(m_);
}

void MujocoPeer::reset()
{
  mj_resetData(m_, d_);
  setDrives();
  for (int w = 0; w < mjNWARNING; ++w)
    d_->warning[w].number = 0;
  message_.clear();
  diverged_ = false;
  forward();
}

void MujocoPeer::setDrives()
{
  for (const Impl::Carrier& cr : impl_->carriers)
  {
    const core::ActuationValue u = impl_->value(cr.actuator, d_->time);
    d_->qpos[cr.drive_qpos] = u.value;
    d_->qvel[cr.drive_dof] = u.rate;
  }
}

void MujocoPeer::forward()
{
  setDrives();
  Active active(this);
  mj_forward(m_, d_);
}

double MujocoPeer::time() const
{
  return d_->time;
}

bool MujocoPeer::step()
{
  setDrives();
  int before[mjNWARNING];
  for (int w = 0; w < mjNWARNING; ++w)
    before[w] = d_->warning[w].number;
  const double t0 = d_->time;
  {
    Active active(this);
    mj_step(m_, d_);
  }
  for (int w = 0; w < mjNWARNING; ++w)
    if (d_->warning[w].number > before[w])
    {
      message_ = std::string("MuJoCo warning '") + kWarningNames[w] + "' in the step from t = " + num(t0) + " s" +
                 (g_warning.empty() ? "" : ": " + g_warning);
      // MuJoCo's own signs of an unstable simulation (it resets the state after them)
      diverged_ = w == mjWARN_BADQPOS || w == mjWARN_BADQVEL || w == mjWARN_BADQACC || w == mjWARN_BADCTRL;
      return false;
    }
  for (int i = 0; i < m_->nq; ++i)
    if (!std::isfinite(d_->qpos[i]))
    {
      message_ = "non-finite position in the step from t = " + num(t0) + " s";
      diverged_ = true;
      return false;
    }
  for (int i = 0; i < m_->nv; ++i)
    if (!std::isfinite(d_->qvel[i]))
    {
      message_ = "non-finite velocity in the step from t = " + num(t0) + " s";
      diverged_ = true;
      return false;
    }
  return true;
}

void MujocoPeer::evaluateForces()
{
  Impl& im = *impl_;
  const core::Model& model = im.model;
  const double t = d_->time;
  im.u.assign(model.actuators.size(), core::ActuationValue{});
  for (size_t a = 0; a < model.actuators.size(); ++a)
    im.u[a] = im.value(static_cast<int>(a), t);
  mju_zero(d_->qfrc_applied, m_->nv);
  // the drives' carriers follow s_dd between the steps
  for (const Impl::Carrier& cr : im.carriers)
    d_->qfrc_applied[cr.drive_dof] = cr.drive_inertia * im.u[cr.actuator].accel;
  for (size_t ci = 0; ci < model.cables.size(); ++ci)
  {
    const core::Cable& cable = model.cables[ci];
    Impl::CableMap& cm = im.cables[ci];
    double length = 0.0, rate = 0.0;
    for (int t_id : cm.tendons)
    {
      length += d_->ten_length[t_id];
      rate += d_->ten_velocity[t_id];
    }
    for (Impl::Segment& s : cm.segments)
    {
      Vec3 p[2], v[2];
      for (int e = 0; e < 2; ++e)
      {
        const Impl::End& end = e == 0 ? s.a : s.b;
        if (end.driven >= 0)
        {
          const Impl::DrivenMass& dm = im.driven[end.driven];
          p[e] = im.drivenPosition(end.driven, t);
          v[e] = im.u[dm.actuator].rate * dm.direction;
        }
        else
        {
          mjtNum res[6];
          mj_objectVelocity(m_, d_, mjOBJ_SITE, end.site, res, 0);
          p[e] = Vec3(d_->site_xpos[3 * end.site], d_->site_xpos[3 * end.site + 1], d_->site_xpos[3 * end.site + 2]);
          v[e] = Vec3(res[3], res[4], res[5]);
        }
      }
      const Vec3 dp = p[1] - p[0];
      s.length = dp.norm();
      s.n = s.length > 0.0 ? Vec3(dp / s.length) : Vec3::Zero();
      length += s.length;
      rate += s.n.dot(v[1] - v[0]);
    }
    // our evaluateCable: pull-in, EA kept, damping on the material stretch rate, tension only
    double pull = 0.0, pull_rate = 0.0;
    if (cable.actuator >= 0)
    {
      pull = im.u[cable.actuator].value;
      pull_rate = im.u[cable.actuator].rate;
    }
    const double rest = cable.rest_length - pull;
    const double k = cable.area > 0.0 ? cable.stiffness * cable.rest_length / rest : cable.stiffness;
    const double c = model.damping_enabled ? cable.damping : 0.0;
    const double stretch = length - rest;
    double tension = k * stretch + c * (rate + pull_rate);
    if (length <= 0.0 || (cable.tension_only && (stretch <= 0.0 || tension <= 0.0)))
      tension = 0.0;
    cm.length = length;
    cm.tension = tension;
    for (int a : cm.actuators)
      d_->ctrl[a] = -tension;
    // segments to driven masses pull their other end (a site on a moving body) along the segment
    for (const Impl::Segment& s : cm.segments)
      for (int e = 0; e < 2; ++e)
      {
        const Impl::End& end = e == 0 ? s.a : s.b;
        if (end.site < 0 || m_->site_bodyid[end.site] == 0 || tension == 0.0)
          continue;
        const Vec3 f = (e == 0 ? tension : -tension) * s.n;
        mjtNum force[3] = { f.x(), f.y(), f.z() }, torque[3] = { 0.0, 0.0, 0.0 };
        mj_applyFT(m_, d_, force, torque, d_->site_xpos + 3 * end.site, m_->site_bodyid[end.site], d_->qfrc_applied);
      }
  }
}

core::Vec3 MujocoPeer::bodyPosition(int body) const
{
  const Impl& im = *impl_;
  if (im.driven_of_body[body] >= 0)
    return im.drivenPosition(im.driven_of_body[body], d_->time);
  const int id = im.body_id[body];
  return Vec3(d_->xpos[3 * id], d_->xpos[3 * id + 1], d_->xpos[3 * id + 2]);
}

core::Vec3 MujocoPeer::pointPosition(const core::PointRef& point) const
{
  const Impl& im = *impl_;
  if (point.body < 0)
    return point.local;
  if (im.driven_of_body[point.body] >= 0)
    return bodyPosition(point.body) + point.local;
  const int id = im.body_id[point.body];
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> rot(d_->xmat + 9 * id);
  return bodyPosition(point.body) + rot * point.local;
}

double MujocoPeer::cableLength(int cable) const
{
  return impl_->cables[cable].length;
}

double MujocoPeer::cableTension(int cable) const
{
  return impl_->cables[cable].tension;
}

double MujocoPeer::actuationForce(int actuator) const
{
  const Impl& im = *impl_;
  const core::Model& model = im.model;
  const core::Actuator& act = model.actuators[actuator];
  double force = 0.0;
  for (int c : act.cables)
    force += im.cables[c].tension;
  const core::ActuationValue u = im.value(actuator, d_->time);
  for (size_t k = 0; k < im.driven.size(); ++k)
  {
    const Impl::DrivenMass& dm = im.driven[k];
    if (dm.actuator != actuator)
      continue;
    // m s_dd d = F d + cable forces + m g (+ guide forces across d)
    const Vec3 g = model.gravity_enabled ? model.gravity : Vec3::Zero();
    double f = dm.mass * (u.accel - g.dot(dm.direction));
    for (const Impl::CableMap& cm : im.cables)
      for (const Impl::Segment& s : cm.segments)
      {
        // the cable pulls each end towards the other: on a, +T n; on b, -T n
        if (s.a.driven == static_cast<int>(k))
          f -= cm.tension * s.n.dot(dm.direction);
        if (s.b.driven == static_cast<int>(k))
          f += cm.tension * s.n.dot(dm.direction);
      }
    force += f;
  }
  for (const Impl::Carrier& cr : im.carriers)
  {
    if (cr.actuator != actuator)
      continue;
    // the connect's force on body1 (the strut end) is efc_force (Jacobian of p1 - p2)
    for (int i = 0; i < d_->nefc; ++i)
      if (d_->efc_type[i] == mjCNSTR_EQUALITY && d_->efc_id[i] == cr.equality)
      {
        force += Vec3(d_->efc_force[i], d_->efc_force[i + 1], d_->efc_force[i + 2]).dot(cr.direction);
        break;
      }
  }
  return force;
}

namespace
{
// the normal forces of the current contacts (N), combined by `fold`
template <typename Fold>
double foldContactForces(const mjModel* m, mjData* d, Fold fold)
{
  double f = 0.0;
  for (int i = 0; i < d->ncon; ++i)
  {
    if (d->contact[i].efc_address < 0)
      continue;
    mjtNum r[6];
    mj_contactForce(m, d, i, r);
    f = fold(f, r[0]);
  }
  return f;
}
}  // namespace

double MujocoPeer::maxContactForce() const
{
  return foldContactForces(m_, d_, [](double a, double b) { return std::max(a, b); });
}

double MujocoPeer::contactForceSum() const
{
  return foldContactForces(m_, d_, [](double a, double b) { return a + b; });
}

double MujocoPeer::totalMass() const
{
  double m = 0.0;
  for (int b = 1; b < m_->nbody; ++b)
    m += m_->body_mass[b];
  return m;
}

double MujocoPeer::carrierMass() const
{
  double m = 0.0;
  for (const Impl::Carrier& cr : impl_->carriers)
    m += std::max(cr.mass, 1e-9);
  return m;
}

double MujocoPeer::contactStiffness(int pair) const
{
  return impl_->pair_stiffness[pair];
}

double MujocoPeer::contactDamping(int pair) const
{
  return impl_->pair_damping[pair];
}

int MujocoPeer::bodyId(int body) const
{
  return impl_->body_id[body];
}

const std::vector<int>& MujocoPeer::tendonIds(int cable) const
{
  return impl_->cables[cable].tendons;
}

int MujocoPeer::pairCount() const
{
  return m_->npair;
}

MujocoTrace runMujoco(const core::Model& model, const MujocoOptions& options)
{
  using Clock = std::chrono::steady_clock;
  MujocoTrace tr;
  if (model.analysis.type != core::AnalysisType::kDynamic)
    throw std::invalid_argument("MuJoCo peer: the scene's analysis must be dynamic");
  MujocoPeer peer(model, options);
  tr.size = core::structureSize(model, model.q0);
  // the pins and ball joints (three rows of a point on a point, no drive): how far their two points part
  std::vector<const core::Constraint*> joints;
  for (const core::Constraint& c : model.constraints)
    if (c.kind == core::Constraint::Kind::kPoints && c.actuator < 0 && c.directions.size() == 3)
      joints.push_back(&c);
  const core::Constraint* worst = nullptr;
  const double dt = options.timestep;
  const long n_steps = std::lround(std::ceil(model.analysis.duration / dt - 1e-9));
  const double interval = model.analysis.output_interval > 0.0 ? model.analysis.output_interval : dt;
  const auto output = [&]()
  {
    peer.forward();
    tr.t.push_back(peer.time());
    tr.force.push_back(model.actuators.empty() ? 0.0 : peer.actuationForce(0));
    std::vector<double> h;
    const auto height = [&](const std::vector<int>& nodes)
    {
      double top = -INFINITY;
      for (int n : nodes)
        top = std::max(top, peer.pointPosition(model.nodes[n].point).z());
      return top - model.ground_level;
    };
    if (model.layers.empty())
      h.push_back(height(model.height_nodes));
    for (const core::OutputLayer& layer : model.layers)
      h.push_back(height(layer.nodes));
    tr.heights.push_back(h);
    std::vector<core::Vec3> p;
    for (size_t b = 0; b < model.bodies.size(); ++b)
      p.push_back(peer.bodyPosition(static_cast<int>(b)));
    tr.positions.push_back(p);
    const double f = peer.maxContactForce();
    if (f > tr.peak)
    {
      tr.peak = f;
      tr.peak_t = peer.time();
    }
    for (const core::Constraint* c : joints)
    {
      const double drift = (peer.pointPosition(c->a) - peer.pointPosition(c->b)).norm();
      if (!(drift <= tr.joint_drift))  // (NaN included)
      {
        tr.joint_drift = drift;
        worst = c;
      }
    }
  };
  // a run whose pins and joints have come apart is no longer the structure, however finite its numbers
  const auto torn = [&]()
  {
    if (!(tr.joint_drift > kMaxJointDrift * tr.size))
      return false;
    tr.status = "diverged";
    tr.message = "the joint '" + (worst ? worst->name : std::string("?")) + "' came apart by " +
                 core::roundedNumber(tr.joint_drift, 3) + " m at t = " + core::roundedNumber(peer.time(), 6) +
                 " s, more than " + core::shortestNumber(kMaxJointDrift) + " of the structure's size (" +
                 core::roundedNumber(tr.size, 3) + " m)";
    return true;
  };
  output();
  double next_output = interval;
  for (long k = 1; k <= n_steps; ++k)
  {
    const double before = peer.time();
    const Clock::time_point t0 = Clock::now();
    const bool ok = peer.step();
    tr.wall_time += std::chrono::duration<double>(Clock::now() - t0).count();
    ++tr.steps;
    tr.solver_iterations += peer.mujocoData()->solver_iter;
    if (!ok)
    {
      tr.status = peer.diverged() ? "diverged" : "mujoco_failed";
      tr.message = peer.message();
      break;
    }
    // the step's forces are those of its start
    const double f = peer.maxContactForce();
    if (f > tr.peak)
    {
      tr.peak = f;
      tr.peak_t = before;
    }
    tr.impulse += peer.contactForceSum() * (peer.time() - before);
    if (k * dt >= next_output - 1e-9 * dt || k == n_steps)
    {
      output();
      next_output += interval;
      if (torn())
        break;
    }
  }
  return tr;
}

}  // namespace active_tensegrity::tools
