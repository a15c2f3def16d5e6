// LowObjects: debris kept across scans, confirmed by its rising returns, removed only by rays
// that went past where it stood or by the ground found at its top.

#include "tarmac/core/low_objects.hpp"

#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <vector>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

constexpr double kVoxel = 0.2;
constexpr int kN = 100;  // a 20 m window from (0, 0)

/// The ground remembered under some columns, lower than a scan's; +inf (none) elsewhere.
struct RememberedGround final : LowObjects::GroundMemory {
  std::map<std::uint32_t, float> z;
  [[nodiscard]] float ground_z(std::uint32_t column) const override {
    const auto it = z.find(column);
    return it == z.end() ? std::numeric_limits<float>::infinity() : it->second;
  }
};

/// One scan's returns, built by hand: each with its rise (cm) and its window column, and the
/// ground remembered under their columns.
struct ScanBuilder {
  std::vector<Eigen::Vector3f> points;
  std::vector<std::uint32_t> voxel, column;
  std::vector<std::uint8_t> rise;
  RememberedGround remembered;

  /// `remembered_below_m`: the ground remembered under its column this far under it (0: none).
  void add(const Eigen::Vector3f& p, int rise_cm, float remembered_below_m = 0.0f) {
    points.push_back(p);
    const int x = static_cast<int>(std::floor(p.x() / kVoxel));
    const int y = static_cast<int>(std::floor(p.y() / kVoxel));
    const bool inside = x >= 0 && y >= 0 && x < kN && y < kN;
    voxel.push_back(inside ? 0u : LowObjects::Scan::kNoColumn);
    column.push_back(inside ? static_cast<std::uint32_t>(y * kN + x) : 0u);
    rise.push_back(static_cast<std::uint8_t>(rise_cm));
    if (remembered_below_m > 0.0f) remembered.z[column.back()] = p.z() - remembered_below_m;
  }
  LowObjects::Scan scan(std::uint32_t number, const Eigen::Vector3f& origin) const {
    LowObjects::Scan s;
    s.origin_W = origin;
    s.points_W = points;
    s.voxel = voxel;
    s.column = column;
    s.rise_cm = rise;
    s.ground = &remembered;
    s.number = number;
    s.stamp_ns = static_cast<std::int64_t>(number) * 100'000'000;
    return s;
  }
};

const Eigen::Vector3f kSensor(2.0f, 10.0f, 2.0f);    // 2 m up, looking along +x
const Eigen::Vector3f kCubeTop(12.0f, 10.0f, 0.1f);  // the front top edge of a 10 cm cube

/// Ground where a beam from the sensor through `at` (a point under 2 m) lands.
Eigen::Vector3f ground_through(const Eigen::Vector3f& at) {
  const float t = kSensor.z() / (kSensor.z() - at.z());
  return kSensor + t * (at - kSensor);
}

LowObjects make() {
  LowObjectParams p;
  EXPECT_TRUE(p.validate().ok());
  LowObjects objects(p, kN, kN, kVoxel);
  objects.place(0, 0);
  return objects;
}

/// Two rising returns on the cube's top edge, `apart`: one scan with them confirms it.
ScanBuilder two_on_its_top(const Eigen::Vector3f& apart) {
  ScanBuilder s;
  s.add(kCubeTop, 10);
  s.add(kCubeTop + apart, 10);
  return s;
}

int confirmed_count(const LowObjects& objects) {
  int n = 0;
  for (const LowObject& o : objects.all()) n += objects.confirmed(o) ? 1 : 0;
  return n;
}

TEST(LowObjects, TwoRisingReturnsConfirmAndLowReturnsOnTheFaceKeepIt) {
  LowObjects objects = make();
  ScanBuilder first;
  first.add(kCubeTop, 10);
  objects.update(first.scan(1, kSensor));
  ASSERT_EQ(objects.all().size(), 1u);
  EXPECT_EQ(confirmed_count(objects), 0) << "one return is a candidate, not an object";
  ScanBuilder second;
  second.add(kCubeTop + Eigen::Vector3f(0.0f, 0.03f, -0.01f), 9);
  objects.update(second.scan(2, kSensor));
  ASSERT_EQ(confirmed_count(objects), 1);
  const std::uint32_t id = objects.all()[0].id;
  // Fifty scans whose beams land on its face low (rise 2 cm: ground height to the eye) and on
  // the ground in front of it: nothing that went past it. It stays, with its id.
  for (std::uint32_t k = 3; k < 53; ++k) {
    ScanBuilder s;
    s.add(Eigen::Vector3f(12.0f, 10.0f, 0.02f), 2);
    s.add(Eigen::Vector3f(11.97f, 10.0f, 0.0f), 0);
    objects.update(s.scan(k, kSensor));
  }
  ASSERT_EQ(confirmed_count(objects), 1);
  EXPECT_EQ(objects.all()[0].id, id);
  EXPECT_EQ(objects.all()[0].returns, 2u);
  EXPECT_EQ(objects.all()[0].scans, 2u) << "one rising return in each of two scans";
}

TEST(LowObjects, TheOrderOfTheReturnsChangesNothing) {
  // Rising returns 12 cm apart in a row (match radius 15 cm): whichever comes first makes an
  // object, the next joins it and moves its centre, the third is then too far and makes
  // another. Taken in the order they came, a driver's layout (rows by beam, by firing, a list)
  // would decide which. Then a beam that goes past under the second object's top, among the
  // rising returns of a second scan.
  const std::vector<Eigen::Vector3f> rising{{12.0f, 10.0f, 0.1f},
                                            {12.12f, 10.0f, 0.1f},
                                            {12.24f, 10.0f, 0.1f},
                                            {15.0f, 8.0f, 0.1f},
                                            {15.01f, 8.01f, 0.09f}};
  const Eigen::Vector3f past = ground_through(Eigen::Vector3f(15.0f, 8.0f, 0.05f));
  const std::vector<std::vector<int>> orders{
      {0, 1, 2, 3, 4, 5}, {5, 4, 3, 2, 1, 0}, {2, 0, 5, 4, 1, 3}};
  std::vector<std::vector<LowObject>> results;
  for (const std::vector<int>& order : orders) {
    LowObjects objects = make();
    for (std::uint32_t number = 1; number <= 3; ++number) {
      ScanBuilder s;
      for (const int k : order) {
        // Scan 1 has every rising return, scans 2 and 3 the first three and the beam past.
        if (k == 5) {
          if (number > 1) s.add(past, 0);
        } else if (number == 1 || k < 3) {
          s.add(rising[static_cast<std::size_t>(k)], 10);
        }
      }
      objects.update(s.scan(number, kSensor));
    }
    results.emplace_back(objects.all().begin(), objects.all().end());
  }
  ASSERT_EQ(results[0].size(), 2u) << "the object the beam went past is gone";
  for (std::size_t r = 1; r < results.size(); ++r) {
    ASSERT_EQ(results[r].size(), results[0].size()) << "order " << r;
    for (std::size_t k = 0; k < results[0].size(); ++k) {
      const LowObject &a = results[0][k], &b = results[r][k];
      EXPECT_EQ(a.id, b.id) << "order " << r << ", object " << k;
      EXPECT_EQ(a.xy_W, b.xy_W) << "order " << r << ", object " << k;
      EXPECT_EQ(a.top_z_W, b.top_z_W);
      EXPECT_EQ(a.returns, b.returns);
      EXPECT_EQ(a.scans, b.scans);
      EXPECT_EQ(a.seen_through, b.seen_through);
    }
  }
}

TEST(LowObjects, RaysThatWentPastUnderItsTopRemoveIt) {
  LowObjects objects = make();
  const ScanBuilder seen = two_on_its_top(Eigen::Vector3f(0.0f, 0.02f, 0.0f));
  objects.update(seen.scan(1, kSensor));
  ASSERT_EQ(confirmed_count(objects), 1);
  EXPECT_EQ(objects.all()[0].scans, 1u) << "two returns, one scan";
  // A beam through where its top was, 5 cm up, lands 0.3 m behind it: gone from there.
  ScanBuilder past;
  past.add(ground_through(Eigen::Vector3f(12.0f, 10.0f, 0.05f)), 0);
  objects.update(past.scan(2, kSensor));
  EXPECT_EQ(confirmed_count(objects), 1) << "one scan is not enough (clear_scans 2)";
  // A rising return on it breaks the run.
  objects.update(seen.scan(3, kSensor));
  objects.update(past.scan(4, kSensor));
  EXPECT_EQ(confirmed_count(objects), 1);
  objects.update(past.scan(5, kSensor));
  EXPECT_EQ(confirmed_count(objects), 0) << "two scans in a row saw through it";
  EXPECT_TRUE(objects.all().empty());
}

TEST(LowObjects, TheGroundFoundAtItsTopRemovesIt) {
  // A glossy floor's mirror returns lower one scan's ground, and the floor itself "rises"
  // 10 cm there. The next scans find the ground where its top was: no object stands there.
  LowObjects objects = make();
  objects.update(two_on_its_top(Eigen::Vector3f(0.02f, 0.0f, 0.0f)).scan(1, kSensor));
  ASSERT_EQ(confirmed_count(objects), 1);
  const Eigen::Vector3f centre(12.01f, 10.0f, 0.1f);
  // Not evidence: a return on its face above this scan's ground (rise 5 cm, 2 cm under its
  // top), one on the ground 8 cm under its top, one at its top's height 12 cm aside, and one
  // at its top's height on this scan's ground but 10 cm above the ground remembered round it
  // (a kerb's top where this scan did not return the road).
  for (std::uint32_t k = 2; k < 12; ++k) {
    ScanBuilder s;
    s.add(centre + Eigen::Vector3f(0.0f, 0.0f, -0.02f), 5);
    s.add(centre + Eigen::Vector3f(-0.03f, 0.0f, -0.08f), 0);
    s.add(centre + Eigen::Vector3f(0.0f, 0.12f, 0.0f), 0);
    s.add(centre + Eigen::Vector3f(-0.04f, 0.0f, 0.0f), 0, 0.10f);
    objects.update(s.scan(k, kSensor));
  }
  ASSERT_EQ(confirmed_count(objects), 1);
  // Evidence: a return on this scan's ground (rise 1 cm) within 8 cm of its centre, 3 cm under
  // its top. One scan is not enough (clear_scans 2); two in a row remove it.
  ScanBuilder floor;
  floor.add(centre + Eigen::Vector3f(-0.05f, 0.03f, -0.03f), 1);
  objects.update(floor.scan(12, kSensor));
  EXPECT_EQ(confirmed_count(objects), 1);
  objects.update(floor.scan(13, kSensor));
  EXPECT_TRUE(objects.all().empty()) << "two scans in a row found the ground at its top";
}

TEST(LowObjects, BeamsOverItsTopOrBesideItDoNotRemoveIt) {
  LowObjects objects = make();
  ScanBuilder seen;
  seen.add(kCubeTop, 10);
  seen.add(kCubeTop, 10);
  objects.update(seen.scan(1, kSensor));
  for (std::uint32_t k = 2; k < 20; ++k) {
    ScanBuilder s;
    // Over its top (12 cm up), and 10 cm beside it, low.
    s.add(ground_through(Eigen::Vector3f(12.0f, 10.0f, 0.12f)), 0);
    s.add(ground_through(Eigen::Vector3f(12.0f, 10.1f, 0.03f)), 0);
    objects.update(s.scan(k, kSensor));
  }
  EXPECT_EQ(confirmed_count(objects), 1);
}

TEST(LowObjects, ALoneReturnLapsesAndTheWindowDropsWhatLeavesIt) {
  LowObjects objects = make();
  ScanBuilder stray;
  stray.add(Eigen::Vector3f(5.0f, 5.0f, 0.1f), 10);
  objects.update(stray.scan(1, kSensor));
  ASSERT_EQ(objects.all().size(), 1u);
  EXPECT_FALSE(objects.confirmed(objects.all()[0]));
  EXPECT_TRUE(objects.lethal(objects.all()[0]))
      << "lethal from its first return (lethal_returns 1)";
  for (std::uint32_t k = 2; k <= 10; ++k) objects.update(ScanBuilder{}.scan(k, kSensor));
  ASSERT_EQ(objects.all().size(), 1u) << "lethal while it waits for a second";
  objects.update(ScanBuilder{}.scan(11, kSensor));
  EXPECT_TRUE(objects.all().empty()) << "candidate_scans without a second return";

  ScanBuilder seen;
  seen.add(kCubeTop, 10);
  seen.add(kCubeTop, 10);
  objects.update(seen.scan(20, kSensor));
  ASSERT_EQ(confirmed_count(objects), 1);
  objects.place(40, 0);  // the window moved 8 m on: x from 8 m
  EXPECT_EQ(confirmed_count(objects), 1);
  objects.place(61, 0);  // x from 12.2 m: its centre left
  EXPECT_TRUE(objects.all().empty());
}

TEST(LowObjects, ReturnsRisingAboveMaxRiseOrOutsideTheWindowMakeNoObject) {
  LowObjects objects = make();
  ScanBuilder s;
  s.add(Eigen::Vector3f(6.0f, 6.0f, 1.0f), 100);  // a wall's return: not low
  s.add(Eigen::Vector3f(6.0f, 6.0f, 1.0f), 100);
  s.add(Eigen::Vector3f(-3.0f, 6.0f, 0.1f), 10);  // outside the window
  s.add(Eigen::Vector3f(-3.0f, 6.0f, 0.1f), 10);
  objects.update(s.scan(1, kSensor));
  EXPECT_TRUE(objects.all().empty());
}

TEST(LowObjects, CapacityRefusesAndCounts) {
  LowObjectParams p;
  p.capacity = 3;
  ASSERT_TRUE(p.validate().ok());
  LowObjects objects(p, kN, kN, kVoxel);
  objects.place(0, 0);
  ScanBuilder s;
  for (int k = 0; k < 5; ++k) s.add(Eigen::Vector3f(3.0f + k, 3.0f, 0.1f), 10);
  objects.update(s.scan(1, kSensor));
  EXPECT_EQ(objects.all().size(), 3u);
  EXPECT_EQ(objects.refused(), 2u);
}

TEST(LowObjects, InvalidParametersAreRefused) {
  LowObjectParams p;
  p.clear_radius_m = 0.5;  // beyond the match radius
  EXPECT_FALSE(p.validate().ok());
  p = LowObjectParams{};
  p.max_rise_m = 0.05;  // under min_rise_m
  EXPECT_FALSE(p.validate().ok());
  p = LowObjectParams{};
  p.clear_scans = 0;
  EXPECT_FALSE(p.validate().ok());
  p = LowObjectParams{};
  p.lethal_returns = 3;  // more than confirm_returns (2)
  EXPECT_FALSE(p.validate().ok());
  p.confirm_returns = 3;
  EXPECT_TRUE(p.validate().ok());
  p.lethal_returns = 0;
  EXPECT_FALSE(p.validate().ok());
}

TEST(LowObjects, LethalReturnsSaysWhenACandidateBlocks) {
  LowObjectParams p;
  p.lethal_returns = 2;
  LowObjects objects(p, kN, kN, kVoxel);
  objects.place(0, 0);
  ScanBuilder one;
  one.add(kCubeTop, 10);
  objects.update(one.scan(1, kSensor));
  ASSERT_EQ(objects.all().size(), 1u);
  EXPECT_FALSE(objects.lethal(objects.all()[0])) << "one return of two";
  objects.update(one.scan(2, kSensor));
  EXPECT_TRUE(objects.lethal(objects.all()[0]));
  EXPECT_TRUE(objects.confirmed(objects.all()[0]));
}

}  // namespace
}  // namespace tarmac::core
