/// Closest points between two strut axes (clamped segments), robust for parallel and end regions.
#pragma once

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
enum class ClosestRegion
{
  kInterior,  // both closest points strictly inside their segments (the paper's Eq. 12 case)
  kEnd,       // at least one closest point at a segment end
  kParallel   // the axes are parallel within tolerance; a representative pair is returned
};

struct SegmentClosest
{
  double s1 = 0.0;  // parameter on segment 1, in [0, 1]
  double s2 = 0.0;  // parameter on segment 2, in [0, 1]
  Vec3 p1 = Vec3::Zero();
  Vec3 p2 = Vec3::Zero();
  double distance = 0.0;  // |p1 - p2|
  ClosestRegion region = ClosestRegion::kInterior;
};

/// Closest points of segments [a1, b1] and [a2, b2].
SegmentClosest closestPointsSegments(const Vec3& a1, const Vec3& b1, const Vec3& a2, const Vec3& b2);

}  // namespace active_tensegrity::core
