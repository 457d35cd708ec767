// `bsn fusion --body FILE` on broken body files: it must refuse to start (non-zero exit) and say where and what,
// as "FILE:LINE: problem" on stderr.
#include <gtest/gtest.h>

#include <string>

#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

class BodyFileErrors : public ProcessTest {
 protected:
  /// Runs fusion on `yaml` and checks the exit code and that its output has "<path>:<line>: " followed (on the
  /// same line) by every one of `problem_words`.
  void expect_error(int domain, const std::string& yaml, int line, const std::vector<std::string>& problem_words) {
    const std::string path = (dir() / "body.yaml").string();
    write_file(path, yaml);
    auto& fusion = spawn("fusion", {"fusion", "--body", path, "--domain", std::to_string(domain)});
    const auto st = fusion.wait_for(20s);  // it fails while parsing, before any DDS set-up
    ASSERT_TRUE(st.has_value()) << "bsn fusion did not exit within 20 s on a broken body file";
    EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) != 0) << describe_status(st);

    const std::string out = read_file(log_path("fusion"));
    const std::string where = path + ":" + std::to_string(line) + ": ";
    const auto at = out.find(where);
    ASSERT_NE(at, std::string::npos) << "expected '" << where << "' in the output:\n" << out;
    const std::string message = out.substr(at, out.find('\n', at) - at);
    for (const auto& w : problem_words)
      EXPECT_NE(message.find(w), std::string::npos) << "'" << w << "' not in: " << message;
  }
};

TEST_F(BodyFileErrors, UnknownKey) {
  expect_error(test_domain(3),
               "name: t\n"
               "segments:\n"
               "  - name: a\n"
               "    node: na\n"
               "    colour: red\n",
               5, {"unknown key", "colour"});
}

TEST_F(BodyFileErrors, DuplicateSegment) {
  expect_error(test_domain(4),
               "name: t\n"
               "segments:\n"
               "  - name: a\n"
               "    node: na\n"
               "  - name: b\n"
               "    node: nb\n"
               "    parent: a\n"
               "  - name: a\n"  // line 8: the second 'a'
               "    node: nc\n",
               8, {"duplicate segment", "'a'"});
}

TEST_F(BodyFileErrors, ParentCycle) {
  // r is a proper root; a -> b -> a is the cycle, reported at the entry of a (line 5).
  expect_error(test_domain(5),
               "name: t\n"
               "segments:\n"
               "  - name: r\n"
               "    node: nr\n"
               "  - name: a\n"
               "    node: na\n"
               "    parent: b\n"
               "  - name: b\n"
               "    node: nb\n"
               "    parent: a\n",
               5, {"parent cycle", "a -> b -> a"});
}

TEST_F(BodyFileErrors, YamlSyntaxError) {
  // The '[' on line 5 is never closed; the parser only notices on a later line. The report names line 5.
  expect_error(test_domain(6),
               "name: t\n"
               "segments:\n"
               "  - name: a\n"
               "    node: na\n"
               "    joint_axes: [z, y\n"
               "  - name: b\n"
               "    node: nb\n",
               5, {"YAML syntax error", "never closed"});
}

}  // namespace
}  // namespace bsn::integration
