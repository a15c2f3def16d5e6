#pragma once
/// @file The DDS participant every tarmac process owns. Localhost-only unless the config opts
/// into named network interfaces (../shared/STACK.md "Network safety").

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tarmac/core/result.hpp"

namespace tarmac::transport {

/// Which transports the participant uses.
enum class TransportMode {
  /// UDPv4 restricted to 127.0.0.1 (interface whitelist, initial peer 127.0.0.1) plus shared
  /// memory. Nothing leaves the machine. The default, like ROS 2's localhost-only switch.
  kLocalhost,
  /// Shared memory only: no sockets at all. Peers must be Fast DDS processes on this machine.
  kSharedMemoryOnly,
  /// UDPv4 on the listed interface addresses (plus shared memory): a deliberate opt-in for a
  /// vehicle network. Requires a non-empty `network_interfaces`.
  kNetwork,
};

struct ParticipantConfig {
  std::uint32_t domain_id = 0;  ///< DDS domain, 0..232
  std::string name = "tarmac";  ///< participant name shown by discovery tools
  TransportMode transport = TransportMode::kLocalhost;
  /// kNetwork only: IPv4 addresses of the interfaces to use, e.g. "10.1.0.5".
  std::vector<std::string> network_interfaces;
  /// kNetwork only: unicast discovery peers (IPv4 addresses), in addition to multicast.
  std::vector<std::string> initial_peers;
  /// Shared-memory segment per participant. The Fast DDS default (512 KiB) makes a 2 MB scan
  /// take ~30 ms; 32 MiB brings it under 1 ms (STACK.md).
  std::uint32_t shm_segment_bytes = 32u << 20;
  std::uint32_t shm_max_message_bytes = 4u << 20;

  [[nodiscard]] core::Status validate() const;
};

/// Renders a mode as its config spelling ("localhost", "shm", "network").
const char* to_string(TransportMode mode);

class ParticipantImpl;

/// Owns one DDS DomainParticipant (and the publisher/subscriber/topics hung from it).
/// Readers and writers keep it alive while they exist. Thread-safe to create endpoints from
/// several threads.
class Participant {
 public:
  /// Creates and enables the participant. Fails with code "dds.participant" when Fast DDS
  /// refuses the configuration, "config.*" when the config itself is invalid.
  static core::Result<Participant> create(const ParticipantConfig& config);

  [[nodiscard]] const ParticipantConfig& config() const;
  /// Internal handle for the typed endpoints of this library.
  [[nodiscard]] const std::shared_ptr<ParticipantImpl>& impl() const { return impl_; }

 private:
  explicit Participant(std::shared_ptr<ParticipantImpl> impl) : impl_(std::move(impl)) {}
  std::shared_ptr<ParticipantImpl> impl_;
};

}  // namespace tarmac::transport
