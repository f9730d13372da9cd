/// Scene files (YAML, SI units) -> Model. Every map is checked for unknown keys, every number for
/// finiteness and range, every name for existence and uniqueness; a bad scene throws SceneError
/// naming the file, the key and the value. The format is documented in docs/scenes.md.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
class SceneError : public std::runtime_error
{
public:
  SceneError(const std::string& file, const std::string& key, const std::string& what)
    : std::runtime_error(file + ": " + (key.empty() ? std::string() : key + ": ") + what), key_(key)
  {
  }
  const std::string& key() const
  {
    return key_;
  }

private:
  std::string key_;
};

/// A command-line style override "dotted.key=value"; value is parsed as YAML.
struct Override
{
  std::string key;
  std::string value;
};

/// The largest scene text the loader reads (a file, or a string), in bytes: 64 MiB.
constexpr std::size_t kMaxSceneBytes = std::size_t(64) << 20;

/// The text of the scene file `path`: a regular file (or a link to one) of at most kMaxSceneBytes. A
/// directory, a device (/dev/zero), a pipe or a larger file is refused with a SceneError that says which.
std::string readSceneFile(const std::string& path);

/// Parses "key=value" (throws SceneError on a missing '=' or an empty key).
Override parseOverride(const std::string& text);

/// Loads and validates a scene file, applying overrides to the YAML tree first.
Model loadScene(const std::string& path, const std::vector<Override>& overrides = {});

/// The same from YAML text (`name` stands for the file in messages).
Model loadSceneFromString(const std::string& yaml, const std::string& name = "<string>",
                          const std::vector<Override>& overrides = {});

}  // namespace active_tensegrity::core
