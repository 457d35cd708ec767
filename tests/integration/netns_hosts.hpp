// Hosts for the multi-host tests: network namespaces joined by a bridge in a namespace of its own (needs root and
// iproute2), and running code inside one of them. Every namespace is deleted when the Hosts go, and those left by a
// killed earlier run are removed first (remove_stale_namespaces).
#pragma once

#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <functional>
#include <map>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "process_fixture.hpp"

namespace bsn::integration {

inline constexpr const char* kNamespacePrefix = "bsn-test-";

inline bool run(const std::string& command) { return std::system((command + " > /dev/null 2>&1").c_str()) == 0; }

/// Deletes the namespaces of earlier runs whose process has gone (a run killed before its clean-up).
inline void remove_stale_namespaces() {
  for (const std::string& name : directory_entries("/var/run/netns")) {
    std::smatch m;
    if (!std::regex_match(name, m, std::regex(std::string(kNamespacePrefix) + "([0-9]+)-.*"))) continue;
    if (::kill(std::stoi(m[1]), 0) != 0 && errno == ESRCH) run("ip netns delete " + name);
  }
}

/// Why this machine cannot run network-namespace hosts ("" when it can): they need root and iproute2.
inline std::string namespaces_unavailable() {
  if (::geteuid() != 0) return "network namespaces need root; running as uid " + std::to_string(::geteuid());
  if (!run("command -v ip") || !run("command -v bridge")) return "iproute2 (ip, bridge) is not installed";
  return "";
}

/// Hosts as network namespaces on one bridge; host i has address 10.231.0.(i+1)/24 on its eth0.
class Hosts {
 public:
  explicit Hosts(const std::vector<std::string>& hosts) {
    const std::string prefix = kNamespacePrefix + std::to_string(::getpid()) + "-";
    bridge_ = prefix + "bridge";
    ok_ = run("ip netns add " + bridge_) && run("ip -n " + bridge_ + " link add br0 type bridge") &&
          run("ip -n " + bridge_ + " link set br0 up");
    for (std::size_t i = 0; ok_ && i < hosts.size(); ++i) {
      const std::string ns = prefix + hosts[i], port = "p" + std::to_string(i);
      names_[hosts[i]] = ns;
      addresses_[hosts[i]] = "10.231.0." + std::to_string(i + 1);
      ok_ = run("ip netns add " + ns) &&
            run("ip link add eth0 netns " + ns + " type veth peer name " + port + " netns " + bridge_) &&
            run("ip -n " + ns + " addr add " + addresses_[hosts[i]] + "/24 dev eth0") &&
            run("ip -n " + ns + " link set eth0 up") && run("ip -n " + ns + " link set lo up") &&
            run("ip -n " + bridge_ + " link set " + port + " master br0") &&
            run("ip -n " + bridge_ + " link set " + port + " up");
      ports_.push_back(port);
    }
  }
  ~Hosts() {
    for (const auto& [host, ns] : names_) run("ip netns delete " + ns);
    run("ip netns delete " + bridge_);
  }
  bool ok() const { return ok_; }
  const std::string& ns(const std::string& host) { return names_.at(host); }
  const std::string& address(const std::string& host) { return addresses_.at(host); }
  /// Stops the bridge from flooding multicast to any port: participants then find each other only by unicast.
  bool block_multicast() {
    for (const std::string& port : ports_)
      if (!run("bridge -n " + bridge_ + " link set dev " + port + " mcast_flood off")) return false;
    return true;
  }

 private:
  bool ok_ = false;
  std::string bridge_;
  std::map<std::string, std::string> names_, addresses_;
  std::vector<std::string> ports_;
};

/// Runs `f` on a thread that has entered network namespace `ns`: sockets and threads it creates stay there.
inline bool run_in_namespace(const std::string& ns, const std::function<void()>& f) {
  bool entered = false;
  std::thread t([&] {
    const int fd = ::open(("/var/run/netns/" + ns).c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return;
    entered = ::setns(fd, CLONE_NEWNET) == 0;
    ::close(fd);
    if (entered) f();
  });
  t.join();
  return entered;
}

}  // namespace bsn::integration
