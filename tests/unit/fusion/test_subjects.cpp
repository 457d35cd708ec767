// Team files and the subject of a body file: which subjects a fusion process serves, with FILE:LINE errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "bsn/config/subjects.hpp"

namespace bsn::config {
namespace {

namespace fs = std::filesystem;

class Subjects : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("bsn_subjects_test_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  /// The message of the ConfigError that loading `path` throws ("" if none).
  static std::string error_of(const std::string& path) {
    try {
      (void)load_subject_entries(path);
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  }
  fs::path dir_;
};

constexpr const char* kBody = "segments:\n  - name: pelvis\n    node: a_pelvis\n";

TEST_F(Subjects, ABodyFileIsOneSubjectNamedByItsSubjectKey) {
  const auto plain = load_subject_entries(write("plain.yaml", kBody));
  ASSERT_EQ(plain.size(), 1u);
  EXPECT_EQ(plain[0].subject, "");  // the default partition, as before subjects existed
  const auto named = load_subject_entries(write("named.yaml", std::string("subject: lab-3\n") + kBody));
  ASSERT_EQ(named.size(), 1u);
  EXPECT_EQ(named[0].subject, "lab-3");
  EXPECT_EQ(named[0].share, 0);
  EXPECT_EQ(load_body_model(named[0].body_path).segments.size(), 1u);  // the body parser accepts the key
}

TEST_F(Subjects, ATeamFileListsSubjectsTheirBodiesRelativeToItAndTheirShares) {
  fs::create_directories(dir_ / "bodies");
  write("bodies/a.yaml", kBody);
  const auto team =
      load_subject_entries(write("team.yaml",
                                 "subjects:\n  - name: a\n    body: bodies/a.yaml\n    share: 2\n  - name: b\n"
                                 "    body: bodies/a.yaml\n"));
  ASSERT_EQ(team.size(), 2u);
  EXPECT_EQ(team[0].subject, "a");
  EXPECT_EQ(team[0].share, 2);
  EXPECT_EQ(fs::path(team[0].body_path), dir_ / "bodies/a.yaml");
  EXPECT_EQ(team[1].subject, "b");
  EXPECT_EQ(team[1].share, 0);
}

TEST_F(Subjects, EveryMistakeInATeamFileIsNamedAtItsLine) {
  EXPECT_EQ(error_of(write("t1.yaml", "subjects:\n  - name: a\n    body: a.yaml\n  - name: a\n    body: b.yaml\n")),
            (dir_ / "t1.yaml").string() + ":4: subject 'a' is listed twice");
  EXPECT_NE(error_of(write("t2.yaml", "subjects:\n  - name: a\n")).find("t2.yaml:2: subject without 'body'"),
            std::string::npos);
  EXPECT_NE(error_of(write("t3.yaml", "subjects:\n  - name: 'a*'\n    body: a.yaml\n"))
                .find("t3.yaml:2: subject 'a*' has a character other than"),
            std::string::npos);
  EXPECT_NE(error_of(write("t4.yaml", "subjects:\n  - name: a\n    body: a.yaml\n    share: 0.5\n"))
                .find("t4.yaml:4: share must be a whole number"),
            std::string::npos);
  EXPECT_NE(error_of(write("t5.yaml", "subjects: []\n")).find("t5.yaml:1: 'subjects' must be a list"),
            std::string::npos);
  EXPECT_NE(error_of(write("t6.yaml", "subjects:\n  - name: a\n    body: a.yaml\n    host: x\n"))
                .find("t6.yaml:4: unknown key 'host' in a subject"),
            std::string::npos);
  EXPECT_NE(error_of(write("t7.yaml", std::string("subject: a/b\n") + kBody)).find("t7.yaml:1: subject 'a/b'"),
            std::string::npos);
}

TEST(SubjectNames, ArePartitionNamesWithoutPatterns) {
  EXPECT_EQ(subject_name_problem("s01"), "");
  EXPECT_EQ(subject_name_problem("Team_A-2.b"), "");
  for (const char* bad : {"a*", "a?", "[ab]", "a b", "a/b", "a\\b"}) EXPECT_NE(subject_name_problem(bad), "") << bad;
  EXPECT_NE(subject_name_problem(std::string(65, 'a')), "");
}

}  // namespace
}  // namespace bsn::config
