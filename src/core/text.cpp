#include "active_tensegrity/core/text.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <cmath>

namespace active_tensegrity::core
{
std::string shortestNumber(double v)
{
  if (std::isnan(v))
    return "nan";
  if (std::isinf(v))
    return v > 0.0 ? "inf" : "-inf";
  char buffer[32];
  const std::to_chars_result r = std::to_chars(buffer, buffer + sizeof(buffer), v);
  return std::string(buffer, r.ptr);
}

std::string roundedNumber(double v, int digits)
{
  if (!std::isfinite(v))
    return shortestNumber(v);
  // the shortest text that reads back as v rounded to `digits` significant digits
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*g", std::clamp(digits, 1, 17), v);
  return shortestNumber(std::strtod(buffer, nullptr));
}

std::string clipped(const std::string& text, std::size_t max_length)
{
  if (text.size() <= max_length)
    return text;
  std::size_t end = max_length;
  // back to the start of a UTF-8 character (continuation bytes are 10xxxxxx)
  while (end > 0 && (static_cast<unsigned char>(text[end]) & 0xC0) == 0x80)
    --end;
  return text.substr(0, end) + "... (" + std::to_string(text.size()) + " bytes)";
}

std::string quoted(const std::string& text)
{
  return "'" + clipped(text) + "'";
}

}  // namespace active_tensegrity::core
