/// Text for messages: numbers in their shortest exact form and user-given text cut to a bounded
/// length, so that an error or status message names a bad value without echoing megabytes of it.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace active_tensegrity::core
{
/// Longest piece of user-given text (a name, a value) a message repeats, in bytes.
constexpr std::size_t kMaxEchoLength = 200;

/// The shortest decimal text that reads back as exactly `v` ("0.5", "-0", "1e-300", "inf", "nan").
std::string shortestNumber(double v);

/// A computed value for a message: `v` rounded to `digits` significant digits, in its shortest form
/// ("0.1" for 0.09999999999999999, the end of a ramp of 0.02 m at 0.4 m/s plus 0.05 s).
std::string roundedNumber(double v, int digits = 12);

/// `text` itself when it has at most `max_length` bytes; else its first `max_length` bytes (never
/// splitting a UTF-8 character), "..." and the full length, e.g. "abc... (1048576 bytes)".
std::string clipped(const std::string& text, std::size_t max_length = kMaxEchoLength);

/// clipped(text) in single quotes: how messages quote a name or a value.
std::string quoted(const std::string& text);

/// The optimal string alignment distance of `a` and `b`: the fewest insertions, deletions, substitutions
/// and swaps of two neighbouring characters that turn one into the other ("radious" to "radius": 1).
std::size_t editDistance(const std::string& a, const std::string& b);

/// The candidate a misspelling of `word` most likely meant: the nearest by editDistance, if it is at most 1
/// for a word of up to 4 characters, at most 2 for a longer one (and not `word` itself); "" when none is.
std::string nearestMatch(const std::string& word, const std::vector<std::string>& candidates);

}  // namespace active_tensegrity::core
