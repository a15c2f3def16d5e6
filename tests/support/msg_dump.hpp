#pragma once
// Renders IDL messages as one "path=value" line per field: floats as C99 %a hex (exact), byte
// sequences as hex. The same format as tests/interop/cyclone_peer.c, so that a message seen by
// tarmac and by Cyclone can be compared field by field.

#include <string>

#include "nav_msgs.h"
#include "sensor_msgs.h"

namespace tarmac::test {

std::string dump(const nav_msgs::msg::dds_::OccupancyGrid_& grid);
std::string dump(const sensor_msgs::msg::dds_::PointCloud2_& cloud);

}  // namespace tarmac::test
