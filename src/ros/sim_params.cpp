#include "active_tensegrity/ros/sim_params.h"

#include <cmath>
#include <iomanip>
#include <sstream>

#include <ros/package.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include "active_tensegrity/core/text.h"

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
  p.real_time_factor = number(nh, "real_time_factor", p.real_time_factor);
  if (p.real_time_factor < 0.0)
    throw ParamError("~real_time_factor must be >= 0 (0 = as fast as possible), got " +
                     core::shortestNumber(p.real_time_factor));
  p.publish_rate = number(nh, "publish_rate", p.publish_rate);
  if (p.publish_rate <= 0.0)
    throw ParamError("~publish_rate must be > 0 Hz, got " + core::shortestNumber(p.publish_rate));
  p.marker_rate = number(nh, "marker_rate", p.marker_rate);
  if (!(p.marker_rate >= 0.0))
    throw ParamError("~marker_rate must be >= 0 Hz of wall time (0 = with every publication), got " +
                     core::shortestNumber(p.marker_rate));
  p.publish_clock = boolean(nh, "publish_clock", p.publish_clock);
  p.frame_id = text(nh, "frame_id", p.frame_id);
  if (p.frame_id.empty())
    throw ParamError("~frame_id is empty");
  p.default_speed = number(nh, "default_speed", p.default_speed);
  if (p.default_speed < 0.0)
    throw ParamError("~default_speed must be > 0 m/s (or 0: the scene's actuation.speed), got " +
                     core::shortestNumber(p.default_speed));
  p.default_acceleration = number(nh, "default_acceleration", p.default_acceleration);
  if (p.default_acceleration < 0.0)
    throw ParamError("~default_acceleration must be > 0 m/s^2 (or 0: derived), got " +
                     core::shortestNumber(p.default_acceleration));
  p.start_paused = boolean(nh, "start_paused", p.start_paused);
  p.adaptive = boolean(nh, "adaptive", p.adaptive);
  p.markers.contact_force_scale = number(nh, "contact_force_scale", p.markers.contact_force_scale);
  if (p.markers.contact_force_scale <= 0.0)
    throw ParamError("~contact_force_scale must be > 0 m/N, got " + core::shortestNumber(p.markers.contact_force_scale));
  p.markers.cable_tension_scale = number(nh, "cable_tension_scale", p.markers.cable_tension_scale);
  if (p.markers.cable_tension_scale < 0.0)
    throw ParamError("~cable_tension_scale must be >= 0 N (0 = the largest tension of the moment), got " +
                     core::shortestNumber(p.markers.cable_tension_scale));
  p.markers.strut_alpha = number(nh, "strut_alpha", p.markers.strut_alpha);
  if (p.markers.strut_alpha <= 0.0 || p.markers.strut_alpha > 1.0)
    throw ParamError("~strut_alpha must be in (0, 1], got " + core::shortestNumber(p.markers.strut_alpha));
  p.markers.cable_width = number(nh, "cable_width", p.markers.cable_width);
  if (p.markers.cable_width <= 0.0)
    throw ParamError("~cable_width must be > 0 m, got " + core::shortestNumber(p.markers.cable_width));
  return p;
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
    << "frame_id: " << frame_id << "\n"
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
