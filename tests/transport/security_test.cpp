// DDS Security (DESIGN.md §6): with dds.security on, only participants holding an identity from
// the configured CA and a grant for the topic can publish into tarmacd. The material is made at
// run time by tools/make-dds-security.sh into a temporary folder (no key is ever committed).
// Localhost-only transport throughout; run inside a private network namespace (test rules).

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "geometry_msgsPubSubTypes.h"
#include "loopback_only.hpp"
#include "rtps_sniffer.hpp"
#include "sensor_msgsPubSubTypes.h"
#include "tarmac/transport/fleet.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac::transport {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using PoseWriter = Writer<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>;
using PoseReader = Reader<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>;
using CloudWriter = Writer<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;
using CloudReader = Reader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;

/// Runs the shipped script into `dir`; false (and the reason) when it fails.
bool make_material(const fs::path& dir, std::string& why, const std::string& extra = "") {
  const fs::path script = test::source_dir() / "tools" / "make-dds-security.sh";
  const std::string command =
      "sh '" + script.string() + "' '" + dir.string() + "' " + extra + " >/dev/null";
  const int rc = std::system(command.c_str());
  if (rc != 0) why = command + " exited with " + std::to_string(rc);
  return rc == 0;
}

class DdsSecurity : public test::LoopbackOnly {
 protected:
  static void SetUpTestSuite() {
    char pattern[] = "/tmp/tarmac-dds-security-XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    root_ = pattern;
    ok_ = make_material(root_ / "fleet", why_, "--vehicles 'tug-a tug-b'") &&
          make_material(root_ / "rogue", why_);
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(root_, ec);
  }
  void SetUp() override {
    TARMAC_REQUIRE_OR_SKIP(std::system("command -v openssl >/dev/null") == 0,
                           "openssl not installed");
    ASSERT_TRUE(ok_) << why_;
    LoopbackOnly::SetUp();
  }

  /// The security block of identity `id` from the material set `set` ("fleet" or "rogue").
  static SecurityConfig security(const std::string& set, const std::string& id) {
    const fs::path dir = root_ / set;
    SecurityConfig s;
    s.enabled = true;
    s.identity_ca = dir / "ca.cert.pem";
    s.identity_certificate = dir / id / "cert.pem";
    s.private_key = dir / id / "key.pem";
    s.permissions_ca = dir / "ca.cert.pem";
    s.governance = dir / "governance.p7s";
    s.permissions = dir / "permissions.p7s";
    return s;
  }

  static ParticipantConfig config(std::uint32_t domain, const std::string& name,
                                  SecurityConfig security = {}) {
    ParticipantConfig c;
    c.domain_id = domain;
    c.name = name;
    c.transport = TransportMode::kLocalhost;  // nothing leaves the machine
    c.security = std::move(security);
    return c;
  }

  static Participant must_create(const ParticipantConfig& c) {
    auto p = Participant::create(c);
    EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().code + ": " + p.error().message);
    return std::move(p).value();
  }

  static inline fs::path root_;
  static inline bool ok_ = false;
  static inline std::string why_;
};

template <typename T>
std::unique_ptr<T> must(core::Result<std::unique_ptr<T>> r) {
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return std::move(r).value();
}

PoseStampedMsg pose_from(const std::string& who, std::int32_t sec) {
  PoseStampedMsg msg;
  msg.header().frame_id(who);
  msg.header().stamp().sec(sec);
  msg.pose().pose().position().x(1.5);
  msg.pose().pose().orientation().w(1.0);
  return msg;
}

TEST_F(DdsSecurity, AuthorisedPeersExchangePoseAndScan) {
  auto daemon =
      must_create(config(test::kDomainSecurityExchange, "tarmacd", security("fleet", "tarmacd")));
  auto publisher = must_create(
      config(test::kDomainSecurityExchange, "publisher", security("fleet", "publisher")));
  auto poses = must(PoseReader::create(daemon, topics::kPose, qos::kPose, 8));
  const QosSpec reliable{Reliability::kReliable, Durability::kVolatile, 2};
  auto clouds = must(CloudReader::create(daemon, "rt/tarmac/lidar/front/points", reliable, 2));
  auto pose_writer = must(PoseWriter::create(publisher, topics::kPose, qos::kPose));
  auto cloud_writer =
      must(CloudWriter::create(publisher, "rt/tarmac/lidar/front/points", reliable));
  ASSERT_TRUE(pose_writer->wait_for_readers(1, 15s));
  ASSERT_TRUE(cloud_writer->wait_for_readers(1, 15s));

  const auto sent = pose_from("map", 42);
  ASSERT_TRUE(pose_writer->write(sent));
  ASSERT_TRUE(poses->wait_for_sample(10s));
  std::vector<PoseStampedMsg> got;
  ASSERT_EQ(poses->take_all(got), 1u);
  EXPECT_TRUE(got[0] == sent);

  core::PointCloud cloud;
  cloud.frame_id = "lidar_front";
  cloud.stamp_ns = 1'700'000'000'000'000'000;
  for (int i = 0; i < 20000; ++i) cloud.points_S.emplace_back(0.01f * i, 1.0f, -0.25f);
  const auto scan = to_point_cloud2(cloud);  // 320 kB: fragmented, every fragment protected
  ASSERT_TRUE(cloud_writer->write(scan));
  ASSERT_TRUE(clouds->wait_for_sample(10s));
  std::vector<PointCloud2Msg> scans;
  ASSERT_EQ(clouds->take_all(scans), 1u);
  EXPECT_TRUE(scans[0] == scan);
}

/// Waits until `reader` holds a sample from `expected` and returns every frame_id it received
/// until then and for `linger` afterwards, while `write` keeps publishing.
template <typename Write>
std::vector<std::string> senders_seen(PoseReader& reader, const std::string& expected, Write write,
                                      std::chrono::milliseconds linger) {
  std::vector<std::string> seen;
  bool have_expected = false;
  auto until = std::chrono::steady_clock::now() + 15s;
  std::vector<PoseStampedMsg> batch;
  for (std::int32_t i = 0; std::chrono::steady_clock::now() < until; ++i) {
    write(i);
    reader.wait_for_sample(50ms);
    batch.clear();
    reader.take_all(batch);
    for (const auto& m : batch) {
      seen.push_back(m.header().frame_id());
      if (!have_expected && m.header().frame_id() == expected) {
        have_expected = true;
        until = std::chrono::steady_clock::now() + linger;
      }
    }
  }
  return seen;
}

TEST_F(DdsSecurity, UnauthenticatedPublisherIsNotHeard) {
  auto daemon = must_create(
      config(test::kDomainSecurityUnauthenticated, "tarmacd", security("fleet", "tarmacd")));
  auto publisher = must_create(
      config(test::kDomainSecurityUnauthenticated, "publisher", security("fleet", "publisher")));
  auto intruder = must_create(config(test::kDomainSecurityUnauthenticated, "intruder"));
  auto reader = must(PoseReader::create(daemon, topics::kPose, qos::kPose, 64));
  auto good = must(PoseWriter::create(publisher, topics::kPose, qos::kPose));
  auto bad = must(PoseWriter::create(intruder, topics::kPose, qos::kPose));

  const auto seen = senders_seen(
      *reader, "publisher",
      [&](std::int32_t i) {
        good->write(pose_from("publisher", i));
        bad->write(pose_from("intruder", i));
      },
      2s);
  EXPECT_EQ(std::count(seen.begin(), seen.end(), "intruder"), 0);
  EXPECT_GT(std::count(seen.begin(), seen.end(), "publisher"), 0);
  EXPECT_EQ(bad->matched_readers(), 0u);
}

TEST_F(DdsSecurity, IdentityFromAnotherCaIsNotHeard) {
  auto daemon =
      must_create(config(test::kDomainSecurityOtherCa, "tarmacd", security("fleet", "tarmacd")));
  auto publisher = must_create(
      config(test::kDomainSecurityOtherCa, "publisher", security("fleet", "publisher")));
  // A complete, self-consistent set of its own: CA, governance, permissions granting poses.
  auto rogue =
      must_create(config(test::kDomainSecurityOtherCa, "rogue", security("rogue", "publisher")));
  auto reader = must(PoseReader::create(daemon, topics::kPose, qos::kPose, 64));
  auto good = must(PoseWriter::create(publisher, topics::kPose, qos::kPose));
  auto bad = must(PoseWriter::create(rogue, topics::kPose, qos::kPose));

  const auto seen = senders_seen(
      *reader, "publisher",
      [&](std::int32_t i) {
        good->write(pose_from("publisher", i));
        bad->write(pose_from("rogue", i));
      },
      2s);
  EXPECT_EQ(std::count(seen.begin(), seen.end(), "rogue"), 0);
  EXPECT_GT(std::count(seen.begin(), seen.end(), "publisher"), 0);
  EXPECT_EQ(bad->matched_readers(), 0u);
}

TEST_F(DdsSecurity, TopicNotGrantedIsRefusedAtWriterCreation) {
  // tarmacd's grant subscribes poses; it may not publish them.
  auto daemon =
      must_create(config(test::kDomainSecurityDenied, "tarmacd", security("fleet", "tarmacd")));
  auto writer = PoseWriter::create(daemon, topics::kPose, qos::kPose);
  ASSERT_FALSE(writer.ok());
  EXPECT_NE(writer.error().message.find("rt/tarmac/pose"), std::string::npos)
      << writer.error().message;
  EXPECT_NE(writer.error().message.find("permissions file"), std::string::npos)
      << writer.error().message;
  // The monitor identity subscribes poses but publishes nothing.
  auto monitor =
      must_create(config(test::kDomainSecurityDenied, "monitor", security("fleet", "monitor")));
  EXPECT_TRUE(PoseReader::create(monitor, topics::kPose, qos::kPose, 4).ok());
  EXPECT_FALSE(PoseWriter::create(monitor, topics::kPose, qos::kPose).ok());
}

/// Collects the fleet summaries a link hands over, and its refusals.
class FleetInbox final : public FleetSink {
 public:
  void summary(core::BevMessage&& m) override { ids.push_back(m.vehicle_id); }
  void reject(std::string_view reason) override { refused.emplace_back(reason); }
  std::vector<std::string> ids, refused;
};

TEST_F(DdsSecurity, FleetVehicle_PublishesUnderItsOwnIdOnly) {
  // make-dds-security.sh --vehicles 'tug-a tug-b': tarmacd-tug-a may publish fleet summaries in
  // its own partition only.
  constexpr auto kDomain = test::kDomainSecurityFleet;
  auto a = must_create(config(kDomain, "tarmacd-tug-a", security("fleet", "tarmacd-tug-a")));
  auto b = must_create(config(kDomain, "tarmacd-tug-b", security("fleet", "tarmacd-tug-b")));
  auto monitor = must_create(config(kDomain, "monitor", security("fleet", "monitor")));
  FleetLinkOptions as_a;
  as_a.vehicle_id = "tug-a";
  auto link_a = must(FleetLink::create(a, as_a));
  FleetLinkOptions as_b = as_a;
  as_b.vehicle_id = "tug-b";
  auto link_b = must(FleetLink::create(b, as_b));
  auto site = must(FleetLink::create(monitor, FleetLinkOptions{}));  // the site view: reads only
  // tug-a's identity cannot write in tug-b's partition: refused at creation.
  const auto forged = FleetLink::create(a, as_b);
  ASSERT_FALSE(forged.ok());
  EXPECT_NE(forged.error().message.find("tarmac_fleet_tug-b"), std::string::npos)
      << forged.error().message;
  // Nor may the monitor publish at all.
  EXPECT_FALSE(FleetLink::create(monitor, as_a).ok());
  // In its own partition under another vehicle's id: delivered, then refused by the id check.
  using FleetWriter = Writer<tarmac_msgs::msg::dds_::FleetBev_PubSubType>;
  auto impostor = must(FleetWriter::create(a, as_a.topic, qos::kFleet, fleet_partition("tug-a")));
  // tug-a's own link's reader, tug-b's and the site view's; and the readers' side of it: tug-b's
  // reader has tug-a's, the impostor's and its own writer, the site view tug-a's and tug-b's too.
  ASSERT_TRUE(impostor->wait_for_readers(3, 10s));
  for (int i = 0; i < 500 && (link_b->matched_writers() < 3 || site->matched_writers() < 3); ++i) {
    std::this_thread::sleep_for(20ms);
  }
  ASSERT_GE(link_b->matched_writers(), 3u);
  ASSERT_GE(site->matched_writers(), 3u);

  core::BevMessage m;
  m.vehicle_id = "tug-a";
  m.stamp_ns = 1'000'000'000;
  m.keyframe = true;
  ASSERT_TRUE(link_a->publish(m));
  m.vehicle_id = "tug-b";
  ASSERT_TRUE(impostor->write(to_fleet_bev(m, "map")));
  FleetInbox at_b, at_site;
  for (int i = 0; i < 500 && (at_site.ids.size() + at_site.refused.size() < 2 ||
                              at_b.ids.size() + at_b.refused.size() < 2);
       ++i) {
    std::this_thread::sleep_for(20ms);
    link_b->drain(at_b);
    site->drain(at_site);
  }
  std::this_thread::sleep_for(100ms);
  link_b->drain(at_b);
  EXPECT_EQ(at_b.ids, std::vector<std::string>{"tug-a"});
  EXPECT_EQ(at_b.refused, std::vector<std::string>{"fleet.impersonation"});
  EXPECT_EQ(at_site.ids, std::vector<std::string>{"tug-a"});
  EXPECT_EQ(at_site.refused, std::vector<std::string>{"fleet.impersonation"});
}

TEST_F(DdsSecurity, CertificateFromAnotherCaFailsAtCreation) {
  auto s = security("fleet", "publisher");
  s.identity_certificate = root_ / "rogue" / "publisher" / "cert.pem";
  s.private_key = root_ / "rogue" / "publisher" / "key.pem";
  auto p = Participant::create(config(test::kDomainSecurityDenied, "mixed", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, "dds.security");
  EXPECT_NE(p.error().message.find("'mixed'"), std::string::npos) << p.error().message;
  EXPECT_NE(p.error().message.find("dds.security.identity_certificate: '" + s.identity_certificate +
                                   "' does not verify against dds.security.identity_ca"),
            std::string::npos)
      << p.error().message;
}

TEST_F(DdsSecurity, IdentityWithoutGrantFailsAtCreation) {
  // Signed by the fleet CA, so it authenticates, but the permissions name no such subject.
  const fs::path dir = root_ / "stranger";
  fs::create_directories(dir);
  const fs::path ca = root_ / "fleet";
  const std::string cmd =
      "cd '" + dir.string() +
      "' && openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out key.pem "
      "2>/dev/null && openssl req -new -key key.pem -subj /O=tarmac/CN=stranger -out csr.pem && "
      "openssl x509 -req -in csr.pem -CA '" +
      (ca / "ca.cert.pem").string() + "' -CAkey '" + (ca / "ca.key.pem").string() +
      "' -CAcreateserial -days 2 -out cert.pem 2>/dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  auto s = security("fleet", "publisher");
  s.use_identity_dir(dir.string());
  EXPECT_EQ(s.identity_certificate, (dir / "cert.pem").string());
  auto p = Participant::create(config(test::kDomainSecurityDenied, "stranger", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, "dds.security");
  EXPECT_NE(p.error().message.find("dds.security.permissions: no grant with "
                                   "<subject_name>CN=stranger,O=tarmac</subject_name>"),
            std::string::npos)
      << p.error().message;
}

TEST_F(DdsSecurity, KeyNotMatchingCertificateFailsAtCreation) {
  auto s = security("fleet", "publisher");
  s.private_key = root_ / "fleet" / "tarmacd" / "key.pem";
  auto p = Participant::create(config(test::kDomainSecurityDenied, "wrong-key", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, "dds.security");
  EXPECT_NE(p.error().message.find("dds.security.private_key: '" + s.private_key +
                                   "' does not belong to dds.security.identity_certificate"),
            std::string::npos)
      << p.error().message;
}

TEST_F(DdsSecurity, MissingOrWrongFilesNameTheKey) {
  auto s = security("fleet", "publisher");
  s.identity_certificate = root_ / "fleet" / "publisher" / "no-such-cert.pem";
  auto p = Participant::create(config(test::kDomainSecurityDenied, "x", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, "config.security");
  EXPECT_EQ(p.error().message.rfind("dds.security.identity_certificate: '", 0), 0u)
      << p.error().message;
  EXPECT_NE(p.error().message.find("no-such-cert.pem' does not exist"), std::string::npos)
      << p.error().message;

  s = security("fleet", "publisher");
  s.private_key = s.identity_certificate;  // swapped by mistake
  p = Participant::create(config(test::kDomainSecurityDenied, "x", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().message.rfind("dds.security.private_key: ", 0), 0u) << p.error().message;
  EXPECT_NE(p.error().message.find("is not a PEM private key"), std::string::npos);

  s = security("fleet", "publisher");
  s.governance.clear();
  p = Participant::create(config(test::kDomainSecurityDenied, "x", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().message,
            "dds.security.governance: must be set when dds.security.enabled is true");

  // Disabled: the paths are not looked at.
  s.enabled = false;
  EXPECT_TRUE(s.validate().ok());
}

TEST_F(DdsSecurity, TamperedPermissionsFailAtCreation) {
  const fs::path tampered = root_ / "tampered.p7s";
  {
    std::ifstream in(root_ / "fleet" / "permissions.p7s");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // Grant the daemon's identity the right to publish poses, after signing.
    const std::string from = "<grant name=\"tarmacd\">";
    ASSERT_NE(text.find(from), std::string::npos);
    const auto at = text.find("<publish><topics>", text.find(from));
    ASSERT_NE(at, std::string::npos);
    text.insert(at + std::string("<publish><topics>").size(), "<topic>rt/tarmac/pose</topic>");
    std::ofstream(tampered) << text;
  }
  auto s = security("fleet", "tarmacd");
  s.permissions = tampered;
  auto p = Participant::create(config(test::kDomainSecurityDenied, "tampered", s));
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, "dds.security");
  EXPECT_NE(p.error().message.find("dds.security.permissions: signature of '" + tampered.string() +
                                   "' does not verify against dds.security.permissions_ca"),
            std::string::npos)
      << p.error().message;
}

}  // namespace
}  // namespace tarmac::transport
