#pragma once
// Watches every network interface of this machine for RTPS (DDS) packets, so a test can prove
// that its DDS traffic stayed on loopback. Uses an AF_PACKET socket: needs CAP_NET_RAW (root).

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "tarmac/core/result.hpp"

namespace tarmac::test {

class RtpsSniffer {
 public:
  struct Counts {
    std::uint64_t loopback = 0;  ///< RTPS packets seen on lo
    /// RTPS bytes (UDP payload) delivered on lo, each packet once (its outgoing copy not counted)
    std::uint64_t loopback_bytes = 0;
    std::uint64_t off_host = 0;  ///< RTPS packets seen on any other interface
    std::string first_off_host;  ///< "<ifname>: <src> -> <dst>" of the first such packet
  };

  /// Starts capturing; fails with code "sniffer.permission" without CAP_NET_RAW.
  static core::Result<std::unique_ptr<RtpsSniffer>> start();
  ~RtpsSniffer();
  RtpsSniffer(const RtpsSniffer&) = delete;
  RtpsSniffer& operator=(const RtpsSniffer&) = delete;

  [[nodiscard]] Counts counts() const;

 private:
  explicit RtpsSniffer(int fd);
  void run();

  int fd_;
  int lo_index_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  Counts counts_;
  std::thread thread_;
};

}  // namespace tarmac::test
