// tarmac_msgs/DebrisArray <-> core::Debris (conversions.hpp).

#include "conversions.hpp"

namespace tarmac::transport {

void fill_debris_array(std::span<const core::Debris> debris, std::int64_t stamp_ns,
                       const std::string& frame_id, DebrisArrayMsg& msg) {
  msg.header().stamp(to_time_msg(stamp_ns));
  msg.header().frame_id() = frame_id;
  msg.objects().resize(debris.size());
  for (std::size_t i = 0; i < debris.size(); ++i) {
    const core::Debris& d = debris[i];
    auto& m = msg.objects()[i];
    m.id(d.id);
    m.position().x(d.xy_W.x());
    m.position().y(d.xy_W.y());
    m.position().z(d.ground_z_m);
    m.footprint_m(static_cast<float>(d.footprint_m));
    m.height_m(static_cast<float>(d.height_m));
    m.first_seen(to_time_msg(d.first_seen_ns));
    m.last_confirmed(to_time_msg(d.last_confirmed_ns));
    m.returns(d.returns);
  }
}

std::vector<core::Debris> from_debris_array(const DebrisArrayMsg& msg) {
  std::vector<core::Debris> out;
  out.reserve(msg.objects().size());
  for (const auto& m : msg.objects()) {
    core::Debris d;
    d.id = m.id();
    d.xy_W = Eigen::Vector2d(m.position().x(), m.position().y());
    d.ground_z_m = m.position().z();
    d.footprint_m = m.footprint_m();
    d.height_m = m.height_m();
    d.first_seen_ns = from_time_msg(m.first_seen());
    d.last_confirmed_ns = from_time_msg(m.last_confirmed());
    d.returns = m.returns();
    out.push_back(d);
  }
  return out;
}

}  // namespace tarmac::transport
