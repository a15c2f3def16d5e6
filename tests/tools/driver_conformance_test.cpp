// Each modelled ROS 2 LiDAR driver's PointCloud2 (tarmac-sim's driver_cloud.hpp, built as the
// driver's source builds it) read back by tarmac's transport and organised by the core: the
// returns all kept, the beams without return rebuilt within 0.2° of the simulator's, the point
// times recovered where the driver gives them. The mapping of each driver's sweeps is judged
// against the grid's in airside_mapping_test.cpp (DriversMessages_*).

#include <cmath>
#include <cstdio>
#include <numbers>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "tarmac/core/organised_scan.hpp"
#include "tarmac/replay/driver_message.hpp"
#include "tarmac/sim/driver_cloud.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace tarmac {
namespace {

constexpr std::int64_t kSweepStartNs = 1'765'000'000'123'456'789;  // an epoch stamp, 2025
constexpr double kPeriodS = 0.1;

struct Sweep {
  sim::LidarParams lidar;
  std::vector<sim::LidarReturn> returns;
};

/// One sweep of the airside scene 30 m down the default path (aircraft, cones, debris around),
/// with 5 % of the returns lost.
Sweep airside_sweep() {
  const sim::Scene scene = sim::Scene::airside_default();
  sim::SequenceParams seq;
  seq.lidar.dropout = 0.05;
  Sweep s;
  s.lidar = seq.lidar;
  const sim::Lidar lidar(seq.lidar);
  const double t_s = 30.0 / seq.path.speed_mps;
  lidar.scan(scene, seq.path.T_W_S(t_s), t_s, nullptr, s.returns);
  return s;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

TEST(DriverConformance, EachDriversSweep_ReturnsKept_BeamsWithoutReturnWithin0_2Degrees_Times) {
  const Sweep s = airside_sweep();
  const sim::Lidar lidar(s.lidar);
  const int beams = s.lidar.beams, steps = s.lidar.azimuth_steps;
  std::vector<char> returned(static_cast<std::size_t>(beams * steps), 0);
  for (const auto& r : s.returns)
    returned[static_cast<std::size_t>(r.beam * steps + r.azimuth_step)] = 1;
  const std::size_t missing = returned.size() - s.returns.size();
  const double beam_step_deg =
      (s.lidar.max_elevation_deg - s.lidar.min_elevation_deg) / (beams - 1);

  for (const sim::Driver driver : sim::all_drivers()) {
    SCOPED_TRACE(std::string(sim::driver_name(driver)));
    const sim::DriverCloud sent =
        sim::encode_sweep(driver, s.lidar, s.returns, kSweepStartNs, kPeriodS);
    const transport::PointCloud2Msg msg = tools::driver_message(sent, "lidar_front");
    core::PointCloud cloud;
    transport::CloudNotes notes;
    ASSERT_TRUE(transport::from_point_cloud2(msg, cloud, &notes).ok());
    EXPECT_FALSE(notes.time_unrelated);

    // Every point time is its firing's (Hesai: its packet's), from the stamp.
    ASSERT_TRUE(cloud.has_time());
    std::size_t timed = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const Eigen::Vector3f& p = cloud.points_S[i];
      if (!p.allFinite() || p.isZero(0.0f)) continue;
      const double az = std::atan2(static_cast<double>(p.y()), static_cast<double>(p.x()));
      int step = static_cast<int>(std::lround(az / (2.0 * std::numbers::pi) * steps));
      step = (step % steps + steps) % steps;
      std::int64_t fired = sim::firing_time_ns(s.lidar, step, kPeriodS);
      if (driver == sim::Driver::kHesai) {  // one time per packet of 6 firings
        const std::int64_t k = (steps - step) % steps;
        fired =
            sim::firing_time_ns(s.lidar, static_cast<int>((steps - (k - k % 6)) % steps), kPeriodS);
      }
      const double want_s = static_cast<double>(kSweepStartNs + fired - sent.stamp_ns) / 1e9;
      EXPECT_NEAR(cloud.time_offset_s[i], want_s, 1e-6) << "point " << i;
      ++timed;
    }
    EXPECT_EQ(timed, s.returns.size());

    core::OrganisedScratch scratch;
    const core::OrganisedCounts counts = core::organise(cloud, scratch);
    EXPECT_NE(counts.layout, core::SweepLayout::kUndecided);
    EXPECT_EQ(cloud.size(), s.returns.size()) << "every return kept";
    // Each rebuilt direction is one of the simulator's beams that returned nothing.
    std::size_t off = 0, twice = 0;
    std::vector<char> found(returned.size(), 0);
    double worst = 0.0;
    for (const Eigen::Vector3f& d : cloud.no_return_S) {
      const double el =
          std::asin(std::clamp(static_cast<double>(d.z()), -1.0, 1.0)) * 180.0 / std::numbers::pi;
      const double az = std::atan2(static_cast<double>(d.y()), static_cast<double>(d.x()));
      const int beam =
          static_cast<int>(std::lround((el - s.lidar.min_elevation_deg) / beam_step_deg));
      int step = static_cast<int>(std::lround(az / (2.0 * std::numbers::pi) * steps));
      step = (step % steps + steps) % steps;
      if (beam < 0 || beam >= beams) {
        ++off;
        continue;
      }
      const std::size_t cell = static_cast<std::size_t>(beam * steps + step);
      const double err = angle_deg(d.cast<double>(), lidar.direction_S(beam, step));
      worst = std::max(worst, err);
      if (returned[cell] != 0 || err > 0.2) ++off;
      twice += found[cell] != 0 ? 1 : 0;
      found[cell] = 1;
    }
    std::printf(
        "%-14s %ux%u, point_step %u: %zu returns, %zu of %zu beams without return "
        "rebuilt (worst %.3f deg), %zu off\n",
        std::string(sim::driver_name(driver)).c_str(), sent.height, sent.width, sent.point_step,
        cloud.size(), cloud.no_return_S.size(), missing, worst, off);
    EXPECT_EQ(off, 0u);
    EXPECT_EQ(twice, 0u);
    // Grids and Hesai's markers name every cell; a list without markers cannot show a ring
    // above the highest that returned.
    const bool every_cell = driver == sim::Driver::kOuster || driver == sim::Driver::kVelodyne ||
                            driver == sim::Driver::kRslidarXYZIRT || driver == sim::Driver::kHesai;
    if (every_cell) {
      EXPECT_EQ(cloud.no_return_S.size(), missing);
    } else {
      EXPECT_GE(cloud.no_return_S.size(), missing * 9 / 10);
    }
  }
}

transport::LidarDriver preset_of(sim::Driver d) {
  switch (d) {
    case sim::Driver::kOuster: return transport::LidarDriver::kOuster;
    case sim::Driver::kVelodyne:
    case sim::Driver::kVelodyneList: return transport::LidarDriver::kVelodyne;
    case sim::Driver::kRslidarXYZIRT: return transport::LidarDriver::kRslidar;
    case sim::Driver::kHesai: return transport::LidarDriver::kHesai;
    case sim::Driver::kAutowareXYZIRCAEDT: return transport::LidarDriver::kAutoware;
  }
  return transport::LidarDriver::kAuto;
}

TEST(DriverConformance, Presets_ReadTheirDriver_RefuseAnother_FixTheTimeOriginNearTheEpoch) {
  const Sweep s = airside_sweep();
  for (const sim::Driver driver : sim::all_drivers()) {
    SCOPED_TRACE(std::string(sim::driver_name(driver)));
    const auto msg = tools::driver_message(
        sim::encode_sweep(driver, s.lidar, s.returns, kSweepStartNs, kPeriodS), "lidar");
    core::PointCloud by_preset, by_auto;
    ASSERT_TRUE(transport::from_point_cloud2(msg, by_preset, nullptr, preset_of(driver)).ok());
    ASSERT_TRUE(transport::from_point_cloud2(msg, by_auto).ok());
    EXPECT_EQ(by_preset.ring, by_auto.ring);
    ASSERT_EQ(by_preset.time_offset_s.size(), by_auto.time_offset_s.size());
    for (std::size_t i = 0; i < by_auto.size(); ++i) {
      if (std::isnan(by_auto.time_offset_s[i])) continue;
      ASSERT_NEAR(by_preset.time_offset_s[i], by_auto.time_offset_s[i], 1e-6) << i;
    }
    // Another driver's message is refused, with the field the preset wanted.
    const auto other = preset_of(driver) == transport::LidarDriver::kOuster
                           ? transport::LidarDriver::kVelodyne
                           : transport::LidarDriver::kOuster;
    core::PointCloud refused;
    const auto status = transport::from_point_cloud2(msg, refused, nullptr, other);
    ASSERT_FALSE(status.ok());
    EXPECT_EQ(status.error().code, "pointcloud.driver_mismatch");
  }
  // A sensor clock a few seconds after its epoch (a simulator, a bench unit without PTP):
  // Hesai's absolute seconds look like seconds from the stamp. Told from the values they are
  // read so, 0.5 s off; the preset reads them as what they are.
  const std::int64_t early_ns = 500'000'000;
  const auto msg = tools::driver_message(
      sim::encode_sweep(sim::Driver::kHesai, s.lidar, s.returns, early_ns, kPeriodS), "lidar");
  core::PointCloud by_preset, by_auto;
  ASSERT_TRUE(
      transport::from_point_cloud2(msg, by_preset, nullptr, transport::LidarDriver::kHesai).ok());
  ASSERT_TRUE(transport::from_point_cloud2(msg, by_auto).ok());
  float preset_max = 0.0f, auto_min = 1.0f;
  for (std::size_t i = 0; i < by_preset.size(); ++i) {
    preset_max = std::max(preset_max, by_preset.time_offset_s[i]);
    auto_min = std::min(auto_min, by_auto.time_offset_s[i]);
  }
  EXPECT_LE(preset_max, kPeriodS);
  EXPECT_GE(auto_min, 0.49f) << "the known limit of telling the origin from the values";
}

}  // namespace
}  // namespace tarmac
