#pragma once
/// @file The DDS participant every tarmac process owns. Localhost-only unless the config opts
/// into named network interfaces (../shared/STACK.md "Network safety").

#include <memory>
#include <string>
#include <vector>

#include "tarmac/core/result.hpp"
#include "tarmac/transport/participant_config.hpp"

namespace tarmac::transport {

/// What the kernel would grant of the configured UDP socket buffers: one message per buffer it
/// caps below the configured size, naming the config key, the sizes and the sysctl to raise
/// (net.core.rmem_max / net.core.wmem_max). Empty when both are granted in full, or when the
/// transport uses no UDP. Probes with a throw-away socket; for start-up, not the cycle.
std::vector<std::string> udp_buffer_shortfalls(const ParticipantConfig& config);

class ParticipantImpl;

/// Owns one DDS DomainParticipant (and the publisher/subscriber/topics hung from it).
/// Readers and writers keep it alive while they exist. Thread-safe to create endpoints from
/// several threads.
class Participant {
 public:
  /// Creates and enables the participant. Fails with code "dds.participant" when Fast DDS
  /// refuses the configuration, "dds.security" when it refuses the security material (e.g. a
  /// certificate not signed by the identity CA, a bad signature on governance or permissions,
  /// no grant for the certificate's subject; the message carries Fast DDS's reason), "config.*"
  /// when the config itself is invalid.
  static core::Result<Participant> create(const ParticipantConfig& config);

  [[nodiscard]] const ParticipantConfig& config() const;
  /// Internal handle for the typed endpoints of this library.
  [[nodiscard]] const std::shared_ptr<ParticipantImpl>& impl() const { return impl_; }

 private:
  explicit Participant(std::shared_ptr<ParticipantImpl> impl) : impl_(std::move(impl)) {}
  std::shared_ptr<ParticipantImpl> impl_;
};

}  // namespace tarmac::transport
