// libFuzzer target: transport::from_point_cloud2, the parser every LiDAR scan goes through.
// The fuzz bytes describe a whole sensor_msgs/PointCloud2 (header, field table, sizes, byte order,
// data); flags can make the sizes consistent so that the point loops, not only the size checks,
// see odd layouts. Properties: a parse either fails with a "pointcloud.*" code or yields
// width*height points with consistent channels, and writing that cloud back out
// (to_point_cloud2) and parsing it again gives the same cloud.

#include <bit>
#include <cmath>
#include <cstring>

#include "conversions.hpp"
#include "fuzz_bytes.hpp"

namespace tarmac::fuzz {
namespace {

using transport::PointCloud2Msg;
namespace pf = sensor_msgs::msg::PointField_Constants;

/// Field names the parser looks for, and one it must ignore; a code past the table is a literal.
const std::vector<std::string> kNames = {"x",    "y", "z",         "intensity", "ring",
                                         "time", "t", "timestamp", "normal_x",  ""};
constexpr std::uint8_t kLiteralName = 255;

enum Flags : std::uint8_t {
  kRowStepFromWidth = 1,  ///< row_step = width * point_step + (the row_step field as padding)
  kDataFromSizes = 2,     ///< data cut or zero-padded to row_step * height (when small enough)
  kBigEndian = 4,
  kDense = 8,
};
constexpr std::size_t kMaxDataBytes = std::size_t{1} << 22;
constexpr std::size_t kMaxFields = 16;

struct Field {
  std::uint8_t name_code = 0;  ///< index into kNames, or kLiteralName
  std::string literal;
  std::uint32_t offset = 0;
  std::uint8_t datatype = pf::FLOAT32;
  std::uint32_t count = 1;
};

struct Recipe {
  std::uint8_t flags = kRowStepFromWidth | kDataFromSizes;
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
  std::string frame_id = "lidar_front";
  std::uint32_t height = 1, width = 0, point_step = 0, row_step = 0;
  std::vector<Field> fields;
  Bytes data;
};

PointCloud2Msg decode(ByteReader& in) {
  PointCloud2Msg msg;
  const auto flags = in.get<std::uint8_t>();
  msg.header().stamp().sec(in.get<std::int32_t>());
  msg.header().stamp().nanosec(in.get<std::uint32_t>());
  msg.header().frame_id(in.string());
  msg.height(in.get<std::uint32_t>());
  msg.width(in.get<std::uint32_t>());
  msg.point_step(in.get<std::uint32_t>());
  const auto row_step = in.get<std::uint32_t>();
  const std::size_t n_fields = in.get<std::uint8_t>() % (kMaxFields + 1);
  for (std::size_t i = 0; i < n_fields; ++i) {
    sensor_msgs::msg::dds_::PointField_ f;
    const auto code = in.get<std::uint8_t>();
    f.name(code < kNames.size() ? kNames[code] : in.string());
    f.offset(in.get<std::uint32_t>());
    f.datatype(in.get<std::uint8_t>());
    f.count(in.get<std::uint32_t>());
    msg.fields().push_back(f);
  }
  const auto rest = in.rest();
  msg.data().assign(rest.begin(), rest.end());
  msg.is_bigendian((flags & kBigEndian) != 0);
  msg.is_dense((flags & kDense) != 0);
  const std::uint64_t packed = std::uint64_t{msg.width()} * msg.point_step();
  msg.row_step((flags & kRowStepFromWidth) != 0 && packed + row_step <= UINT32_MAX
                   ? static_cast<std::uint32_t>(packed + row_step)
                   : row_step);
  const std::uint64_t size = std::uint64_t{msg.row_step()} * msg.height();
  if ((flags & kDataFromSizes) != 0 && size <= kMaxDataBytes) msg.data().resize(size);
  return msg;
}

Bytes encode(const Recipe& r) {
  ByteWriter out;
  out.put(r.flags);
  out.put(r.sec);
  out.put(r.nanosec);
  out.string(r.frame_id);
  out.put(r.height);
  out.put(r.width);
  out.put(r.point_step);
  out.put(r.row_step);
  out.put(static_cast<std::uint8_t>(r.fields.size()));
  for (const Field& f : r.fields) {
    out.put(f.name_code);
    if (f.name_code >= kNames.size()) out.string(f.literal);
    out.put(f.offset);
    out.put(f.datatype);
    out.put(f.count);
  }
  out.bytes(r.data);
  return out.take();
}

bool same_bits(const void* a, const void* b, std::size_t n) {
  return n == 0 || std::memcmp(a, b, n) == 0;  // memcmp wants non-null pointers even for n = 0
}

void check_round_trip(const core::PointCloud& cloud) {
  const PointCloud2Msg again = transport::to_point_cloud2(cloud);
  core::PointCloud reparsed;
  TARMAC_FUZZ_CHECK(transport::from_point_cloud2(again, reparsed).ok());
  TARMAC_FUZZ_CHECK(reparsed.frame_id == cloud.frame_id);
  TARMAC_FUZZ_CHECK(reparsed.stamp_ns == cloud.stamp_ns);
  TARMAC_FUZZ_CHECK(reparsed.size() == cloud.size());
  TARMAC_FUZZ_CHECK(reparsed.intensity.size() == cloud.intensity.size());
  TARMAC_FUZZ_CHECK(reparsed.ring == cloud.ring);
  TARMAC_FUZZ_CHECK(reparsed.time_offset_s.size() == cloud.time_offset_s.size());
  const std::size_t n = cloud.size();
  TARMAC_FUZZ_CHECK(same_bits(reparsed.points_S.data(), cloud.points_S.data(), n * 12));
  TARMAC_FUZZ_CHECK(
      same_bits(reparsed.intensity.data(), cloud.intensity.data(), cloud.intensity.size() * 4));
  // Parsed point times are seconds within 10 s of the stamp, or NaN: written as a relative
  // float32 `time`, they read back bit for bit.
  TARMAC_FUZZ_CHECK(same_bits(reparsed.time_offset_s.data(), cloud.time_offset_s.data(),
                              cloud.time_offset_s.size() * 4));
}

/// A width x height cloud of `fields` records, `row_pad` bytes after each row, filled with a
/// byte pattern (so every datatype sees varied values).
Recipe layout(std::uint32_t width, std::uint32_t height, std::vector<Field> fields,
              std::uint32_t point_step, std::uint32_t row_pad, bool big_endian) {
  Recipe r;
  r.sec = 1767225600;
  r.nanosec = 123456789;
  r.width = width;
  r.height = height;
  r.point_step = point_step;
  r.row_step = row_pad;
  r.fields = std::move(fields);
  r.flags = kRowStepFromWidth | kDataFromSizes | (big_endian ? kBigEndian : 0) | kDense;
  r.data.resize(std::size_t{width * point_step + row_pad} * height);
  for (std::size_t i = 0; i < r.data.size(); ++i) r.data[i] = static_cast<std::uint8_t>(i * 37);
  return r;
}

const std::vector<Bytes>& seeds() {
  static const std::vector<Bytes> all = [] {
    std::vector<Bytes> s;
    // The writer's own layout, from real clouds: with and without optional channels.
    core::PointCloud cloud;
    cloud.frame_id = "lidar_front";
    cloud.stamp_ns = 1767225600123456789;
    for (int i = 0; i < 24; ++i) {
      cloud.points_S.emplace_back(0.5f * i, -1.0f + 0.1f * i, 0.25f);
      cloud.intensity.push_back(static_cast<float>(i));
      cloud.ring.push_back(static_cast<std::uint16_t>(i % 16));
      cloud.time_offset_s.push_back(1e-4f * static_cast<float>(i));
    }
    const auto from_msg = [](const PointCloud2Msg& m) {
      Recipe r;
      r.flags = kRowStepFromWidth | kDataFromSizes | (m.is_bigendian() ? kBigEndian : 0);
      r.sec = m.header().stamp().sec();
      r.nanosec = m.header().stamp().nanosec();
      r.frame_id = m.header().frame_id();
      r.height = m.height();
      r.width = m.width();
      r.point_step = m.point_step();
      r.row_step = 0;
      for (const auto& f : m.fields()) {
        Field field;
        field.name_code = static_cast<std::uint8_t>(
            std::find(kNames.begin(), kNames.end(), f.name()) - kNames.begin());
        field.offset = f.offset();
        field.datatype = f.datatype();
        field.count = f.count();
        r.fields.push_back(field);
      }
      r.data = m.data();
      return r;
    };
    s.push_back(encode(from_msg(transport::to_point_cloud2(cloud))));
    core::PointCloud bare = cloud;
    bare.intensity.clear();
    bare.ring.clear();
    bare.time_offset_s.clear();
    s.push_back(encode(from_msg(transport::to_point_cloud2(bare))));
    // Driver layouts: Ouster (padding, uint32 t in ns, uint16 ring, row padding), Velodyne
    // (float time), Hesai/Livox (float64 epoch timestamp), big-endian, and every datatype.
    s.push_back(encode(layout(32, 4,
                              {{0, "", 0, pf::FLOAT32, 1},
                               {1, "", 4, pf::FLOAT32, 1},
                               {2, "", 8, pf::FLOAT32, 1},
                               {3, "", 16, pf::FLOAT32, 1},
                               {6, "", 20, pf::UINT32, 1},
                               {4, "", 26, pf::UINT16, 1},
                               {8, "", 28, pf::FLOAT32, 1}},
                              48, 16, false)));
    s.push_back(encode(layout(40, 1,
                              {{0, "", 0, pf::FLOAT32, 1},
                               {1, "", 4, pf::FLOAT32, 1},
                               {2, "", 8, pf::FLOAT32, 1},
                               {3, "", 12, pf::FLOAT32, 1},
                               {4, "", 16, pf::UINT16, 1},
                               {5, "", 18, pf::FLOAT32, 1}},
                              22, 0, false)));
    s.push_back(encode(layout(16, 2,
                              {{0, "", 0, pf::FLOAT64, 1},
                               {1, "", 8, pf::FLOAT64, 1},
                               {2, "", 16, pf::FLOAT64, 1},
                               {3, "", 24, pf::UINT8, 1},
                               {7, "", 32, pf::FLOAT64, 1}},
                              40, 0, true)));
    s.push_back(encode(layout(20, 1,
                              {{0, "", 0, pf::INT8, 1},
                               {1, "", 1, pf::INT16, 1},
                               {2, "", 3, pf::INT32, 1},
                               {3, "", 7, pf::UINT32, 1},
                               {4, "", 11, pf::INT16, 1},
                               {kLiteralName, "reflectivity", 13, pf::UINT16, 1}},
                              15, 3, true)));
    // Rejections: missing z, unknown datatype, count 2, field past point_step, sizes that
    // disagree (no size flags).
    s.push_back(encode(
        layout(4, 1, {{0, "", 0, pf::FLOAT32, 1}, {1, "", 4, pf::FLOAT32, 1}}, 8, 0, false)));
    s.push_back(encode(
        layout(4, 1, {{0, "", 0, pf::FLOAT32, 1}, {1, "", 4, pf::FLOAT32, 1}, {2, "", 8, 9, 1}}, 12,
               0, false)));
    s.push_back(encode(layout(
        4, 1, {{0, "", 0, pf::FLOAT32, 2}, {1, "", 4, pf::FLOAT32, 1}, {2, "", 8, pf::FLOAT32, 1}},
        12, 0, false)));
    s.push_back(encode(layout(
        4, 1, {{0, "", 0, pf::FLOAT32, 1}, {1, "", 4, pf::FLOAT32, 1}, {2, "", 10, pf::FLOAT32, 1}},
        12, 0, false)));
    Recipe sizes = layout(
        4, 3, {{0, "", 0, pf::FLOAT32, 1}, {1, "", 4, pf::FLOAT32, 1}, {2, "", 8, pf::FLOAT32, 1}},
        12, 0, false);
    sizes.flags = 0;
    sizes.row_step = 40;
    s.push_back(encode(sizes));
    return s;
  }();
  return all;
}

}  // namespace
}  // namespace tarmac::fuzz

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  tarmac::fuzz::handle_make_seeds(argc, argv, &tarmac::fuzz::seeds,
                                  {"x", "y", "z", "intensity", "ring", "time", "timestamp"});
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tarmac;
  fuzz::ByteReader in(data, size);
  const transport::PointCloud2Msg msg = fuzz::decode(in);
  core::PointCloud cloud;
  const core::Status parsed = transport::from_point_cloud2(msg, cloud);
  if (!parsed) {
    TARMAC_FUZZ_CHECK(parsed.error().code.rfind("pointcloud.", 0) == 0);
    return 0;
  }
  TARMAC_FUZZ_CHECK(cloud.size() == std::size_t{msg.width()} * msg.height());
  TARMAC_FUZZ_CHECK(cloud.consistent());
  fuzz::check_round_trip(cloud);
  return 0;
}
