/// Small command-line helpers shared by the tools.
#pragma once

#include <cmath>
#include <filesystem>
#include <functional>
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

/// A tool's command line, walked in order: options that take a value (`--name VALUE`), flags (`--name`) and
/// positional arguments. Asking for help (-h, --help), an unknown option, a missing or empty value and a positional
/// argument too many are handled here, with one wording for every tool (BadArgument).
class CommandLine
{
public:
  using Take = std::function<void(const std::string& value)>;
  /// `what` names the positional arguments in messages ("scene"); `context` prefixes the unknown-option message and
  /// `hint` follows it.
  explicit CommandLine(std::string what = "scene", std::string context = "", std::string hint = "")
    : what_(std::move(what)), context_(std::move(context)), hint_(std::move(hint))
  {
  }
  /// `--name VALUE`: take(VALUE).
  CommandLine& value(const std::string& name, Take take)
  {
    values_.emplace_back(name, std::move(take));
    return *this;
  }
  /// `--name`: set().
  CommandLine& flag(const std::string& name, std::function<void()> set)
  {
    flags_.emplace_back(name, std::move(set));
    return *this;
  }
  /// Up to `most` positional arguments, each given to take; `dash` also takes "-" (stdin) as one.
  CommandLine& positional(Take take, int most = 1, bool dash = false)
  {
    positional_ = std::move(take);
    most_ = most;
    dash_ = dash;
    return *this;
  }
  /// Walks the rest of `args`; false when help was asked (what follows it is not read).
  bool parse(Args& args)
  {
    while (args.more())
    {
      const std::string arg = args.option();
      if (arg == "-h" || arg == "--help")
        return false;
      if (take(arg, args))
        continue;
      if (!arg.empty() && arg[0] == '-' && !(dash_ && arg == "-"))
        throw BadArgument(context_ + "unknown option '" + arg + "'" + hint_);
      if (!positional_ || given_.size() >= static_cast<size_t>(most_))
        throw BadArgument(given_.empty() ?
                              context_ + "unexpected argument '" + arg + "'" + hint_ :
                              "more than one " + what_ + " given ('" + given_.back() + "' and '" + arg + "')");
      given_.push_back(arg);
      positional_(arg);
    }
    return true;
  }
  bool parse(int argc, char** argv)
  {
    Args args(std::vector<std::string>(argv + 1, argv + argc));
    return parse(args);
  }

private:
  bool take(const std::string& arg, Args& args)
  {
    for (const auto& [name, take] : values_)
      if (arg == name)
      {
        const std::string v = args.value(arg);
        // (an empty name opens nothing and writes nothing, and the run would say nothing of it)
        if (v.empty())
          throw BadArgument(arg + " needs a value, got an empty one ('')");
        take(v);
        return true;
      }
    for (const auto& [name, set] : flags_)
      if (arg == name)
      {
        set();
        return true;
      }
    return false;
  }

  std::string what_, context_, hint_;
  std::vector<std::pair<std::string, Take>> values_;
  std::vector<std::pair<std::string, std::function<void()>>> flags_;
  Take positional_;
  int most_ = 1;
  bool dash_ = false;
  std::vector<std::string> given_;
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
