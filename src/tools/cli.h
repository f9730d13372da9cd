/// Small command-line helpers shared by the tools.
#pragma once

#include <sstream>
#include <string>
#include <vector>

namespace active_tensegrity::tools
{
/// "a,b,c" -> {"a", "b", "c"} (an empty text gives no item; empty items between commas are kept).
inline std::vector<std::string> splitList(const std::string& s)
{
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    out.push_back(item);
  return out;
}

}  // namespace active_tensegrity::tools
