// libFuzzer target for the scene loader: the input is a scene's YAML text; lines of the form
// "#--set key=value" (YAML comments, so the text stays a scene) are applied as command-line overrides.
// A loaded scene must give a consistent, finite start: its initial state and the first CSV row (min_gap,
// min_cable_strut_gap and min_ground_gap may be +inf: nothing to measure). Anything else than a load or a SceneError is
// a finding (an uncaught exception, an abort, a sanitizer report, a non-finite number).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <sstream>
#include <string>
#include <typeinfo>
#include <vector>

#include "active_tensegrity/core/outputs/csv.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"

namespace at = active_tensegrity::core;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::vector<at::Override> overrides;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("#--set ", 0) == 0)
    {
      try
      {
        overrides.push_back(at::parseOverride(line.substr(7)));
      }
      catch (const at::SceneError&)
      {
        return 0;
      }
    }
  at::Model model;
  try
  {
    model = at::loadSceneFromString(text, "fuzz.yaml", overrides);
  }
  catch (const at::SceneError& e)
  {
    if (std::string(e.what()).size() > 4000)
    {
      std::fprintf(stderr, "message of %zu bytes\n", std::string(e.what()).size());
      std::abort();
    }
    return 0;
  }
  catch (const std::exception& e)
  {
    // anything else the loader lets out is a defect: say what it was before libFuzzer reports the abort
    std::fprintf(stderr, "the loader threw %s: %s\n", typeid(e).name(), e.what());
    std::abort();
  }
  const at::State s = at::initialState(model);
  if (!s.q.allFinite())
  {
    std::fprintf(stderr, "non-finite initial state\n");
    std::abort();
  }
  const std::vector<std::string> cols = at::csvColumns(model);
  const std::vector<double> row = at::csvRow(model, s);
  for (size_t i = 0; i < row.size(); ++i)
    if (!std::isfinite(row[i]) &&
        !((cols[i] == "min_gap" || cols[i] == "min_cable_strut_gap" || cols[i] == "min_ground_gap") && row[i] > 0.0))
    {
      std::fprintf(stderr, "non-finite %s = %g in the first row\n", cols[i].c_str(), row[i]);
      std::abort();
    }
  return 0;
}
