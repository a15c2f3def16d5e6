#include "rtps_sniffer.hpp"

#include <arpa/inet.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <netinet/ip.h>
#include <netinet/ip6.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace tarmac::test {

namespace {

/// Returns the UDP payload of an IPv4/IPv6 packet (cooked capture: starts at the IP header),
/// or nullptr when it is not a first-fragment UDP packet. Fills src/dst for reporting.
const std::uint8_t* udp_payload(const std::uint8_t* p, std::size_t n, std::uint16_t proto,
                                std::size_t& payload_len, std::string& src, std::string& dst) {
  char a[INET6_ADDRSTRLEN] = {0};
  char b[INET6_ADDRSTRLEN] = {0};
  std::size_t ip_len = 0;
  if (proto == ETH_P_IP && n >= 20) {
    const std::size_t ihl = (p[0] & 0x0f) * 4u;
    const bool later_fragment = ((p[6] & 0x1f) | p[7]) != 0;
    if (p[9] != IPPROTO_UDP || later_fragment || n < ihl + 8) return nullptr;
    inet_ntop(AF_INET, p + 12, a, sizeof a);
    inet_ntop(AF_INET, p + 16, b, sizeof b);
    ip_len = ihl;
  } else if (proto == ETH_P_IPV6 && n >= 48) {
    if (p[6] != IPPROTO_UDP) return nullptr;
    inet_ntop(AF_INET6, p + 8, a, sizeof a);
    inet_ntop(AF_INET6, p + 24, b, sizeof b);
    ip_len = 40;
  } else {
    return nullptr;
  }
  src = a;
  dst = b;
  payload_len = n - ip_len - 8;
  return p + ip_len + 8;
}

}  // namespace

core::Result<std::unique_ptr<RtpsSniffer>> RtpsSniffer::start() {
  const int fd = socket(AF_PACKET, SOCK_DGRAM, htons(ETH_P_ALL));
  if (fd < 0) {
    return core::Error{"sniffer.permission", std::string("AF_PACKET socket: ") +
                                                 std::strerror(errno) +
                                                 " (needs CAP_NET_RAW, i.e. root)"};
  }
  timeval tv{0, 50'000};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  return std::unique_ptr<RtpsSniffer>(new RtpsSniffer(fd));
}

RtpsSniffer::RtpsSniffer(int fd) : fd_(fd), lo_index_(static_cast<int>(if_nametoindex("lo"))) {
  thread_ = std::thread([this] { run(); });
}

RtpsSniffer::~RtpsSniffer() {
  stop_ = true;
  thread_.join();
  close(fd_);
}

RtpsSniffer::Counts RtpsSniffer::counts() const {
  std::lock_guard lock(mutex_);
  return counts_;
}

void RtpsSniffer::run() {
  std::uint8_t buf[65536];
  while (!stop_) {
    sockaddr_ll from{};
    socklen_t from_len = sizeof from;
    const ssize_t n =
        recvfrom(fd_, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &from_len);
    if (n <= 0) continue;  // timeout: check stop_
    std::size_t len = 0;
    std::string src, dst;
    const std::uint8_t* payload =
        udp_payload(buf, static_cast<std::size_t>(n), ntohs(from.sll_protocol), len, src, dst);
    if (payload == nullptr || len < 4 || std::memcmp(payload, "RTPS", 4) != 0) continue;
    std::lock_guard lock(mutex_);
    if (from.sll_ifindex == lo_index_) {
      ++counts_.loopback;
      if (from.sll_pkttype != PACKET_OUTGOING) counts_.loopback_bytes += len;
    } else {
      if (counts_.off_host++ == 0) {
        char name[IF_NAMESIZE] = "?";
        if_indextoname(static_cast<unsigned>(from.sll_ifindex), name);
        counts_.first_off_host = std::string(name) + ": " + src + " -> " + dst;
      }
    }
  }
}

}  // namespace tarmac::test
