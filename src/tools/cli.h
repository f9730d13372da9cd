/// Small command-line helpers shared by the tools.
#pragma once

#include <cmath>
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
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

/// A bad command-line argument: reported with its name and value (the tools exit with status 2).
struct BadArgument : std::invalid_argument
{
  using std::invalid_argument::invalid_argument;
};

/// The whole of `text` as a positive, finite int or double, else BadArgument naming the option and value
/// (std::stod alone would take "1e-3x" as 1e-3 and "-1" as -1).
template <class T>
T parsePositive(const std::string& option, const std::string& text)
{
  static_assert(std::is_same_v<T, int> || std::is_same_v<T, double>, "int or double");
  size_t used = 0;
  T v = 0;
  try
  {
    if constexpr (std::is_same_v<T, int>)
      v = std::stoi(text, &used);
    else
      v = std::stod(text, &used);
  }
  catch (const std::exception&)
  {
    used = 0;
  }
  if (used != text.size() || text.empty() || !std::isfinite(static_cast<double>(v)) || v <= 0)
    throw BadArgument(option + ": expected a positive " + (std::is_same_v<T, int> ? "integer" : "number") + ", got '" +
                      text + "'");
  return v;
}

/// "a,b,c" as positive numbers (each checked as parsePositive<double>).
inline std::vector<double> parsePositiveList(const std::string& option, const std::string& text)
{
  std::vector<double> out;
  for (const std::string& item : splitList(text))
    out.push_back(parsePositive<double>(option, item));
  if (out.empty())
    throw BadArgument(option + ": expected a list of positive numbers, got '" + text + "'");
  return out;
}

/// "--option value" arguments, walked in order: option() takes the next one, value() the value after it
/// (std::invalid_argument when there is none).
class Args
{
public:
  explicit Args(std::vector<std::string> args) : args_(std::move(args)) {}
  bool more() const
  {
    return next_ < args_.size();
  }
  std::string option()
  {
    return args_[next_++];
  }
  std::string value(const std::string& option)
  {
    if (next_ >= args_.size())
      throw std::invalid_argument(option + " needs a value");
    return args_[next_++];
  }

private:
  std::vector<std::string> args_;
  size_t next_ = 0;
};

/// The directory of the shipped scenes: <prefix>/share/active_tensegrity/config/scenes when the running tool
/// is installed as <prefix>/lib/active_tensegrity/<tool> (install space), else `source_dir`, the source
/// tree's config/scenes (devel space).
inline std::string sceneDirectory(const std::string& source_dir)
{
  std::error_code error;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", error);
  if (!error)
  {
    const std::filesystem::path installed =
        exe.parent_path().parent_path().parent_path() / "share" / "active_tensegrity" / "config" / "scenes";
    if (std::filesystem::is_directory(installed, error))
      return installed.string();
  }
  return source_dir;
}

}  // namespace active_tensegrity::tools
