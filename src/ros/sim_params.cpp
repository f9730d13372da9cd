#include "active_tensegrity/ros/sim_params.h"

#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <ros/package.h>
#include <ros/this_node.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::ros_layer
{
namespace
{
const char* kDefaultScene = "package://active_tensegrity/config/scenes/tower.yaml";

std::string show(XmlRpc::XmlRpcValue v)
{
  if (v.getType() == XmlRpc::XmlRpcValue::TypeString)
    return "'" + static_cast<std::string>(v) + "'";
  std::ostringstream s;
  v.write(s);
  return s.str();
}

// YAML text of a parameter value (for a scene override)
std::string yamlText(XmlRpc::XmlRpcValue& v, const std::string& key)
{
  std::ostringstream s;
  s << std::setprecision(17);
  switch (v.getType())
  {
    case XmlRpc::XmlRpcValue::TypeBoolean:
      return static_cast<bool>(v) ? "true" : "false";
    case XmlRpc::XmlRpcValue::TypeInt:
      s << static_cast<int>(v);
      return s.str();
    case XmlRpc::XmlRpcValue::TypeDouble:
      s << static_cast<double>(v);
      return s.str();
    case XmlRpc::XmlRpcValue::TypeString:
      return static_cast<std::string>(v);
    case XmlRpc::XmlRpcValue::TypeArray:
    {
      s << "[";
      for (int i = 0; i < v.size(); ++i)
        s << (i ? ", " : "") << yamlText(v[i], key);
      s << "]";
      return s.str();
    }
    default:
      throw ParamError("~overrides/" + key + ": unsupported value " + show(v) +
                       " (give a number, a boolean, a string or a list)");
  }
}

// flattens a nested map {solver: {dt: 1e-4}} or a flat {solver.dt: 1e-4} into dotted keys
void flatten(XmlRpc::XmlRpcValue& v, const std::string& prefix, std::vector<core::Override>& out)
{
  if (v.getType() == XmlRpc::XmlRpcValue::TypeStruct)
  {
    for (auto& kv : v)
      flatten(kv.second, prefix.empty() ? kv.first : prefix + "." + kv.first, out);
    return;
  }
  out.push_back({ prefix, yamlText(v, prefix) });
}

double number(const ros::NodeHandle& nh, const std::string& name, double fallback)
{
  if (!nh.hasParam(name))
    return fallback;
  XmlRpc::XmlRpcValue v;
  nh.getParam(name, v);
  double x = 0.0;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeDouble)
    x = static_cast<double>(v);
  else if (v.getType() == XmlRpc::XmlRpcValue::TypeInt)
    x = static_cast<int>(v);
  else
    throw ParamError("~" + name + " must be a number, got " + show(v));
  if (!std::isfinite(x))
    throw ParamError("~" + name + " must be finite, got " + show(v));
  return x;
}

bool boolean(const ros::NodeHandle& nh, const std::string& name, bool fallback)
{
  if (!nh.hasParam(name))
    return fallback;
  XmlRpc::XmlRpcValue v;
  nh.getParam(name, v);
  if (v.getType() != XmlRpc::XmlRpcValue::TypeBoolean)
    throw ParamError("~" + name + " must be true or false, got " + show(v));
  return static_cast<bool>(v);
}

std::string text(const ros::NodeHandle& nh, const std::string& name, const std::string& fallback)
{
  if (!nh.hasParam(name))
    return fallback;
  XmlRpc::XmlRpcValue v;
  nh.getParam(name, v);
  if (v.getType() != XmlRpc::XmlRpcValue::TypeString)
    throw ParamError("~" + name + " must be a string, got " + show(v));
  return static_cast<std::string>(v);
}
}  // namespace

std::string resolvePackageUrl(const std::string& url)
{
  const std::string scheme = "package://";
  if (url.compare(0, scheme.size(), scheme) != 0)
    return url;
  const std::string rest = url.substr(scheme.size());
  const size_t slash = rest.find('/');
  const std::string pkg = rest.substr(0, slash);
  const std::string path = ros::package::getPath(pkg);
  if (path.empty())
    throw ParamError("~scene: package '" + pkg + "' of '" + url + "' not found (is the workspace sourced?)");
  return slash == std::string::npos ? path : path + rest.substr(slash);
}

SimParams loadSimParams(const ros::NodeHandle& nh)
{
  SimParams p;
  p.scene = resolvePackageUrl(text(nh, "scene", kDefaultScene));
  if (p.scene.empty())
    throw ParamError("~scene is empty");
  if (nh.hasParam("overrides"))
  {
    XmlRpc::XmlRpcValue v;
    nh.getParam("overrides", v);
    if (v.getType() != XmlRpc::XmlRpcValue::TypeStruct)
      throw ParamError("~overrides must be a map of scene keys to values (e.g. {solver.dt: 1e-4}), got " + show(v));
    flatten(v, "", p.overrides);
  }
  for (const std::string& name : liveParamNames())
  {
    const double value = number(nh, name, liveParam(p, name));
    if (const std::string err = checkLiveParam(name, value); !err.empty())
      throw ParamError(err);
    setLiveParam(p, name, value);
  }
  p.publish_clock = boolean(nh, "publish_clock", p.publish_clock);
  p.frame_id = text(nh, "frame_id", p.frame_id);
  if (p.frame_id.empty())
    throw ParamError("~frame_id is empty");
  // the node's namespace, /robot_a -> robot_a (the root namespace: no prefix)
  std::string ns = ros::this_node::getNamespace();
  while (!ns.empty() && ns.front() == '/')
    ns.erase(ns.begin());
  p.tf_prefix = text(nh, "tf_prefix", ns);
  if (!p.tf_prefix.empty() && (p.tf_prefix.front() == '/' || p.tf_prefix.back() == '/' ||
                               p.tf_prefix.find_first_of(" \t\n") != std::string::npos))
    throw ParamError("~tf_prefix must not start or end with '/' nor hold spaces (tf2 frames are such as "
                     "robot_a/S1), got " +
                     core::quoted(p.tf_prefix));
  if (p.frame_id.find('/') == 0)
    throw ParamError("~frame_id must not start with '/' (tf2 frames have no leading slash), got " +
                     core::quoted(p.frame_id));
  const double queue = number(nh, "queue_size", p.queue_size);
  if (!(queue >= 1.0 && queue <= 100000.0 && queue == std::floor(queue)))
    throw ParamError("~queue_size must be a whole number of messages from 1 to 100000, got " +
                     core::shortestNumber(queue));
  p.queue_size = static_cast<int>(queue);
  p.start_paused = boolean(nh, "start_paused", p.start_paused);
  p.adaptive = boolean(nh, "adaptive", p.adaptive);
  return p;
}

namespace
{
/// A live parameter: its name, where it lives in SimParams, and what a value must be (the refusal's words).
struct LiveParamSpec
{
  const char* name;
  double& (*field)(SimParams&);
  bool (*accepts)(double);
  const char* requirement;
};

const std::vector<LiveParamSpec>& liveParamSpecs()
{
  static const std::vector<LiveParamSpec> specs = {
    { "real_time_factor", [](SimParams& p) -> double& { return p.real_time_factor; }, [](double v) { return v >= 0.0; },
      "must be >= 0 (0 = as fast as possible)" },
    { "publish_rate", [](SimParams& p) -> double& { return p.publish_rate; }, [](double v) { return v > 0.0; },
      "must be > 0 Hz" },
    { "max_publish_wall_rate", [](SimParams& p) -> double& { return p.max_publish_wall_rate; },
      [](double v) { return v >= 0.0; }, "must be >= 0 Hz of wall time (0 = no cap)" },
    { "marker_rate", [](SimParams& p) -> double& { return p.marker_rate; }, [](double v) { return v >= 0.0; },
      "must be >= 0 Hz of wall time (0 = with every publication)" },
    { "default_speed", [](SimParams& p) -> double& { return p.default_speed; }, [](double v) { return v >= 0.0; },
      "must be > 0 m/s (or 0: the scene's actuation.speed)" },
    { "default_acceleration", [](SimParams& p) -> double& { return p.default_acceleration; },
      [](double v) { return v >= 0.0; }, "must be > 0 m/s^2 (or 0: derived)" },
    { "contact_force_scale", [](SimParams& p) -> double& { return p.markers.contact_force_scale; },
      [](double v) { return v > 0.0; }, "must be > 0 m/N" },
    { "cable_tension_scale", [](SimParams& p) -> double& { return p.markers.cable_tension_scale; },
      [](double v) { return v >= 0.0; }, "must be >= 0 N (0 = the largest tension of the moment)" },
    { "cable_width", [](SimParams& p) -> double& { return p.markers.cable_width; }, [](double v) { return v > 0.0; },
      "must be > 0 m" },
    { "strut_alpha", [](SimParams& p) -> double& { return p.markers.strut_alpha; },
      [](double v) { return v > 0.0 && v <= 1.0; }, "must be in (0, 1]" },
  };
  return specs;
}

const LiveParamSpec& liveParamSpec(const std::string& name)
{
  for (const LiveParamSpec& spec : liveParamSpecs())
    if (name == spec.name)
      return spec;
  throw std::logic_error("no live parameter '" + name + "'");
}
}  // namespace

const std::vector<std::string>& liveParamNames()
{
  static const std::vector<std::string> names = []
  {
    std::vector<std::string> out;
    for (const LiveParamSpec& spec : liveParamSpecs())
      out.emplace_back(spec.name);
    return out;
  }();
  return names;
}

std::string checkLiveParam(const std::string& name, double value)
{
  const LiveParamSpec& spec = liveParamSpec(name);
  const std::string got = ", got " + core::shortestNumber(value);
  if (!std::isfinite(value))
    return "~" + name + " must be finite" + got;
  return spec.accepts(value) ? "" : "~" + name + " " + spec.requirement + got;
}

double liveParam(const SimParams& p, const std::string& name)
{
  // (read through the accessor that sets it; nothing is written)
  return liveParamSpec(name).field(const_cast<SimParams&>(p));
}

void setLiveParam(SimParams& p, const std::string& name, double value)
{
  liveParamSpec(name).field(p) = value;
}

void resolveCommandDefaults(SimParams& params, const core::Model& model)
{
  if (params.default_speed <= 0.0)
    params.default_speed = model.analysis.schedule.speed > 0.0 ? model.analysis.schedule.speed : 0.1;
  if (params.default_acceleration <= 0.0)
    params.default_acceleration =
        params.default_speed / (model.analysis.schedule.blend_time > 0.0 ? model.analysis.schedule.blend_time : 0.1);
}

void writeSimParams(ros::NodeHandle& nh, const SimParams& p)
{
  nh.setParam("scene", p.scene);
  for (const std::string& name : liveParamNames())
    nh.setParam(name, liveParam(p, name));
  nh.setParam("publish_clock", p.publish_clock);
  nh.setParam("frame_id", p.frame_id);
  nh.setParam("tf_prefix", p.tf_prefix);
  nh.setParam("queue_size", p.queue_size);
  nh.setParam("start_paused", p.start_paused);
  nh.setParam("adaptive", p.adaptive);
}

std::string SimParams::describe() const
{
  std::ostringstream s;
  s << "scene: " << scene << "\n";
  for (const core::Override& o : overrides)
    s << "overrides: " << o.key << " = " << o.value << "\n";
  s << "real_time_factor: " << real_time_factor << (real_time_factor == 0.0 ? " (as fast as possible)" : "") << "\n"
    << "publish_rate: " << publish_rate << " Hz (simulated time)\n"
    << "marker_rate: " << marker_rate
    << (marker_rate == 0.0 ? " (markers with every publication)" : " Hz (wall time, at most)") << "\n"
    << "publish_clock: " << (publish_clock ? "true" : "false") << "\n"
    << "queue_size: " << queue_size << " messages per subscriber (data topics and /tf)\n"
    << "frame_id: " << frame_id << "\n"
    << "tf_prefix: " << (tf_prefix.empty() ? "(none: frames are the bodies' names)" : tf_prefix) << "\n"
    << "max_publish_wall_rate: " << max_publish_wall_rate
    << (max_publish_wall_rate == 0.0 ? " (no cap)" : " Hz (wall time, at most)") << "\n"
    << "default_speed: " << default_speed << " m/s\n"
    << "default_acceleration: " << default_acceleration << " m/s^2\n"
    << "start_paused: " << (start_paused ? "true" : "false") << "\n"
    << "adaptive: " << (adaptive ? "true (steps from solver.error_tolerance)" : "false (fixed steps of solver.dt)")
    << "\n"
    << "contact_force_scale: " << markers.contact_force_scale << " m/N\n"
    << "cable_tension_scale: " << markers.cable_tension_scale << " N\n"
    << "cable_width: " << markers.cable_width << " m\n"
    << "strut_alpha: " << markers.strut_alpha;
  return s.str();
}

}  // namespace active_tensegrity::ros_layer
