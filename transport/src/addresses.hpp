#pragma once
/// @file IPv4 addresses and discovery servers as the config spells them: checked by
/// ParticipantConfig::validate(), turned into locators by the participant.

#include <cstdint>
#include <string>

namespace tarmac::transport {

/// True when `text` is a dotted IPv4 address ("10.1.0.5").
bool is_ipv4(const std::string& text);

/// "a.b.c.d:port" split into `address` and `port`; false when it is not an IPv4 address and a
/// port 1..65535.
bool split_server(const std::string& text, std::string& address, std::uint32_t& port);

}  // namespace tarmac::transport
