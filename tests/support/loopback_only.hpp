#pragma once
// A fixture for DDS tests: each test runs under a packet capture when permitted (skipped
// outside CI when not, failed in CI), and no RTPS packet may appear on an interface other than
// lo.

#include <chrono>
#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include "rtps_sniffer.hpp"
#include "test_env.hpp"

namespace tarmac::test {

class LoopbackOnly : public ::testing::Test {
 protected:
  void SetUp() override {
    auto sniffer = RtpsSniffer::start();
    TARMAC_REQUIRE_OR_SKIP(sniffer.ok(), "packet capture unavailable: " +
                                             (sniffer.ok() ? "" : sniffer.error().message));
    sniffer_ = std::move(sniffer).value();
  }
  void TearDown() override {
    if (!sniffer_) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));  // packets still in flight
    const auto counts = sniffer_->counts();
    EXPECT_EQ(counts.off_host, 0u) << "RTPS left loopback: " << counts.first_off_host;
    if (expect_loopback_traffic_) {
      EXPECT_GT(counts.loopback, 0u) << "the capture saw no loopback RTPS either";
    }
  }

  /// Also require RTPS on lo (proves the capture works for tests that surely send).
  bool expect_loopback_traffic_ = false;
  std::unique_ptr<RtpsSniffer> sniffer_;
};

}  // namespace tarmac::test
