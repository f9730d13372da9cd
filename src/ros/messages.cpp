#include "active_tensegrity/ros/messages.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <utility>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/contact.h"

namespace active_tensegrity::ros_layer
{
namespace
{
// geometry_msgs Point or Vector3 from a vector
template <typename Msg>
Msg xyz(const core::Vec3& v)
{
  Msg m;
  m.x = v.x();
  m.y = v.y();
  m.z = v.z();
  return m;
}

geometry_msgs::Point point(const core::Vec3& v)
{
  return xyz<geometry_msgs::Point>(v);
}

geometry_msgs::Vector3 vector(const core::Vec3& v)
{
  return xyz<geometry_msgs::Vector3>(v);
}

std_msgs::ColorRGBA rgba(float r, float g, float b, float a = 1.0f)
{
  std_msgs::ColorRGBA c;
  c.r = r;
  c.g = g;
  c.b = b;
  c.a = a;
  return c;
}

// blue (0) -> green (0.5) -> red (1)
std_msgs::ColorRGBA tensionColour(double x)
{
  x = std::clamp(x, 0.0, 1.0);
  if (x < 0.5)
    return rgba(0.0f, static_cast<float>(2.0 * x), static_cast<float>(1.0 - 2.0 * x));
  return rgba(static_cast<float>(2.0 * x - 1.0), static_cast<float>(2.0 - 2.0 * x), 0.0f);
}

visualization_msgs::Marker marker(const std::string& frame, const ros::Time& stamp, const std::string& ns, int id,
                                  int type)
{
  visualization_msgs::Marker m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.ns = ns;
  m.id = id;
  m.type = type;
  m.action = visualization_msgs::Marker::ADD;
  m.pose.orientation.w = 1.0;
  m.frame_locked = false;
  return m;
}

geometry_msgs::Quaternion orientation(const core::Body& b, const Eigen::VectorXd& q)
{
  geometry_msgs::Quaternion out;
  out.w = 1.0;
  if (b.kind != core::BodyKind::kStrut)
    return out;
  const Eigen::Quaterniond e = core::toEigenQuaternion(q.segment<4>(b.offset + 3).normalized());
  out.x = e.x();
  out.y = e.y();
  out.z = e.z();
  out.w = e.w();
  return out;
}
}  // namespace

std::string bodyFrame(const core::Model& model, int body, const std::string& tf_prefix)
{
  return tf_prefix.empty() ? model.bodies[body].name : tf_prefix + "/" + model.bodies[body].name;
}

MessageBuilder::MessageBuilder(const core::Model& model, std::string frame_id, MarkerOptions options,
                               std::string tf_prefix)
  : model_(model), frame_id_(std::move(frame_id)), options_(options), tf_prefix_(std::move(tf_prefix))
{
  core::Vec3 centre = core::Vec3::Zero();
  for (const core::Body& b : model.bodies)
    centre += model.q0.segment<3>(b.offset) / static_cast<double>(model.bodies.size());
  ground_centre_ = core::Vec3(centre.x(), centre.y(), model.ground.height - 0.005);  // the slab is 1 cm thick
}

void MessageBuilder::clearMarkers()
{
  arrow_shown_.clear();
  clear_all_ = true;
}

Snapshot MessageBuilder::build(const core::State& state, const ros::Time& stamp,
                               const std::vector<core::ContactPairState>* given, bool markers)
{
  Snapshot out;
  const Eigen::VectorXd& q = state.q;

  // tf: world -> every body, at its centre of mass (struts: body z along the axis)
  for (size_t i = 0; i < model_.bodies.size(); ++i)
  {
    const core::Body& b = model_.bodies[i];
    geometry_msgs::TransformStamped t;
    t.header.stamp = stamp;
    t.header.frame_id = frame_id_;
    t.child_frame_id = bodyFrame(model_, static_cast<int>(i), tf_prefix_);
    t.transform.translation = vector(q.segment<3>(b.offset));
    t.transform.rotation = orientation(b, q);
    out.transforms.push_back(t);
  }

  std::vector<core::ContactPairState> searched;
  if (!given)
    searched = core::activeContacts(model_, state);
  const std::vector<core::ContactPairState>& contacts = given ? *given : searched;
  out.contacts.header.stamp = stamp;
  out.contacts.header.frame_id = frame_id_;
  for (const core::ContactPairState& c : contacts)
  {
    active_tensegrity::Contact m;
    m.strut_a = core::contactBodyName(model_, c.body_a);
    m.strut_b = core::contactBodyName(model_, c.body_b);
    m.point_a = point(c.point_a);
    m.point_b = point(c.point_b);
    m.normal = vector(c.normal);
    m.penetration = c.penetration;
    m.penetration_rate = c.penetration_rate;
    m.normal_force = c.normal_force;
    m.friction_force = vector(c.friction_on_a);
    out.contacts.contacts.push_back(m);
  }

  const std::vector<core::CableState> cables = core::cableStates(model_, state);
  out.cables.header.stamp = stamp;
  out.cables.header.frame_id = frame_id_;
  for (size_t i = 0; i < cables.size(); ++i)
  {
    active_tensegrity::Cable m;
    m.name = model_.cables[i].name;
    m.length = cables[i].length;
    m.rest_length = cables[i].rest_length;
    m.tension = cables[i].tension;
    m.slack = cables[i].slack;
    out.cables.cables.push_back(m);
  }
  out.struts.header.stamp = stamp;
  out.struts.header.frame_id = frame_id_;
  const std::vector<double> axial = core::strutAxialForces(model_, state);
  for (size_t b = 0; b < model_.bodies.size(); ++b)
    if (model_.bodies[b].kind == core::BodyKind::kStrut)
    {
      const core::Body& body = model_.bodies[b];
      out.struts.names.push_back(body.name);
      out.struts.axial_forces.push_back(axial[b]);
      const int index = static_cast<int>(b);
      out.struts.start.push_back(
          point(core::pointPosition(model_, core::PointRef{ index, core::Vec3(0.0, 0.0, -0.5 * body.length) }, q)));
      out.struts.end.push_back(
          point(core::pointPosition(model_, core::PointRef{ index, core::Vec3(0.0, 0.0, 0.5 * body.length) }, q)));
    }

  out.actuators.header.stamp = stamp;
  for (size_t i = 0; i < model_.actuators.size(); ++i)
  {
    out.actuators.name.push_back(model_.actuators[i].name);
    const bool has = i < state.u.size();
    out.actuators.position.push_back(has ? state.u[i].value : 0.0);
    out.actuators.velocity.push_back(has ? state.u[i].rate : 0.0);
    out.actuators.effort.push_back(core::actuationForce(model_, state, static_cast<int>(i)));
  }

  if (markers)
    addMarkers(state, contacts, cables, stamp, out.markers);
  return out;
}

void MessageBuilder::addMarkers(const core::State& state, const std::vector<core::ContactPairState>& contacts,
                                const std::vector<core::CableState>& cables, const ros::Time& stamp,
                                visualization_msgs::MarkerArray& out)
{
  using visualization_msgs::Marker;
  if (clear_all_)
  {
    Marker all = marker(frame_id_, stamp, "", 0, Marker::CUBE);
    all.action = Marker::DELETEALL;
    out.markers.push_back(all);
    clear_all_ = false;
  }
  const Eigen::VectorXd& q = state.q;

  // struts: cylinders of their real radius and length about the centre of mass; point masses: spheres
  for (size_t i = 0; i < model_.bodies.size(); ++i)
  {
    const core::Body& b = model_.bodies[i];
    const bool strut = b.kind == core::BodyKind::kStrut;
    Marker m = marker(frame_id_, stamp, strut ? "struts" : "bodies", static_cast<int>(i),
                      strut ? Marker::CYLINDER : Marker::SPHERE);
    m.pose.position = point(q.segment<3>(b.offset));
    m.pose.orientation = orientation(b, q);
    if (strut)
    {
      m.scale.x = m.scale.y = 2.0 * b.radius();
      m.scale.z = b.length;
      m.color = rgba(0.55f, 0.57f, 0.6f, static_cast<float>(options_.strut_alpha));
    }
    else
    {
      m.scale.x = m.scale.y = m.scale.z = 0.04;
      m.color = rgba(0.9f, 0.75f, 0.1f);
    }
    out.markers.push_back(m);
  }

  // the ground: a thin slab whose top is the ground plane, 20 m square under the initial configuration
  if (model_.ground.enabled)
  {
    Marker m = marker(frame_id_, stamp, "ground", 0, Marker::CUBE);
    m.pose.position = point(ground_centre_);
    m.pose.orientation.w = 1.0;
    m.scale.x = m.scale.y = 20.0;
    m.scale.z = 0.01;
    m.color = rgba(0.35f, 0.4f, 0.35f, 0.8f);
    out.markers.push_back(m);
  }

  // cables: one line list for the taut ones (coloured by tension), one for the slack ones
  double tension_scale = options_.cable_tension_scale;
  if (tension_scale <= 0.0)
    for (const core::CableState& c : cables)
      tension_scale = std::max(tension_scale, c.tension);
  Marker taut = marker(frame_id_, stamp, "cables", 0, Marker::LINE_LIST);
  Marker slack = marker(frame_id_, stamp, "slack_cables", 0, Marker::LINE_LIST);
  taut.scale.x = options_.cable_width;
  slack.scale.x = 0.4 * options_.cable_width;
  slack.color = rgba(0.6f, 0.6f, 0.6f, 0.6f);
  for (size_t i = 0; i < cables.size(); ++i)
  {
    const core::Cable& cable = model_.cables[i];
    const std_msgs::ColorRGBA colour = tensionColour(tension_scale > 0.0 ? cables[i].tension / tension_scale : 0.0);
    Marker& into = cables[i].slack ? slack : taut;
    for (size_t k = 0; k + 1 < cable.points.size(); ++k)
    {
      into.points.push_back(point(core::pointPosition(model_, cable.points[k], q)));
      into.points.push_back(point(core::pointPosition(model_, cable.points[k + 1], q)));
      if (!cables[i].slack)
      {
        into.colors.push_back(colour);
        into.colors.push_back(colour);
      }
    }
  }
  taut.color = rgba(1.0f, 1.0f, 1.0f);
  // rviz refuses an empty line list: an empty one is deleted instead
  for (Marker* m : { &taut, &slack })
  {
    if (m->points.empty())
      m->action = Marker::DELETE;
    out.markers.push_back(*m);
  }

  // contact forces: per pair in contact, the normal force on strut a (from its contact point along n)
  // and on strut b (opposite), and the friction force on strut a; ids 4 * pair + 0..3
  std::vector<int> shown;
  for (const core::ContactPairState& c : contacts)
  {
    shown.push_back(c.pair);
    const auto arrow = [&](int k, const core::Vec3& from, const core::Vec3& force, const std_msgs::ColorRGBA& colour)
    {
      Marker m = marker(frame_id_, stamp, "contact_forces", 4 * c.pair + k, Marker::ARROW);
      m.points.push_back(point(from));
      m.points.push_back(point(from + options_.contact_force_scale * force));
      m.scale.x = 0.015;  // shaft diameter
      m.scale.y = 0.03;   // head diameter
      m.scale.z = 0.0;    // default head length
      m.color = colour;
      if (force.norm() * options_.contact_force_scale < 1e-6)
        m.action = Marker::DELETE;
      out.markers.push_back(m);
    };
    arrow(0, c.point_a, c.normal_force * c.normal, rgba(1.0f, 0.85f, 0.0f));
    arrow(1, c.point_b, -c.normal_force * c.normal, rgba(1.0f, 0.85f, 0.0f));
    arrow(2, c.point_a, c.friction_on_a, rgba(0.0f, 0.9f, 1.0f));
    arrow(3, c.point_b, -c.friction_on_a, rgba(0.0f, 0.9f, 1.0f));
  }
  std::sort(shown.begin(), shown.end());
  std::vector<int> gone;
  std::set_difference(arrow_shown_.begin(), arrow_shown_.end(), shown.begin(), shown.end(), std::back_inserter(gone));
  for (int p : gone)
    for (int k = 0; k < 4; ++k)
    {
      Marker m = marker(frame_id_, stamp, "contact_forces", 4 * p + k, Marker::ARROW);
      m.action = Marker::DELETE;
      out.markers.push_back(m);
    }
  arrow_shown_ = std::move(shown);
}

}  // namespace active_tensegrity::ros_layer
