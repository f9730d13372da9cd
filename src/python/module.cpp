// active_tensegrity._core: the core's scene loader and analyses for Python (pybind11). The package's Python
// code (python/active_tensegrity) wraps it; docs/python.md describes the API.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/kinematics.h"
#include "active_tensegrity/core/scene.h"

namespace py = pybind11;
namespace at = active_tensegrity::core;

namespace
{
std::vector<at::Override> overrides(const std::vector<std::string>& texts)
{
  std::vector<at::Override> out;
  out.reserve(texts.size());
  for (const std::string& t : texts)
    out.push_back(at::parseOverride(t));
  return out;
}

/// rows x columns of doubles as a numpy array (copied)
py::array_t<double> table(const std::vector<double>& values, size_t rows, size_t columns)
{
  py::array_t<double> a({ rows, columns });
  std::copy(values.begin(), values.end(), a.mutable_data());
  return a;
}

const char* analysisName(at::AnalysisType t)
{
  switch (t)
  {
    case at::AnalysisType::kStatic:
      return "static";
    case at::AnalysisType::kDynamic:
      return "dynamic";
    case at::AnalysisType::kModal:
      return "modal";
  }
  return "unknown";
}

/// What one run collects at every output step (filled with the GIL released, converted afterwards).
struct Collected
{
  std::vector<double> rows, nodes, members, contacts;
  size_t steps = 0;
};

py::dict run(const at::Model& model)
{
  if (model.analysis.type == at::AnalysisType::kModal)
    throw py::value_error("run: the scene's analysis.type is modal (natural modes have no output steps; run it with "
                          "tensegrity_run)");
  Collected c;
  at::RunResult result;
  {
    const py::gil_scoped_release release;
    result = at::runAnalysis(model,
                             [&](const at::State& s)
                             {
                               const std::vector<double> row = at::csvRow(model, s);
                               c.rows.insert(c.rows.end(), row.begin(), row.end());
                               for (const at::Node& n : model.nodes)
                               {
                                 const at::Vec3 p = at::pointPosition(model, n.point, s.q);
                                 c.nodes.insert(c.nodes.end(), { p.x(), p.y(), p.z() });
                               }
                               const std::vector<double> m = at::memberRow(model, s);
                               c.members.insert(c.members.end(), m.begin(), m.end());
                               for (const at::ContactPairState& k : at::activeContacts(model, s))
                               {
                                 const at::StrutPair& pair = model.checked_pairs[k.pair];
                                 c.contacts.insert(c.contacts.end(),
                                                   { static_cast<double>(c.steps), static_cast<double>(pair.body_a),
                                                     static_cast<double>(pair.body_b), k.point_a.x(), k.point_a.y(),
                                                     k.point_a.z(), k.point_b.x(), k.point_b.y(), k.point_b.z(),
                                                     k.normal.x(), k.normal.y(), k.normal.z(), k.penetration,
                                                     k.penetration_rate, k.normal_force, k.friction_on_a.x(),
                                                     k.friction_on_a.y(), k.friction_on_a.z() });
                               }
                               ++c.steps;
                             });
  }
  const std::vector<std::string> columns = at::csvColumns(model);
  const std::vector<std::string> member_columns = at::memberColumns(model);
  py::dict out;
  out["columns"] = columns;
  out["table"] = table(c.rows, c.steps, columns.size());
  py::array_t<double> nodes({ c.steps, model.nodes.size(), size_t{ 3 } });
  std::copy(c.nodes.begin(), c.nodes.end(), nodes.mutable_data());
  out["nodes"] = nodes;
  out["member_columns"] = member_columns;
  out["members"] = table(c.members, c.steps, member_columns.size());
  out["contacts"] = table(c.contacts, c.contacts.size() / 18, 18);
  py::dict summary;
  summary["status"] = at::toString(result.summary.status);
  summary["message"] = result.summary.message;
  summary["warnings"] = result.summary.warnings;
  summary["newton_iterations"] = result.summary.iterations;
  summary["step_cuts"] = result.summary.step_cuts;
  summary["output_steps"] = result.steps;
  summary["solver_steps"] = result.solver_steps;
  summary["wall_time"] = result.wall_time;
  out["summary"] = summary;
  return out;
}
}  // namespace

PYBIND11_MODULE(_core, m)
{
  m.doc() = "active_tensegrity's core: scenes and their analyses (use the package active_tensegrity)";
  // a refused scene: ValueError with the loader's message; the key it names is the exception's `key`
  static py::handle scene_error = py::exception<at::SceneError>(m, "SceneError", PyExc_ValueError).release();
  py::register_exception_translator(
      [](std::exception_ptr p)
      {
        try
        {
          if (p)
            std::rethrow_exception(p);
        }
        catch (const at::SceneError& e)
        {
          py::object error = py::reinterpret_borrow<py::object>(scene_error)(e.what());
          error.attr("key") = e.key();
          PyErr_SetObject(scene_error.ptr(), error.ptr());
        }
      });

  py::class_<at::Model>(m, "Model", "A loaded, validated scene")
      .def_property_readonly("name", [](const at::Model& s) { return s.name; })
      .def_property_readonly("source", [](const at::Model& s) { return s.source; })
      .def_property_readonly("analysis", [](const at::Model& s) { return analysisName(s.analysis.type); })
      .def_property_readonly("nodes",
                             [](const at::Model& s)
                             {
                               std::vector<std::string> v;
                               for (const at::Node& n : s.nodes)
                                 v.push_back(n.name);
                               return v;
                             })
      .def_property_readonly("bodies",
                             [](const at::Model& s)
                             {
                               std::vector<std::string> v;
                               for (const at::Body& b : s.bodies)
                                 v.push_back(b.name);
                               return v;
                             })
      .def_property_readonly("cables",
                             [](const at::Model& s)
                             {
                               std::vector<std::string> v;
                               for (const at::Cable& c : s.cables)
                                 v.push_back(c.name);
                               return v;
                             })
      .def_property_readonly("actuators",
                             [](const at::Model& s)
                             {
                               std::vector<std::string> v;
                               for (const at::Actuator& a : s.actuators)
                                 v.push_back(a.name);
                               return v;
                             });

  m.def(
      "load_scene",
      [](const std::string& path, const std::vector<std::string>& sets)
      {
        const std::vector<at::Override> o = overrides(sets);
        const py::gil_scoped_release release;
        return at::loadScene(path, o);
      },
      py::arg("path"), py::arg("overrides") = std::vector<std::string>{},
      "Loads and validates a scene file; overrides are 'key=value' texts as tensegrity_run --set takes them");
  m.def(
      "load_scene_text",
      [](const std::string& text, const std::string& name, const std::vector<std::string>& sets)
      {
        const std::vector<at::Override> o = overrides(sets);
        const py::gil_scoped_release release;
        return at::loadSceneFromString(text, name, o);
      },
      py::arg("text"), py::arg("name") = "<string>", py::arg("overrides") = std::vector<std::string>{},
      "The same from YAML text (`name` stands for the file in messages)");
  m.def("run", &run, py::arg("model"),
        "Runs the scene's analysis (static or dynamic); a dict of numpy arrays per output step and the summary");
}
