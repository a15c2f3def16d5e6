// tarmacd as systemd runs it: an AF_UNIX datagram socket stands in for systemd's notify socket
// (NOTIFY_SOCKET, WATCHDOG_USEC); the test observes READY=1, WATCHDOG=1, STATUS=, then sends
// SIGTERM and expects STOPPING=1, the saved map and exit status 0. The daemon's DDS stays on
// loopback (packet capture) on its own domain.

#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "rtps_sniffer.hpp"
#include "test_env.hpp"

namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

class NotifySocket {
 public:
  explicit NotifySocket(const fs::path& path) : path_(path) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    fs::remove(path);
    bound_ = bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
    timeval tv{0, 100'000};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~NotifySocket() {
    close(fd_);
    fs::remove(path_);
  }
  [[nodiscard]] bool bound() const { return bound_; }

  /// Receives datagrams until one contains `needle` or the timeout passes; keeps them all.
  bool wait_for(const std::string& needle, std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (const auto& m : messages_) {
      if (m.find(needle) != std::string::npos) return true;
    }
    char buf[4096];
    while (std::chrono::steady_clock::now() < deadline) {
      const ssize_t n = recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) continue;
      messages_.emplace_back(buf, static_cast<std::size_t>(n));
      if (messages_.back().find(needle) != std::string::npos) return true;
    }
    return false;
  }
  /// Index of the first message containing `needle`, or -1.
  [[nodiscard]] int first(const std::string& needle) const {
    for (std::size_t i = 0; i < messages_.size(); ++i) {
      if (messages_[i].find(needle) != std::string::npos) return static_cast<int>(i);
    }
    return -1;
  }
  [[nodiscard]] const std::vector<std::string>& messages() const { return messages_; }

 private:
  fs::path path_;
  int fd_ = -1;
  bool bound_ = false;
  std::vector<std::string> messages_;
};

TEST(Tarmacd, Notify_ReadyWatchdogStatusThenStoppingAndExit0OnSigterm) {
  auto sniffer = tarmac::test::RtpsSniffer::start();
  TARMAC_REQUIRE_OR_SKIP(sniffer.ok(), "packet capture unavailable");

  const fs::path dir = fs::temp_directory_path() / ("tarmacd-process-" + std::to_string(getpid()));
  fs::create_directories(dir);
  const fs::path config = dir / "tarmac.yaml";
  {
    std::ofstream out(config);
    // The shipped defaults, except domain and state directory; real time is attempted as shipped.
    out << "version: 1\ndds: {domain_id: " << tarmac::test::kDomainDaemonProcess
        << "}\nstate: {dir: " << (dir / "state").string() << "}\n";
  }
  NotifySocket notify(dir / "notify.sock");
  ASSERT_TRUE(notify.bound());

  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    setenv("NOTIFY_SOCKET", (dir / "notify.sock").c_str(), 1);
    setenv("WATCHDOG_USEC", "2000000", 1);
    const std::string log = (dir / "tarmacd.log").string();
    freopen(log.c_str(), "w", stdout);
    freopen(log.c_str(), "a", stderr);
    execl(TARMAC_TARMACD, TARMAC_TARMACD, "--config", config.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  const bool ready = notify.wait_for("READY=1", 15s);
  const bool watchdog = notify.wait_for("WATCHDOG=1", 5s);
  const bool status = notify.wait_for("STATUS=", 5s);
  kill(pid, SIGTERM);
  const bool stopping = notify.wait_for("STOPPING=1", 10s);
  int wstatus = 0;
  pid_t waited = 0;
  for (int i = 0; i < 100 && waited == 0; ++i) {
    waited = waitpid(pid, &wstatus, WNOHANG);
    if (waited == 0) std::this_thread::sleep_for(100ms);
  }
  if (waited == 0) {
    kill(pid, SIGKILL);
    waitpid(pid, &wstatus, 0);
  }
  std::ifstream log_in(dir / "tarmacd.log");
  const std::string log((std::istreambuf_iterator<char>(log_in)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(ready) << log;
  EXPECT_TRUE(watchdog);
  EXPECT_TRUE(status);
  EXPECT_TRUE(stopping);
  EXPECT_LT(notify.first("READY=1"), notify.first("WATCHDOG=1")) << "watchdog before READY";
  ASSERT_NE(waited, 0) << "tarmacd did not exit within 10 s of SIGTERM\n" << log;
  ASSERT_TRUE(WIFEXITED(wstatus)) << log;
  EXPECT_EQ(WEXITSTATUS(wstatus), 0) << log;
  // The map is saved on the way out.
  std::ifstream map(dir / "state" / "occupancy_window.bin", std::ios::binary);
  std::string header;
  std::getline(map, header);
  EXPECT_EQ(header.rfind("tarmac occupancy window v1", 0), 0u) << header;

  std::this_thread::sleep_for(200ms);
  const auto counts = sniffer.value()->counts();
  EXPECT_EQ(counts.off_host, 0u) << "RTPS left loopback: " << counts.first_off_host;
  EXPECT_GT(counts.loopback, 0u);
  fs::remove_all(dir);
}

}  // namespace
