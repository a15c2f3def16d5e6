#pragma once
/// @file The participant's settings as plain config values (filled from YAML by config/): domain,
/// transports, socket and shared-memory sizes, DDS Security files. No Fast DDS here: the config
/// and the offline tools include it without linking DDS (library tarmac_transport_settings).

#include <cstdint>
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

/// DDS Security (OMG DDS-Security 1.1 builtin plugins: PKI-DH authentication,
/// Access-Permissions access control, AES-GCM-GMAC crypto). Off by default. When enabled, every
/// path must name a readable file; tools/make-dds-security.sh creates a test set.
struct SecurityConfig {
  bool enabled = false;
  std::string identity_ca;           ///< PEM: the CA that signs participants' identities
  std::string identity_certificate;  ///< PEM: this participant's certificate, signed by it
  std::string private_key;           ///< PEM: the certificate's private key
  std::string permissions_ca;        ///< PEM: the CA that signs governance and permissions
  std::string governance;            ///< S/MIME-signed governance XML (.p7s): domain rules
  std::string permissions;           ///< S/MIME-signed permissions XML (.p7s): grants

  /// "config.security" naming dds.security.<key> when a file is missing or unreadable.
  [[nodiscard]] core::Status validate() const;

  /// Takes the identity (certificate and key) from `dir`, laid out as tools/make-dds-security.sh
  /// makes it: dir/cert.pem, dir/key.pem. For tools sharing one config file with tarmacd but
  /// holding their own identity (`--identity DIR`). Enables security.
  void use_identity_dir(const std::string& dir);
};

struct ParticipantConfig {
  std::uint32_t domain_id = 0;  ///< DDS domain, 0..232
  std::string name = "tarmac";  ///< participant name shown by discovery tools
  TransportMode transport = TransportMode::kLocalhost;
  /// kNetwork only: IPv4 addresses of the interfaces to use, e.g. "10.1.0.5".
  std::vector<std::string> network_interfaces;
  /// kNetwork only: unicast discovery peers (IPv4 addresses), in addition to multicast.
  std::vector<std::string> initial_peers;
  /// Fast DDS discovery servers, "IPv4:port" each (`fastdds discovery -i N -l IP -p PORT`):
  /// non-empty makes this participant their client, so it discovers the others through them
  /// instead of announcing itself to every peer (fleet scale, docs/fleet.md). Entry N is the
  /// server of id N, as in ROS_DISCOVERY_SERVER. UDP transports only; with transport
  /// 'localhost' the servers must be on 127.0.0.0/8.
  std::vector<std::string> discovery_servers;
  /// Shared-memory segment per participant. The Fast DDS default (512 KiB) makes a 2 MB scan
  /// take ~30 ms; 32 MiB brings it under 1 ms (STACK.md).
  std::uint32_t shm_segment_bytes = 32u << 20;
  std::uint32_t shm_max_message_bytes = 4u << 20;
  /// Socket receive buffer (SO_RCVBUF) of every UDP socket the participant opens. A best-effort
  /// PointCloud2 of ~1 MB from a publisher that is not on this participant's shared memory (a
  /// ROS 2 driver on Cyclone, another computer) arrives as hundreds of UDP fragments at once; the
  /// kernel's default buffer (~208 KB) overflows and the samples are lost below the reader. The
  /// default holds four 1 MiB clouds. The kernel caps it at net.core.rmem_max
  /// (see `udp_buffer_shortfalls`).
  std::uint32_t udp_receive_buffer_bytes = 4u << 20;
  /// Socket send buffer (SO_SNDBUF) of every UDP socket: room for a burst of output fragments
  /// (costmap, ESDF band) without the kernel refusing them. Capped at net.core.wmem_max.
  std::uint32_t udp_send_buffer_bytes = 4u << 20;
  SecurityConfig security;  ///< off by default

  [[nodiscard]] core::Status validate() const;
};

/// Renders a mode as its config spelling ("localhost", "shm", "network").
const char* to_string(TransportMode mode);

}  // namespace tarmac::transport
