// Broad phase of strut contact (core/broad_phase): on random scenes of 10, 50 and 200 struts, with all
// pairs or a random subset checked, candidates(), sweep() and direct() return the same pairs, which are
// exactly the pairs whose capsule boxes (computed here independently) overlap; every pair closer than
// the margin is among them (no contact missed) and sparse scenes are pruned. Then the choice between
// sweep and direct comparison, and configurations placed by hand (far apart, moved into contact, margin).
// Every two struts numbered without a list (`pairs: auto`), up to the most struts it numbers. Last, the kept
// list of near slots (NearSlotCache) against nearContactSlots along random walks.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/contact/contact_search.h"
#include "active_tensegrity/oracle/near_slot_cache.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
struct SceneSpec
{
  int struts = 10;
  double side = 1.0;           // centres uniform in [0, side]^3 (m)
  double pair_fraction = 1.0;  // each pair i < j checked with this probability (1: all pairs)
  bool off_sphere = false;     // Theta scaled by 1 + 1e-3 u, as in Newton iterates
};

Vec3 randomUnit(std::mt19937& rng)
{
  std::normal_distribution<double> n(0.0, 1.0);
  return Vec3(n(rng), n(rng), n(rng)).normalized();
}

// a point mass first (so strut offsets do not start at 0), then the struts, lengths 0.5-1.5 m and radii
// 0.01-0.06 m, random centres and axes; q0 filled
Model randomScene(const SceneSpec& spec, std::mt19937& rng)
{
  std::uniform_real_distribution<double> u01(0.0, 1.0), length(0.5, 1.5), radius(0.01, 0.06);
  Model m;
  m.name = "random";
  m.bodies.push_back(makePointMass("M", 1.0));
  for (int i = 0; i < spec.struts; ++i)
    m.bodies.push_back(makeStrut("S" + std::to_string(i), length(rng), radius(rng), 2000.0));
  finalizeModel(m);
  m.q0.setZero(m.nq);
  m.q0.head<3>() = Vec3(0.5, 0.5, 0.5) * spec.side;
  for (int i = 1; i <= spec.struts; ++i)
  {
    const Body& b = m.bodies[i];
    m.q0.segment<3>(b.offset) = spec.side * Vec3(u01(rng), u01(rng), u01(rng));
    m.q0.segment<4>(b.offset + 3) = thetaFromZAxis(randomUnit(rng));
    if (spec.off_sphere)
      m.q0.segment<4>(b.offset + 3) *= 1.0 + 1e-3 * (2.0 * u01(rng) - 1.0);
  }
  for (int i = 1; i <= spec.struts; ++i)
    for (int j = i + 1; j <= spec.struts; ++j)
      if (spec.pair_fraction >= 1.0 || u01(rng) < spec.pair_fraction)
        m.listed_pairs.push_back(makeStrutPair(m, i, j));
  return m;
}

// box of a strut from its two axis ends (independent of BroadPhase's centre +- half extent)
void strutBox(const Model& m, int body, const Eigen::VectorXd& q, double margin, Vec3& lo, Vec3& hi)
{
  const Body& b = m.bodies[body];
  const Vec3 c = q.segment<3>(b.offset);
  const Vec3 axis = rotationMatrix(q.segment<4>(b.offset + 3)).col(2);
  const Vec3 e1 = c - 0.5 * b.length * axis, e2 = c + 0.5 * b.length * axis;
  lo = e1.cwiseMin(e2) - Vec3::Constant(b.radius() + margin);
  hi = e1.cwiseMax(e2) + Vec3::Constant(b.radius() + margin);
}

// largest separation of the two boxes over the axes (negative: they overlap)
double boxSeparation(const Model& m, const StrutPair& p, const Eigen::VectorXd& q, double margin)
{
  Vec3 lo_a, hi_a, lo_b, hi_b;
  strutBox(m, p.body_a, q, margin, lo_a, hi_a);
  strutBox(m, p.body_b, q, margin, lo_b, hi_b);
  return std::max((lo_b - hi_a).maxCoeff(), (lo_a - hi_b).maxCoeff());
}

struct SceneCounts
{
  int pairs = 0, candidates = 0, closer_than_margin = 0, touching = 0;
};

// every check of one scene at one margin; returns the counts for the scene-level expectations
SceneCounts checkScene(const Model& m, double margin, const std::string& what)
{
  SCOPED_TRACE(what + ", margin " + std::to_string(margin));
  const BroadPhase broad(m);
  std::vector<int> cand, sw, dir;
  broad.candidates(m.q0, margin, cand);
  broad.sweep(m.q0, margin, sw);
  broad.direct(m.q0, margin, dir);
  EXPECT_EQ(cand, sw);
  EXPECT_EQ(sw, dir);
  EXPECT_TRUE(std::is_sorted(cand.begin(), cand.end()));
  EXPECT_EQ(std::adjacent_find(cand.begin(), cand.end()), cand.end());  // no pair twice
  const std::set<int> in(cand.begin(), cand.end());
  SceneCounts n;
  n.pairs = static_cast<int>(m.checkedPairCount());
  n.candidates = static_cast<int>(cand.size());
  for (int i = 0; i < m.pairSlots(); ++i)
  {
    const bool listed = in.count(i) > 0;
    if (!m.isCheckedPair(i))
    {
      EXPECT_FALSE(listed) << "slot " << i << " of two struts sharing a node";
      continue;
    }
    const ContactPairState st = contactGeometry(m, i, m.q0);
    if (st.gap < margin)
    {
      ++n.closer_than_margin;
      EXPECT_TRUE(listed) << "missed pair " << i << " with gap " << st.gap;
    }
    if (st.gap < 0.0)
      ++n.touching;
    // exactly the pairs whose boxes overlap (ties within rounding either way)
    const double sep = boxSeparation(m, m.strutPair(i), m.q0, margin);
    if (sep < -1e-12)
    {
      EXPECT_TRUE(listed) << "pair " << i << ": boxes overlap by " << -sep;
    }
    else if (sep > 1e-12)
    {
      EXPECT_FALSE(listed) << "pair " << i << ": boxes " << sep << " apart";
    }
  }
  return n;
}

// two parallel struts along z (radius 0.02 m, length 1 m), B at x = dx from A
Model parallelPair(double dx)
{
  Model m;
  m.bodies.push_back(makeStrut("A", 1.0, 0.02, 2000.0));
  m.bodies.push_back(makeStrut("B", 1.0, 0.02, 2000.0));
  finalizeModel(m);
  m.listed_pairs.push_back(makeStrutPair(m, 0, 1));
  m.q0.setZero(m.nq);
  m.q0.segment<4>(3) = thetaFromZAxis(Vec3::UnitZ());
  m.q0.segment<3>(7) = Vec3(dx, 0.0, 0.0);
  m.q0.segment<4>(10) = thetaFromZAxis(Vec3::UnitZ());
  return m;
}
}  // namespace

TEST(BroadPhase, RandomScenesAllPairsMatchTheDirectComparisonAndMissNoContact)
{
  // the cube shrinks relative to n^(1/3) so that the small scenes are crowded too
  const std::vector<SceneSpec> specs = { { 10, 1.0 }, { 50, 1.8 }, { 200, 3.0 } };
  std::mt19937 rng(21);
  for (const SceneSpec& spec : specs)
  {
    int touching = 0;
    for (int rep = 0; rep < 10; ++rep)
    {
      const Model m = randomScene(spec, rng);
      const std::string what = std::to_string(spec.struts) + " struts, all pairs, scene " + std::to_string(rep);
      for (double margin : { 0.0, 0.05 })
      {
        const SceneCounts n = checkScene(m, margin, what);
        EXPECT_EQ(n.pairs, spec.struts * (spec.struts - 1) / 2);
        // sparse enough that the broad phase prunes
        EXPECT_LT(n.candidates, n.pairs) << what << ", margin " << margin;
        EXPECT_GE(n.candidates, n.closer_than_margin) << what;
        touching += margin == 0.0 ? n.touching : 0;
      }
    }
    // crowded enough that contacts exist: at least one per scene on average (10 struts: ~2.5, 50: ~20,
    // 200: ~85 with this seed)
    EXPECT_GE(touching, 10) << spec.struts << " struts";
  }
}

TEST(BroadPhase, RandomScenesWithASubsetOfPairsAndThetaOffTheSphere)
{
  const std::vector<SceneSpec> specs = { { 10, 1.0, 0.4 }, { 50, 1.8, 0.3 }, { 200, 3.0, 0.2, true } };
  std::mt19937 rng(22);
  int touching = 0;
  for (const SceneSpec& spec : specs)
    for (int rep = 0; rep < 10; ++rep)
    {
      const Model m = randomScene(spec, rng);
      ASSERT_LT(static_cast<int>(m.checkedPairList().size()), spec.struts * (spec.struts - 1) / 2);
      const std::string what = std::to_string(spec.struts) + " struts, subset, scene " + std::to_string(rep);
      for (double margin : { 0.0, 0.05 })
      {
        const SceneCounts n = checkScene(m, margin, what);
        EXPECT_LT(n.candidates, n.pairs) << what;
        touching += margin == 0.0 ? n.touching : 0;
      }
    }
  EXPECT_GT(touching, 10);
}

TEST(BroadPhase, SweepForManyPairsPerStrutDirectForFew)
{
  std::mt19937 rng(23);
  const Model all = randomScene({ 200, 3.5 }, rng);
  EXPECT_TRUE(BroadPhase(all).usesSweep());
  // a chain: each strut checked against its successor only (one pair per strut)
  Model chain = randomScene({ 200, 3.5, 0.0 }, rng);
  ASSERT_TRUE(chain.checkedPairList().empty());
  for (int i = 1; i < 200; ++i)
    chain.listed_pairs.push_back(makeStrutPair(chain, i, i + 1));
  EXPECT_FALSE(BroadPhase(chain).usesSweep());
  // both answers still agree for the chain (candidates() goes the direct way here)
  for (double margin : { 0.0, 0.05 })
    checkScene(chain, margin, "chain");
}

// Every two struts that share no node (`pairs: auto`): numbered, not stored. Each slot's bodies, its constants
// and its slot back agree; the struts sharing a node are gaps; the broad phase finds what it finds for the same
// pairs listed, in both its ways; the minimum gap through the broad phase equals every pair's.
TEST(AllStrutPairs, NumberEveryPairOnceAndTheBroadPhaseFindsThemAsForAList)
{
  std::mt19937 rng(31);
  for (int rep = 0; rep < 4; ++rep)
  {
    Model m = randomScene({ 60, 2.0, 0.0 }, rng);  // a point mass (body 0), then 60 struts; nothing listed
    m.contact.enabled = true;
    std::vector<int> struts;
    for (int b = 1; b <= 60; ++b)
      struts.push_back(b);
    std::shuffle(struts.begin(), struts.end(), rng);  // any order given: numbered ascending
    std::uniform_int_distribution<int> strut(1, 60);
    std::vector<std::pair<int, int>> joined = { { 0, 5 } };  // a point mass and a strut: no strut pair
    std::set<std::pair<int, int>> joined_struts;
    for (int k = 0; k < 40; ++k)
    {
      const int a = strut(rng), b = strut(rng);
      joined.emplace_back(a, b);
      if (a != b)
        joined_struts.insert({ std::min(a, b), std::max(a, b) });
    }
    m.checkAllStrutPairs(struts, joined);
    ASSERT_EQ(m.pairSlots(), 60 * 59 / 2);
    ASSERT_EQ(m.checkedPairCount(), 60 * 59 / 2 - static_cast<long>(joined_struts.size()));
    std::pair<int, int> previous = { -1, -1 };
    for (int slot = 0; slot < m.pairSlots(); ++slot)
    {
      const auto [a, b] = m.pairBodies(slot);
      ASSERT_TRUE(a >= 1 && a < b && b <= 60) << "slot " << slot;
      ASSERT_LT(previous, std::make_pair(a, b)) << "slot " << slot;  // in the order of the struts' pairs
      previous = { a, b };
      const bool shares = joined_struts.count({ a, b }) > 0;
      ASSERT_EQ(m.isCheckedPair(slot), !shares) << "slot " << slot;
      ASSERT_EQ(m.allPairsSlot(a, b), shares ? -1 : slot);
      ASSERT_EQ(m.allPairsSlot(b, a), shares ? -1 : slot);
      const StrutPair p = m.strutPair(slot), made = makeStrutPair(m, a, b);
      ASSERT_EQ(p.body_a, a);
      ASSERT_EQ(p.body_b, b);
      ASSERT_EQ(p.stiffness90, made.stiffness90);
    }
    EXPECT_EQ(previous, std::make_pair(59, 60));
    EXPECT_EQ(m.allPairsSlot(0, 5), -1);  // not a strut
    EXPECT_EQ(m.allPairsSlot(7, 7), -1);
    for (double margin : { 0.0, 0.05 })
      checkScene(m, margin, "all strut pairs, scene " + std::to_string(rep));
    // the same pairs listed: the same pairs found
    Model listed = m;
    std::vector<int> slots;
    listed.listed_pairs = m.checkedPairList(&slots);
    listed.all_strut_pairs = false;
    ASSERT_EQ(static_cast<long>(slots.size()), m.checkedPairCount());
    std::vector<int> numbered, found;
    BroadPhase(m).candidates(m.q0, 0.05, numbered);
    BroadPhase(listed).candidates(m.q0, 0.05, found);
    ASSERT_EQ(numbered.size(), found.size());
    for (size_t k = 0; k < found.size(); ++k)
      EXPECT_EQ(numbered[k], slots[static_cast<size_t>(found[k])]);
    // the minimum gap: every pair's, and through the broad phase
    double every = std::numeric_limits<double>::infinity();
    for (int slot = 0; slot < m.pairSlots(); ++slot)
      if (m.isCheckedPair(slot))
        every = std::min(every, contactGeometry(m, slot, m.q0).gap);
    EXPECT_EQ(minimumGap(m, m.q0), every);
    EXPECT_EQ(minimumGapNear(m, BroadPhase(m), m.q0), every);
    EXPECT_EQ(minimumGapNear(listed, BroadPhase(listed), m.q0), every);
    // spread out (the first margins find nothing near)
    Eigen::VectorXd far = m.q0;
    for (int b = 1; b <= 60; ++b)
      far.segment<3>(m.bodies[b].offset) *= 40.0;
    double every_far = std::numeric_limits<double>::infinity();
    for (int slot = 0; slot < m.pairSlots(); ++slot)
      if (m.isCheckedPair(slot))
        every_far = std::min(every_far, contactGeometry(m, slot, far).gap);
    EXPECT_GT(every_far, 1.0);
    EXPECT_EQ(minimumGapNear(m, BroadPhase(m), far), every_far);
  }
}

TEST(AllStrutPairs, NumberTheMostStrutsAndRefuseOneMore)
{
  Model m;
  const int n = Model::kMostAutoPairStruts;
  std::vector<int> struts;
  for (int i = 0; i < n; ++i)
  {
    m.bodies.push_back(makeStrut("S" + std::to_string(i), 1.0, 0.01, 1000.0));
    struts.push_back(i);
  }
  m.checkAllStrutPairs(struts, { { 0, 1 } });
  const long long slots = static_cast<long long>(n) * (n - 1) / 2;
  ASSERT_EQ(m.pairSlots(), slots);
  // 4 (slots + 2 ground spheres a strut) fits an int: rviz marker ids
  EXPECT_LE(4 * (slots + 2LL * n), static_cast<long long>(std::numeric_limits<int>::max()));
  // every row's first and last slot, and random ones: the bodies and back
  const auto check = [&m](long long slot)
  {
    const auto [a, b] = m.pairBodies(static_cast<int>(slot));
    ASSERT_TRUE(a >= 0 && a < b && b < Model::kMostAutoPairStruts) << "slot " << slot;
    if (a == 0 && b == 1)
      ASSERT_EQ(m.allPairsSlot(a, b), -1);
    else
      ASSERT_EQ(m.allPairsSlot(a, b), slot);
  };
  long long first = 0;
  for (long long k = 0; k + 1 < n; ++k)
  {
    check(first);
    check(first + (n - k - 1) - 1);
    ASSERT_EQ(m.pairBodies(static_cast<int>(first)), std::make_pair(static_cast<int>(k), static_cast<int>(k + 1)));
    first += n - k - 1;
  }
  ASSERT_EQ(first, slots);
  std::mt19937 rng(32);
  std::uniform_int_distribution<long long> any(0, slots - 1);
  for (int k = 0; k < 100000; ++k)
    check(any(rng));
  m.bodies.push_back(makeStrut("one more", 1.0, 0.01, 1000.0));
  struts.push_back(n);
  try
  {
    m.checkAllStrutPairs(struts, {});
    FAIL() << "numbered the pairs of " << n + 1 << " struts";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("at most 32000 struts, the scene has 32001"), std::string::npos) << e.what();
  }
}

TEST(BroadPhase, NoPairsNoCandidates)
{
  std::mt19937 rng(24);
  const Model m = randomScene({ 20, 0.5, 0.0 }, rng);  // crowded, but nothing checked
  const BroadPhase broad(m);
  std::vector<int> out = { 7 };
  broad.candidates(m.q0, 0.05, out);
  EXPECT_TRUE(out.empty());
  out = { 7 };
  broad.sweep(m.q0, 0.05, out);
  EXPECT_TRUE(out.empty());
  out = { 7 };
  broad.direct(m.q0, 0.05, out);
  EXPECT_TRUE(out.empty());
}

TEST(BroadPhase, StrutsFarApartAreNoCandidateUntilMovedIntoContact)
{
  Model m = parallelPair(0.0);
  // A along x at the origin, B along y 3 m away in every direction
  m.q0.segment<4>(3) = thetaFromZAxis(Vec3::UnitX());
  m.q0.segment<3>(7) = Vec3(3.0, 3.0, 3.0);
  m.q0.segment<4>(10) = thetaFromZAxis(Vec3::UnitY());
  const BroadPhase broad(m);
  std::vector<int> sw, dir;
  broad.sweep(m.q0, 0.05, sw);
  broad.direct(m.q0, 0.05, dir);
  EXPECT_TRUE(sw.empty());
  EXPECT_TRUE(dir.empty());
  // B moved over A's middle, crossing it with 1 mm of overlap
  Eigen::VectorXd q = m.q0;
  q.segment<3>(7) = Vec3(0.1, 0.2, 0.04 - 1e-3);
  ASSERT_NEAR(contactGeometry(m, 0, q).gap, -1e-3, 1e-12);
  broad.sweep(q, 0.0, sw);
  broad.direct(q, 0.0, dir);
  EXPECT_EQ(sw, std::vector<int>{ 0 });
  EXPECT_EQ(dir, std::vector<int>{ 0 });
  // and out again along z only: the boxes part in z alone
  q.segment<3>(7).z() = 0.2;
  broad.sweep(q, 0.0, sw);
  broad.direct(q, 0.0, dir);
  EXPECT_TRUE(sw.empty());
  EXPECT_TRUE(dir.empty());
}

TEST(BroadPhase, EachBoxGrowsByTheMargin)
{
  // parallel struts 0.03 m apart (surface to surface): the boxes are exact in x, so they overlap
  // once each has grown by half the gap
  const Model m = parallelPair(0.04 + 0.03);
  ASSERT_NEAR(contactGeometry(m, 0, m.q0).gap, 0.03, 1e-12);
  const BroadPhase broad(m);
  std::vector<int> sw, dir;
  for (double margin : { 0.0, 0.014 })
  {
    broad.sweep(m.q0, margin, sw);
    broad.direct(m.q0, margin, dir);
    EXPECT_TRUE(sw.empty()) << margin;
    EXPECT_TRUE(dir.empty()) << margin;
  }
  for (double margin : { 0.016, 0.05 })
  {
    broad.sweep(m.q0, margin, sw);
    broad.direct(m.q0, margin, dir);
    EXPECT_EQ(sw, std::vector<int>{ 0 }) << margin;
    EXPECT_EQ(dir, std::vector<int>{ 0 }) << margin;
  }
}

TEST(BroadPhase, BoxesThatJustTouchAreCandidatesBothWays)
{
  // surfaces touching (gap 0, exact in binary): the boxes share a face, and closed boxes overlap
  const Model m = parallelPair(0.04);
  ASSERT_EQ(contactGeometry(m, 0, m.q0).gap, 0.0);
  const BroadPhase broad(m);
  std::vector<int> sw, dir;
  broad.sweep(m.q0, 0.0, sw);
  broad.direct(m.q0, 0.0, dir);
  EXPECT_EQ(sw, std::vector<int>{ 0 });
  EXPECT_EQ(dir, std::vector<int>{ 0 });
}

TEST(BroadPhase, ParallelLatticeWithTiesOnTheSweepAxis)
{
  // 6 x 6 struts along z on a square grid, spacing 2 r + 1 mm in x (apart) and 2 r - 1 mm in y
  // (touching): many equal box ends on the sweep axis
  Model m;
  const double r = 0.02;
  for (int i = 0; i < 36; ++i)
    m.bodies.push_back(makeStrut("S" + std::to_string(i), 1.0, r, 2000.0));
  finalizeModel(m);
  m.q0.setZero(m.nq);
  for (int i = 0; i < 36; ++i)
  {
    const Body& b = m.bodies[i];
    m.q0.segment<3>(b.offset) = Vec3((i % 6) * (2 * r + 1e-3), (i / 6) * (2 * r - 1e-3), 0.0);
    m.q0.segment<4>(b.offset + 3) = thetaFromZAxis(Vec3::UnitZ());
  }
  for (int i = 0; i < 36; ++i)
    for (int j = i + 1; j < 36; ++j)
      m.listed_pairs.push_back(makeStrutPair(m, i, j));
  ASSERT_TRUE(BroadPhase(m).usesSweep());
  const SceneCounts n = checkScene(m, 0.0, "lattice");
  EXPECT_EQ(n.touching, 6 * 5);    // neighbours in y
  EXPECT_EQ(n.candidates, 6 * 5);  // x neighbours 1 mm apart are no candidates
}

TEST(BroadPhase, AxisAlignedStrutsTouchingBy1nmAreCandidates)
{
  // the tightest boxes: axis-aligned struts end to end and end against side, overlapping by 1e-9 m
  // (no margin), then apart by 1e-9 m
  for (int axis = 0; axis < 3; ++axis)
    for (double sign : { -1.0, 1.0 })
      for (double overlap : { 1e-9, -1e-9 })
      {
        const Vec3 e = sign * Vec3::Unit(axis), side = Vec3::Unit((axis + 1) % 3);
        Model m = parallelPair(0.0);
        // end to end: B collinear beyond A's end along e
        m.q0.segment<4>(3) = thetaFromZAxis(e);
        m.q0.segment<4>(10) = thetaFromZAxis(e);
        m.q0.segment<3>(7) = (1.0 + 0.04 - overlap) * e;
        // end against side: C across e, its middle just beyond A's other end (A's end cap on C's side)
        m.bodies.push_back(makeStrut("C", 1.0, 0.02, 2000.0));
        const Eigen::VectorXd q_ab = m.q0;
        finalizeModel(m);
        m.q0.setZero(m.nq);
        m.q0.head(q_ab.size()) = q_ab;
        m.q0.segment<3>(14) = (-0.5 - 0.04 + overlap) * e;
        m.q0.segment<4>(17) = thetaFromZAxis(side);
        m.listed_pairs.push_back(makeStrutPair(m, 0, 2));
        const std::string what = "axis " + std::to_string(axis) + (sign > 0.0 ? " +" : " -") +
                                 (overlap > 0.0 ? ", overlapping by 1 nm" : ", 1 nm apart");
        for (int p = 0; p < 2; ++p)
          ASSERT_NEAR(contactGeometry(m, p, m.q0).gap, -overlap, 1e-12) << what << ", pair " << p;
        const BroadPhase broad(m);
        std::vector<int> sw, dir;
        broad.sweep(m.q0, 0.0, sw);
        broad.direct(m.q0, 0.0, dir);
        const std::vector<int> expected = overlap > 0.0 ? std::vector<int>{ 0, 1 } : std::vector<int>{};
        EXPECT_EQ(sw, expected) << what;
        EXPECT_EQ(dir, expected) << what;
      }
}

TEST(BroadPhase, APairListedTwiceIsRefused)
{
  // the sweep finds a pair once: a duplicate would make it disagree with the direct comparison
  Model m = parallelPair(0.03);
  m.listed_pairs.push_back(makeStrutPair(m, 1, 0));
  EXPECT_THROW(BroadPhase{ m }, std::invalid_argument);
}

TEST(NearSlotCache, GivesTheNearSlotsOfEveryConfigurationAlongARandomWalk)
{
  // 50 crowded struts drift and wander (each centre moves by up to reach / 2 per call, half of it along its
  // own direction; now and then all of them jump by 0.2 m, and the reach changes); at every call the kept list must
  // give exactly what nearContactSlots computes from scratch, while rebuilding far less often than it is called
  std::mt19937 rng(31);
  Model m = randomScene({ 50, 1.8 }, rng);
  m.contact.enabled = true;
  const BroadPhase broad(m);
  NearSlotCache cache;
  std::vector<int> fresh, kept, scratch;
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd q = m.q0;
  std::vector<Vec3> drift;  // each body's own direction: the motions add up, as along a trajectory
  for (size_t b = 0; b < m.bodies.size(); ++b)
    drift.push_back(randomUnit(rng));
  const std::vector<double> reaches = { 1e-3, 1e-3, 1e-3, 4e-3, 1e-4 };
  long compared = 0, near_total = 0;
  const int calls = 600;
  for (int k = 0; k < calls; ++k)
  {
    const double reach = reaches[(k / 100) % reaches.size()];
    const bool jump = k % 150 == 149;
    for (size_t i = 0; i < m.bodies.size(); ++i)
    {
      const Body& b = m.bodies[i];
      const double step = jump ? 0.2 : 0.5 * reach;
      q.segment<3>(b.offset) += 0.5 * step * (drift[i] + Vec3(u(rng), u(rng), u(rng)) / std::sqrt(3.0));
      if (b.kind == BodyKind::kStrut)  // (a turn by at most about step / length at the ends)
        q.segment<4>(b.offset + 3) += 0.1 * step / b.length * Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng));
    }
    nearContactSlots(m, broad, q, reach, scratch, fresh);
    cache.find(m, broad, q, reach, kept);
    ASSERT_EQ(kept, fresh) << "call " << k << ", reach " << reach;
    near_total += static_cast<long>(fresh.size());
    ++compared;
  }
  EXPECT_GT(near_total, 10 * compared);  // (crowded: contacts to find at every call)
  std::printf("near slots per call %.1f, kept lists built %ld in %d calls, kept slots passed over by their bound %ld\n",
              static_cast<double>(near_total) / compared, cache.rebuilds(), calls, cache.bounded());
  EXPECT_LT(cache.rebuilds(), calls / 4);
  EXPECT_GE(cache.rebuilds(), 4);  // at least the first list and one per jump
  // the kept slots' bounds spare narrow phases (while exact: the comparisons above)
  EXPECT_GT(cache.bounded(), 5 * compared);
}

TEST(NearSlotCache, TakesTheGapsItIsGivenForTheSlotsThatHaveThem)
{
  // the gaps of about half the slots given (evaluated at q, as the dynamics gives those of the last step's end):
  // the same slots as from scratch; a given gap is taken as it is (a slot far apart listed when told it touches)
  std::mt19937 rng(5);
  Model m = randomScene({ 50, 1.8 }, rng);
  m.contact.enabled = true;
  const BroadPhase broad(m);
  NearSlotCache cache, told;
  std::vector<int> fresh, kept, scratch, candidates;
  const int slots = m.contactSlots();
  SlotValues known(slots, std::numeric_limits<double>::quiet_NaN());
  std::bernoulli_distribution half(0.5);
  Eigen::VectorXd q = m.q0;
  const double reach = 1e-3;
  int given = 0;
  for (int k = 0; k < 20; ++k)
  {
    for (const Body& b : m.bodies)
      q.segment<3>(b.offset) += 0.3 * reach * randomUnit(rng);
    known.reset(slots, std::numeric_limits<double>::quiet_NaN());
    for (int i = 0; i < slots; ++i)
      if (half(rng))
      {
        known.set(i, contactGeometry(m, i, q).gap);
        ++given;
      }
    nearContactSlots(m, broad, q, reach, scratch, fresh);
    cache.find(m, broad, q, reach, kept, &known);
    ASSERT_EQ(kept, fresh) << "call " << k;
  }
  EXPECT_GT(given, 0);
  // a candidate of the grown boxes that is apart beyond 2 reach, told it touches
  contactCandidates(m, broad, q, 16.0 * reach, candidates);
  int far = -1;
  for (int i : candidates)
    if (contactGeometry(m, i, q).gap > 2.0 * reach)
      far = i;
  ASSERT_GE(far, 0);
  known.reset(slots, std::numeric_limits<double>::quiet_NaN());
  known.set(far, -1e-3);
  told.find(m, broad, q, reach, kept, &known);
  EXPECT_NE(std::find(kept.begin(), kept.end(), far), kept.end());
  EXPECT_EQ(kept.size(), fresh.size() + 1);
}
