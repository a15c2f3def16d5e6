#include "msg_dump.hpp"

#include <cstdarg>
#include <cstdio>

namespace tarmac::test {

namespace {

void line(std::string& out, const char* fmt, ...) {
  char buf[512];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  out += buf;
  out += '\n';
}

void header(std::string& out, const std_msgs::msg::dds_::Header_& h) {
  line(out, "header.stamp.sec=%d", h.stamp().sec());
  line(out, "header.stamp.nanosec=%u", h.stamp().nanosec());
  line(out, "header.frame_id=%s", h.frame_id().c_str());
}

void pose(std::string& out, const char* prefix, const geometry_msgs::msg::dds_::Pose_& p) {
  line(out, "%s.position.x=%a", prefix, p.position().x());
  line(out, "%s.position.y=%a", prefix, p.position().y());
  line(out, "%s.position.z=%a", prefix, p.position().z());
  line(out, "%s.orientation.x=%a", prefix, p.orientation().x());
  line(out, "%s.orientation.y=%a", prefix, p.orientation().y());
  line(out, "%s.orientation.z=%a", prefix, p.orientation().z());
  line(out, "%s.orientation.w=%a", prefix, p.orientation().w());
}

template <typename Byte>
void bytes(std::string& out, const char* name, const std::vector<Byte>& data) {
  line(out, "%s.size=%zu", name, data.size());
  out += name;
  out += '=';
  static const char* kHex = "0123456789abcdef";
  for (const Byte b : data) {
    const auto u = static_cast<unsigned char>(b);
    out += kHex[u >> 4];
    out += kHex[u & 15];
  }
  out += '\n';
}

}  // namespace

std::string dump(const nav_msgs::msg::dds_::OccupancyGrid_& g) {
  std::string out;
  header(out, g.header());
  line(out, "info.map_load_time.sec=%d", g.info().map_load_time().sec());
  line(out, "info.map_load_time.nanosec=%u", g.info().map_load_time().nanosec());
  line(out, "info.resolution=%a", static_cast<double>(g.info().resolution()));
  line(out, "info.width=%u", g.info().width());
  line(out, "info.height=%u", g.info().height());
  pose(out, "info.origin", g.info().origin());
  bytes(out, "data", g.data());
  return out;
}

std::string dump(const sensor_msgs::msg::dds_::PointCloud2_& c) {
  std::string out;
  header(out, c.header());
  line(out, "height=%u", c.height());
  line(out, "width=%u", c.width());
  line(out, "fields.size=%zu", c.fields().size());
  for (std::size_t i = 0; i < c.fields().size(); ++i) {
    const auto& f = c.fields()[i];
    line(out, "fields[%zu].name=%s", i, f.name().c_str());
    line(out, "fields[%zu].offset=%u", i, f.offset());
    line(out, "fields[%zu].datatype=%u", i, static_cast<unsigned>(f.datatype()));
    line(out, "fields[%zu].count=%u", i, f.count());
  }
  line(out, "is_bigendian=%d", c.is_bigendian() ? 1 : 0);
  line(out, "point_step=%u", c.point_step());
  line(out, "row_step=%u", c.row_step());
  bytes(out, "data", c.data());
  line(out, "is_dense=%d", c.is_dense() ? 1 : 0);
  return out;
}

}  // namespace tarmac::test
