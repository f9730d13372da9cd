// A dependant of active_tensegrity compiled with other flags than the library (CMakeLists.txt here): it
// must lay out the structs with fixed-size Eigen members as the library does (the exported
// EIGEN_MAX_STATIC_ALIGN_BYTES), and pass models and states to and from it. Its scenes come from
// DOWNSTREAM_SCENE_DIR (test/downstream/run).
#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/outputs/eigen_layout.h"
#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/design/form_finding.h"
#include "active_tensegrity/design/generators.h"

namespace at = active_tensegrity::core;

namespace
{
// This package's own numbers (internal linkage: never the library's copy of a helper)
template <class T, class M>
at::TypeLayout layoutHere(M T::*member)
{
  const T object{};
  at::TypeLayout l;
  l.size = sizeof(T);
  l.align = alignof(T);
  l.member_offset = static_cast<std::size_t>(reinterpret_cast<const char*>(&(object.*member)) -
                                             reinterpret_cast<const char*>(&object));
  return l;
}

void expectSame(const std::string& type, const at::TypeLayout& here, const at::TypeLayout& library)
{
  EXPECT_EQ(here.size, library.size) << "sizeof(" << type << ")";
  EXPECT_EQ(here.align, library.align) << "alignof(" << type << ")";
  EXPECT_EQ(here.member_offset, library.member_offset) << "member offset in " << type;
}

std::string sceneDir()
{
  const char* dir = std::getenv("DOWNSTREAM_SCENE_DIR");
  return dir ? dir : "";
}
}  // namespace

TEST(DownstreamLayout, CompiledWithFlagsThatWouldChangeTheLayout)
{
#ifdef __AVX__
  // Eigen's own alignment for these flags, had the exported definition not fixed it
  EXPECT_GT(EIGEN_IDEAL_MAX_ALIGN_BYTES, at::libraryEigenLayout().max_static_align_bytes);
#else
  GTEST_SKIP() << "compiled without AVX (DOWNSTREAM_CXX_FLAGS): Eigen's alignment would be the library's anyway";
#endif
}

TEST(DownstreamLayout, SameLayoutAsTheLibrary)
{
  const at::EigenLayout library = at::libraryEigenLayout();
  EXPECT_EQ(EIGEN_MAX_STATIC_ALIGN_BYTES, library.max_static_align_bytes);
  expectSame("EigenLayoutProbe", layoutHere(&at::EigenLayoutProbe::vector), library.probe);
  expectSame("Constraint", layoutHere(&at::Constraint::coefficients), library.constraint);
  expectSame("Model", layoutHere(&at::Model::gravity), library.model);
  expectSame("State", layoutHere(&at::State::natural), library.state);
}

TEST(DownstreamLayout, SceneLoadedAndRunThroughTheLibrary)
{
  ASSERT_FALSE(sceneDir().empty()) << "DOWNSTREAM_SCENE_DIR is not set";
  const at::Model model =
      at::loadScene(sceneDir() + "/quadruplex.yaml",
                    { at::parseOverride("analysis.steps=5"), at::parseOverride("analysis.max_actuation=0.2") });
  ASSERT_FALSE(model.constraints.empty());
  for (const at::Constraint& c : model.constraints)
  {
    EXPECT_TRUE(c.coefficients.allFinite()) << c.name;
    EXPECT_GE(c.rows(), 1) << c.name;
  }
  EXPECT_TRUE(model.gravity.allFinite());
  const at::State start = at::initialState(model);
  EXPECT_EQ(start.q.size(), model.nq);
  int outputs = 0;
  const at::RunResult r =
      at::runAnalysis(model, [&outputs](const at::State& s) { outputs += s.q.allFinite() ? 1 : 0; });
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_GT(outputs, 0);
}

// The design library through the same exported config: a generated prism loads, and form-finding returns its form
TEST(Downstream, DesignLibraryGeneratesAndFindsAForm)
{
  active_tensegrity::design::PrismSpec spec;
  spec.struts = 4;
  const std::string yaml = active_tensegrity::design::prismScene(spec);
  EXPECT_EQ(at::loadSceneFromString(yaml, "prism").bodies.size(), 4u);
  active_tensegrity::design::FormFindingOptions options;
  const active_tensegrity::design::FormFindingResult form = active_tensegrity::design::findForm(yaml, "prism", options);
  EXPECT_EQ(form.positions.size(), 8u);
}
