#include "process_fixture.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace bsn::integration {

std::string bsn_executable() { return BSN_EXECUTABLE; }

int test_domain(int offset) {
  constexpr int kDefaultBase = 20;
  constexpr int kOffsets = 100;  // each run owns base .. base + 99
  int base = kDefaultBase;
  if (const char* env = std::getenv("BSN_TEST_DOMAIN_BASE")) {
    char* end = nullptr;
    const long v = std::strtol(env, &end, 10);
    if (end == env || *end != '\0' || v < 0 || v > 232 - kOffsets + 1)
      throw std::invalid_argument(std::string("BSN_TEST_DOMAIN_BASE='") + env + "' is not a domain id in 0.." +
                                  std::to_string(232 - kOffsets + 1));
    base = static_cast<int>(v);
  }
  if (offset < 0 || offset >= kOffsets) throw std::invalid_argument("test domain offset out of 0..99");
  return base + offset;
}

bool wait_until(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto end = Clock::now() + timeout;
  while (!done()) {
    if (Clock::now() >= end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

void write_file(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string tail(const std::filesystem::path& path, std::size_t lines) {
  std::ifstream in(path);
  std::deque<std::string> last;
  for (std::string line; std::getline(in, line);) {
    last.push_back(line);
    if (last.size() > lines) last.pop_front();
  }
  std::string out;
  for (const auto& l : last) out += l + "\n";
  return out;
}

std::string describe_status(const std::optional<int>& status) {
  if (!status) return "still running";
  if (WIFEXITED(*status)) return "exited with " + std::to_string(WEXITSTATUS(*status));
  if (WIFSIGNALED(*status)) return "killed by signal " + std::to_string(WTERMSIG(*status));
  return "waitpid status " + std::to_string(*status);
}

bool exited_cleanly(const std::optional<int>& status) {
  return status && WIFEXITED(*status) && WEXITSTATUS(*status) == 0;
}

int exit_code(const std::optional<int>& status) { return status && WIFEXITED(*status) ? WEXITSTATUS(*status) : -1; }

std::set<std::string> directory_entries(const std::filesystem::path& dir) {
  std::set<std::string> names;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) names.insert(e.path().filename().string());
  return names;
}

namespace {

std::vector<int> all_pids() {
  std::vector<int> pids;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = e.path().filename().string();
    if (!name.empty() && std::all_of(name.begin(), name.end(), [](char c) { return c >= '0' && c <= '9'; })) {
      pids.push_back(std::atoi(name.c_str()));
    }
  }
  return pids;
}

}  // namespace

std::vector<int> children_of(int pid) {
  std::vector<int> children;
  for (int p : all_pids()) {
    // /proc/<pid>/stat: "pid (comm) state ppid ..."; comm may contain spaces and parentheses.
    const std::string stat = read_file("/proc/" + std::to_string(p) + "/stat");
    const auto close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream rest(stat.substr(close + 1));
    std::string state;
    int ppid = 0;
    if (rest >> state >> ppid && ppid == pid) children.push_back(p);
  }
  return children;
}

std::set<std::string> shm_entries_used_by(int pid) {
  std::set<std::string> used;
  const std::string proc = "/proc/" + std::to_string(pid);
  std::istringstream maps(read_file(proc + "/maps"));
  for (std::string line; std::getline(maps, line);) {
    if (const auto at = line.find("/dev/shm/"); at != std::string::npos) {
      std::string name = line.substr(at + 9);
      if (const auto del = name.find(" (deleted)"); del != std::string::npos) name.erase(del);
      used.insert(name);
    }
  }
  std::error_code ec;
  for (const auto& fd : std::filesystem::directory_iterator(proc + "/fd", ec)) {
    std::error_code ec2;
    const std::string target = std::filesystem::read_symlink(fd.path(), ec2).string();
    if (!ec2 && target.rfind("/dev/shm/", 0) == 0) used.insert(target.substr(9));
  }
  return used;
}

std::set<std::string> shm_entries_in_use() {
  std::set<std::string> used;
  for (int p : all_pids()) used.merge(shm_entries_used_by(p));
  return used;
}

std::vector<std::pair<int, std::string>> bsn_processes_in_domain(int domain) {
  std::vector<std::pair<int, std::string>> found;
  const std::string program = std::filesystem::path(bsn_executable()).filename().string();
  const std::string wanted = std::to_string(domain);
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = e.path().filename().string();
    if (name.empty() || !std::all_of(name.begin(), name.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
    const int pid = std::atoi(name.c_str());
    if (pid == getpid()) continue;
    const std::string cmdline = read_file(e.path() / "cmdline");  // arguments separated by '\0'
    std::vector<std::string> args;
    std::string printable;
    for (std::size_t start = 0; start < cmdline.size();) {
      const std::size_t end = std::min(cmdline.find('\0', start), cmdline.size());
      args.push_back(cmdline.substr(start, end - start));
      printable += (printable.empty() ? "" : " ") + args.back();
      start = end + 1;
    }
    if (args.empty() || std::filesystem::path(args[0]).filename().string() != program) continue;
    for (std::size_t i = 0; i + 1 < args.size(); ++i) {
      if (args[i] == "--domain" && args[i + 1] == wanted) {
        found.emplace_back(pid, printable);
        break;
      }
    }
  }
  return found;
}

void ProcessTest::SetUp() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string templ = std::string("/tmp/bsn-integ-") + info->test_suite_name() + "-" + info->name() + "-XXXXXX";
  std::vector<char> buf(templ.begin(), templ.end());
  buf.push_back('\0');
  ASSERT_NE(mkdtemp(buf.data()), nullptr) << "mkdtemp failed";
  dir_ = buf.data();
}

void ProcessTest::TearDown() {
  for (auto it = children_.rbegin(); it != children_.rend(); ++it) {
    if (it->second->running()) it->second->stop(std::chrono::milliseconds(3000));
  }
  if (HasFailure()) {
    for (const auto& [name, process] : children_) {
      std::cerr << "----- last lines of " << log_path(name).string() << " (pid " << process->pid() << ") -----\n"
                << tail(log_path(name));
    }
  }
  children_.clear();
  if (!dir_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
}

dds::ChildProcess& ProcessTest::spawn(const std::string& name, const std::vector<std::string>& args) {
  std::vector<std::string> argv{bsn_executable()};
  argv.insert(argv.end(), args.begin(), args.end());
  return spawn_command(name, argv);
}

dds::ChildProcess& ProcessTest::spawn_command(const std::string& name, const std::vector<std::string>& argv) {
  children_.emplace_back(name, std::make_unique<dds::ChildProcess>(argv, log_path(name).string()));
  return *children_.back().second;
}

dds::ChildProcess& ProcessTest::child(const std::string& name) {
  for (auto& [n, p] : children_)
    if (n == name) return *p;
  throw std::out_of_range("no child process named " + name);
}

std::optional<int> ProcessTest::stop(const std::string& name, std::chrono::milliseconds grace) {
  return child(name).stop(grace);
}

}  // namespace bsn::integration
