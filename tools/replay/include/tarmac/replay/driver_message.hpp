#pragma once
/// @file A tarmac-sim DriverCloud as the PointCloud2 message its driver publishes (transport's
/// type): what tarmac-replay --driver sends and the driver conformance tests read back.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "conversions.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/sim/driver_cloud.hpp"

namespace tarmac::tools {

inline transport::PointCloud2Msg driver_message(const sim::DriverCloud& c,
                                                const std::string& frame_id) {
  transport::PointCloud2Msg msg;
  msg.header().frame_id(frame_id);
  msg.header().stamp(transport::to_time_msg(c.stamp_ns));
  msg.height(c.height);
  msg.width(c.width);
  for (const auto& f : c.fields) {
    sensor_msgs::msg::dds_::PointField_ field;
    field.name(f.name);
    field.offset(f.offset);
    field.datatype(f.datatype);
    field.count(1);
    msg.fields().push_back(field);
  }
  msg.is_bigendian(false);
  msg.point_step(c.point_step);
  msg.row_step(c.point_step * c.width);
  msg.data(c.data);
  msg.is_dense(c.is_dense);
  return msg;
}

/// Organised sweep `grid` (rows = beams, lowest first, by azimuth steps; NaN or (0, 0, 0)
/// where nothing returned, as tarmac-sim writes organised/) as its driver's message, the sweep
/// starting at `stamp_ns` and fired over `period_s`. tarmac-sim's sweeps are instantaneous: give
/// 0, and every point's time is the sweep's (in the driver's unit and origin), so that a daemon
/// that deskews leaves them as they are.
inline transport::PointCloud2Msg driver_sweep_message(const core::PointCloud& grid,
                                                      std::size_t rows, std::size_t cols,
                                                      sim::Driver driver, std::int64_t stamp_ns,
                                                      double period_s,
                                                      const std::string& frame_id) {
  std::vector<sim::LidarReturn> returns;
  for (std::size_t i = 0; i < rows * cols && i < grid.size(); ++i) {
    const Eigen::Vector3f& p = grid.points_S[i];
    if (!p.allFinite() || p.isZero(0.0f)) continue;
    sim::LidarReturn r;
    r.point_S = p.cast<double>();
    r.range_m = r.true_range_m = r.point_S.norm();
    r.intensity = grid.has_intensity() ? grid.intensity[i] : 0.0f;
    r.beam = static_cast<int>(i / cols);
    r.azimuth_step = static_cast<int>(i % cols);
    returns.push_back(r);
  }
  sim::LidarParams lidar;
  lidar.beams = static_cast<int>(rows);
  lidar.azimuth_steps = static_cast<int>(cols);
  return driver_message(sim::encode_sweep(driver, lidar, returns, stamp_ns, period_s), frame_id);
}

}  // namespace tarmac::tools
