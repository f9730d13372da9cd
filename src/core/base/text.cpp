#include "active_tensegrity/core/base/text.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <vector>

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

std::size_t editDistance(const std::string& a, const std::string& b)
{
  // three rows of the dynamic programme: i - 2, i - 1, i
  std::vector<std::size_t> before(b.size() + 1), last(b.size() + 1), row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j)
    last[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i)
  {
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
    {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      row[j] = std::min({ last[j] + 1, row[j - 1] + 1, last[j - 1] + cost });
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        row[j] = std::min(row[j], before[j - 2] + 1);
    }
    std::swap(before, last);
    std::swap(last, row);
  }
  return last[b.size()];
}

std::string nearestMatch(const std::string& word, const std::vector<std::string>& candidates)
{
  // (words far longer than any key are not compared: the distance costs their product)
  const std::size_t allowed = word.size() <= 4 ? 1 : 2;
  std::string best;
  std::size_t best_distance = allowed + 1;
  for (const std::string& c : candidates)
  {
    if (c == word || c.size() > word.size() + allowed || word.size() > c.size() + allowed)
      continue;
    const std::size_t d = editDistance(word, c);
    if (d < best_distance)
    {
      best = c;
      best_distance = d;
    }
  }
  return best;
}

}  // namespace active_tensegrity::core
