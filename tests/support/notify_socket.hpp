#pragma once
// A stand-in for systemd's notify socket: an AF_UNIX datagram socket bound at a path, to be
// passed as NOTIFY_SOCKET to tarmacd (or set in this process, for an executor run in-process).
// It keeps every message it received, in order.

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace tarmac::test {

class NotifySocket {
 public:
  explicit NotifySocket(const std::filesystem::path& path) : path_(path) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    std::filesystem::remove(path);
    bound_ = bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
    timeval tv{0, 10'000};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~NotifySocket() {
    close(fd_);
    std::filesystem::remove(path_);
  }
  NotifySocket(const NotifySocket&) = delete;
  NotifySocket& operator=(const NotifySocket&) = delete;
  [[nodiscard]] bool bound() const { return bound_; }

  /// Receives datagrams until one contains `needle` or the timeout passes; keeps them all.
  bool wait_for(const std::string& needle, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (const auto& m : messages_) {
      if (m.find(needle) != std::string::npos) return true;
    }
    while (std::chrono::steady_clock::now() < deadline) {
      if (receive_one() && messages_.back().find(needle) != std::string::npos) return true;
    }
    return false;
  }
  /// Receives whatever arrives for `duration`.
  void collect_for(std::chrono::milliseconds duration) {
    const auto deadline = std::chrono::steady_clock::now() + duration;
    while (std::chrono::steady_clock::now() < deadline) receive_one();
  }
  /// Index of the first message containing `needle`, or -1.
  [[nodiscard]] int first(const std::string& needle) const {
    for (std::size_t i = 0; i < messages_.size(); ++i) {
      if (messages_[i].find(needle) != std::string::npos) return static_cast<int>(i);
    }
    return -1;
  }
  /// How many messages received so far contain `needle`.
  [[nodiscard]] int count(const std::string& needle) const {
    int n = 0;
    for (const auto& m : messages_) n += m.find(needle) != std::string::npos ? 1 : 0;
    return n;
  }
  [[nodiscard]] const std::vector<std::string>& messages() const { return messages_; }

 private:
  /// One datagram (waits at most 10 ms); true when one arrived.
  bool receive_one() {
    char buf[4096];
    const ssize_t n = recv(fd_, buf, sizeof buf, 0);
    if (n <= 0) return false;
    messages_.emplace_back(buf, static_cast<std::size_t>(n));
    return true;
  }

  std::filesystem::path path_;
  int fd_ = -1;
  bool bound_ = false;
  std::vector<std::string> messages_;
};

}  // namespace tarmac::test
