// The core's and the design library's dynamic symbols are their own (cmake/core_exports.map): an Eigen function they
// instantiate for Eigen's own types stays inside. Exported, it would take the calls of OMPL, loaded in the same process
// and built from its own Eigen headers and flags: the folding planner corrupts the heap in
// ompl::base::ProjectionMatrix::ComputeRandom when a library of the package exports JacobiSVD's functions.
#include <array>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace
{
struct Exports
{
  int symbols = 0;                   // defined dynamic symbols
  std::vector<std::string> foreign;  // of them, Eigen's functions for types that are not the package's
  int status = -1;                   // nm's exit status
};

Exports exportsOf(const std::string& library)
{
  Exports e;
  FILE* pipe = popen(("nm -DC --defined-only '" + library + "' 2>&1").c_str(), "r");
  if (!pipe)
    return e;
  std::array<char, 4096> buffer{};
  std::string line;
  while (std::fgets(buffer.data(), buffer.size(), pipe))
  {
    line += buffer.data();
    if (line.empty() || line.back() != '\n')
      continue;  // (a longer line: read on)
    ++e.symbols;
    if (line.find("Eigen::") != std::string::npos && line.find("active_tensegrity") == std::string::npos)
      e.foreign.push_back(line.substr(0, 200));
    line.clear();
  }
  e.status = pclose(pipe);
  return e;
}
}  // namespace

TEST(LibraryExports, TheCheckFindsEigenFunctionsInALibraryBuiltWithoutAMap)
{
  // OMPL exports the Eigen functions it instantiates: what the check below looks for is there to be found
  const Exports ompl = exportsOf(OMPL_LIBRARY_PATH);
  ASSERT_EQ(ompl.status, 0) << OMPL_LIBRARY_PATH;
  EXPECT_GT(ompl.foreign.size(), 10u);
}

TEST(LibraryExports, CoreAndDesignExportNoEigenFunctionOfTheirOwn)
{
  for (const char* library : { CORE_LIBRARY_PATH, DESIGN_LIBRARY_PATH })
  {
    const Exports e = exportsOf(library);
    ASSERT_EQ(e.status, 0) << library;
    EXPECT_GT(e.symbols, 50) << library << ": nm listed too little to have read its symbol table";
    std::string first;
    for (size_t k = 0; k < e.foreign.size() && k < 5; ++k)
      first += e.foreign[k];
    EXPECT_TRUE(e.foreign.empty()) << library << " exports " << e.foreign.size() << " Eigen functions, first:\n"
                                   << first;
  }
}
