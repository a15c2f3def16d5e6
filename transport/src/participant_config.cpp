#include "tarmac/transport/participant_config.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "addresses.hpp"

namespace tarmac::transport {

namespace {

core::Error config_error(const std::string& key, const std::string& why) {
  return core::Error{"config.transport", key + ": " + why};
}

core::Error security_error(const std::string& key, const std::string& why) {
  return core::Error{"config.security", "dds.security." + key + ": " + why};
}

/// Checks one security file: set, a readable regular file, and (when `marker` is given) the
/// kind of PEM block expected, so swapped paths are caught here rather than as a vague refusal.
core::Status check_security_file(const std::string& key, const std::string& path,
                                 const char* marker, const char* what) {
  if (path.empty()) return security_error(key, "must be set when dds.security.enabled is true");
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (status.type() == std::filesystem::file_type::not_found) {
    return security_error(key, "'" + path + "' does not exist");
  }
  if (ec) return security_error(key, "'" + path + "': " + ec.message());
  if (!std::filesystem::is_regular_file(status)) {
    return security_error(key, "'" + path + "' is not a regular file");
  }
  if (::access(path.c_str(), R_OK) != 0) {
    return security_error(key, "cannot read '" + path + "': " + std::strerror(errno));
  }
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!in.good() && !in.eof()) return security_error(key, "cannot read '" + path + "'");
  if (marker != nullptr && text.find(marker) == std::string::npos) {
    return security_error(key, "'" + path + "' is not " + what + " (no '" + marker + "')");
  }
  return core::Ok{};
}

}  // namespace

const char* to_string(TransportMode mode) {
  switch (mode) {
    case TransportMode::kLocalhost: return "localhost";
    case TransportMode::kSharedMemoryOnly: return "shm";
    case TransportMode::kNetwork: return "network";
  }
  return "?";
}

core::Status SecurityConfig::validate() const {
  if (!enabled) return core::Ok{};
  constexpr const char* kCert = "-----BEGIN CERTIFICATE-----";
  constexpr const char* kCertWhat = "a PEM certificate";
  if (auto ok = check_security_file("identity_ca", identity_ca, kCert, kCertWhat); !ok) return ok;
  if (auto ok = check_security_file("identity_certificate", identity_certificate, kCert, kCertWhat);
      !ok) {
    return ok;
  }
  if (auto ok =
          check_security_file("private_key", private_key, "PRIVATE KEY-----", "a PEM private key");
      !ok) {
    return ok;
  }
  if (auto ok = check_security_file("permissions_ca", permissions_ca, kCert, kCertWhat); !ok) {
    return ok;
  }
  // Governance and permissions: S/MIME (openssl smime -sign) or PEM PKCS#7; Fast DDS checks.
  if (auto ok = check_security_file("governance", governance, nullptr, nullptr); !ok) return ok;
  if (auto ok = check_security_file("permissions", permissions, nullptr, nullptr); !ok) return ok;
  return core::Ok{};
}

void SecurityConfig::use_identity_dir(const std::string& dir) {
  enabled = true;
  identity_certificate = (std::filesystem::path(dir) / "cert.pem").string();
  private_key = (std::filesystem::path(dir) / "key.pem").string();
}

core::Status ParticipantConfig::validate() const {
  if (domain_id > 232) {
    return config_error("dds.domain_id", "must be 0..232, got " + std::to_string(domain_id));
  }
  if (shm_segment_bytes < shm_max_message_bytes) {
    return config_error("dds.shm_segment_bytes", "must be >= dds.shm_max_message_bytes");
  }
  if (shm_max_message_bytes < 64u * 1024u) {
    return config_error("dds.shm_max_message_bytes", "must be >= 65536");
  }
  // Fast DDS refuses a UDP transport whose buffers are smaller than one datagram (65500 B).
  if (udp_receive_buffer_bytes < 64u * 1024u) {
    return config_error("dds.udp_receive_buffer_bytes", "must be >= 65536");
  }
  if (udp_send_buffer_bytes < 64u * 1024u) {
    return config_error("dds.udp_send_buffer_bytes", "must be >= 65536");
  }
  if (transport == TransportMode::kNetwork && network_interfaces.empty()) {
    return config_error("dds.network_interfaces",
                        "transport 'network' needs the interface addresses to use, explicitly");
  }
  if (transport != TransportMode::kNetwork &&
      (!network_interfaces.empty() || !initial_peers.empty())) {
    return config_error("dds.network_interfaces",
                        std::string("only allowed with transport 'network', transport is '") +
                            to_string(transport) + "'");
  }
  for (const auto& address : network_interfaces) {
    if (!is_ipv4(address))
      return config_error("dds.network_interfaces", "not an IPv4 address: " + address);
  }
  for (const auto& address : initial_peers) {
    if (!is_ipv4(address))
      return config_error("dds.initial_peers", "not an IPv4 address: " + address);
  }
  if (!discovery_servers.empty() && transport == TransportMode::kSharedMemoryOnly) {
    return config_error("dds.discovery_servers", "need a UDP transport, transport is 'shm'");
  }
  if (discovery_servers.size() > 256) return config_error("dds.discovery_servers", "at most 256");
  for (const auto& server : discovery_servers) {
    std::string address;
    std::uint32_t port = 0;
    if (!split_server(server, address, port)) {
      return config_error("dds.discovery_servers", "not IPv4:port (port 1..65535): " + server);
    }
    if (transport == TransportMode::kLocalhost && address.rfind("127.", 0) != 0) {
      return config_error("dds.discovery_servers",
                          "transport 'localhost' reaches 127.0.0.0/8 only, not " + server);
    }
  }
  return security.validate();
}

}  // namespace tarmac::transport
