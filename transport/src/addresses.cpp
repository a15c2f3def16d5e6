#include "addresses.hpp"

#include <arpa/inet.h>

#include <algorithm>

namespace tarmac::transport {

bool is_ipv4(const std::string& text) {
  in_addr addr{};
  return inet_pton(AF_INET, text.c_str(), &addr) == 1;
}

bool split_server(const std::string& text, std::string& address, std::uint32_t& port) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos) return false;
  address = text.substr(0, colon);
  const std::string digits = text.substr(colon + 1);
  if (digits.empty() || digits.size() > 5 ||
      !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return false;
  }
  port = static_cast<std::uint32_t>(std::stoul(digits));
  return is_ipv4(address) && port >= 1 && port <= 65535;
}

}  // namespace tarmac::transport
