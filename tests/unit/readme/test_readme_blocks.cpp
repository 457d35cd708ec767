// The README's shell commands as the README-commands test extracts them: blocks, opt-out markers, commands.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "readme_blocks.hpp"

namespace bsn::readme {
namespace {

using ::testing::HasSubstr;

/// The message of the std::invalid_argument that extracting `markdown` throws ("" if none).
std::string extraction_error(const std::string& markdown) {
  try {
    extract_code_blocks(markdown, "doc.md");
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ReadmeBlocks, ShellBlocksSplitIntoCommandsWithTheirLines) {
  const std::string md =
      "# Title\n"                   // 1
      "\n"                          // 2
      "```sh\n"                     // 3
      "./build/bsn demo   # go\n"   // 4
      "\n"                          // 5
      "# a comment line\n"          // 6
      "./build/bsn echo x\n"        // 7
      "```\n"                       // 8
      "```cpp\n"                    // 9
      "int main() {}\n"             // 10
      "```\n"                       // 11
      "~~~bash title=\"run it\"\n"  // 12
      "ls\n"                        // 13
      "~~~\n"                       // 14
      "```\n"                       // 15
      "plain text\n"                // 16
      "```\n";                      // 17
  const auto blocks = extract_code_blocks(md, "doc.md");
  ASSERT_EQ(blocks.size(), 4u);
  EXPECT_EQ(blocks[0].fence_line, 3);
  EXPECT_EQ(blocks[0].language, "sh");
  EXPECT_TRUE(blocks[0].runs());
  ASSERT_EQ(blocks[0].commands.size(), 2u);
  EXPECT_EQ(blocks[0].commands[0].line, 4);
  EXPECT_EQ(blocks[0].commands[0].text, "./build/bsn demo   # go");
  EXPECT_EQ(blocks[0].commands[1].line, 7);
  EXPECT_EQ(blocks[1].language, "cpp");
  EXPECT_FALSE(blocks[1].shell);
  EXPECT_TRUE(blocks[1].commands.empty());
  EXPECT_EQ(blocks[2].language, "bash");
  EXPECT_EQ(blocks[2].attributes, "title=\"run it\"");
  EXPECT_TRUE(blocks[2].runs());
  ASSERT_EQ(blocks[2].commands.size(), 1u);
  EXPECT_EQ(blocks[2].commands[0].line, 13);
  EXPECT_EQ(blocks[3].language, "");
  EXPECT_FALSE(blocks[3].runs());
  EXPECT_EQ(blocks[3].lines, std::vector<std::string>{"plain text"});
}

TEST(ReadmeBlocks, ASkipMarkerCarriesItsReasonToTheNextBlock) {
  const std::string md =
      "<!-- readme-test: skip, reason: needs a second machine -->\n"  // 1
      "\n"                                                            // 2
      "```sh\n"                                                       // 3
      "ssh other-host bsn fusion\n"                                   // 4
      "```\n"                                                         // 5
      "<!--\n"                                                        // 6
      "  readme-test: skip, reason: installs packages\n"              // 7
      "  with apt -->\n"                                              // 8
      "```sh\n"                                                       // 9
      "sudo apt install x\n"                                          // 10
      "```\n"                                                         // 11
      "```sh\n"                                                       // 12
      "true\n"                                                        // 13
      "```\n";                                                        // 14
  const auto blocks = extract_code_blocks(md, "doc.md");
  ASSERT_EQ(blocks.size(), 3u);
  EXPECT_EQ(blocks[0].skip_reason, "needs a second machine");
  EXPECT_FALSE(blocks[0].runs());
  EXPECT_EQ(blocks[0].commands.size(), 1u);  // still extracted, to be listed
  EXPECT_EQ(blocks[1].skip_reason, "installs packages with apt");
  EXPECT_FALSE(blocks[2].skip_reason.has_value()) << "a marker applies to one block only";
  EXPECT_TRUE(blocks[2].runs());
}

TEST(ReadmeBlocks, AMarkerWithoutReasonOrBlockIsAnErrorAtItsLine) {
  EXPECT_THAT(extraction_error("text\n<!-- readme-test: skip -->\n```sh\nls\n```\n"),
              HasSubstr("doc.md:2: a readme-test skip needs its reason"));
  EXPECT_THAT(extraction_error("<!-- readme-test: skip, reason:   -->\n```sh\nls\n```\n"),
              HasSubstr("doc.md:1: a readme-test skip needs its reason"));
  EXPECT_THAT(extraction_error("<!-- readme-test: norun -->\n```sh\nls\n```\n"),
              HasSubstr("doc.md:1: unknown readme-test marker"));
  EXPECT_THAT(extraction_error("<!-- readme-test: skip, reason: r -->\nSome prose.\n```sh\nls\n```\n"),
              HasSubstr("doc.md:1: the readme-test marker is not followed by a code block (line 2"));
  EXPECT_THAT(extraction_error("<!-- readme-test: skip, reason: r -->\n```cpp\nx;\n```\n"),
              HasSubstr("doc.md:1: the readme-test marker is before a 'cpp' block"));
  EXPECT_THAT(extraction_error("```sh\nls\n```\n<!-- readme-test: skip, reason: r -->\n"),
              HasSubstr("doc.md:4: the readme-test marker is not followed by a code block"));
  EXPECT_THAT(extraction_error("<!-- readme-test: skip, reason: r\n```sh\nls\n```\n"),
              HasSubstr("doc.md:1: the readme-test comment is not closed"));
  // Other HTML comments are prose.
  EXPECT_EQ(extraction_error("<!-- a note -->\n```sh\nls\n```\n"), "");
}

TEST(ReadmeBlocks, ABackslashContinuesTheCommandOnTheNextLine) {
  const std::string md =
      "```sh\n"                            // 1
      "D=x\n"                              // 2
      "./build/bsn tune a \\\n"            // 3
      "  b \\\n"                           // 4
      "  c --holdout 4\n"                  // 5
      "echo done   # not continued: \\\n"  // 6
      "echo next\n"                        // 7
      "```\n";                             // 8
  const auto blocks = extract_code_blocks(md);
  ASSERT_EQ(blocks.size(), 1u);
  const auto& c = blocks[0].commands;
  ASSERT_EQ(c.size(), 4u);
  EXPECT_EQ(c[1].line, 3);
  EXPECT_EQ(c[1].text, "./build/bsn tune a \\\n  b \\\n  c --holdout 4");
  EXPECT_EQ(c[2].line, 6) << "a backslash inside a comment continues nothing";
  EXPECT_EQ(c[3].line, 7);
  EXPECT_THAT(extraction_error("```sh\nls \\\n```\n"),
              HasSubstr("doc.md:2: the command ends in a backslash, but the block (from line 1) ends there"));
}

TEST(ReadmeBlocks, AHereDocumentIsPartOfItsCommand) {
  const std::string md =
      "```sh\n"                              // 1
      "cat > body.yaml <<'EOF'\n"            // 2
      "segments:\n"                          // 3
      "  # a YAML comment, not a command\n"  // 4
      "EOF\n"                                // 5
      "cat <<-END | wc -l\n"                 // 6
      "\tone\n"                              // 7
      "\tEND\n"                              // 8
      "grep x <<< \"$v\"\n"                  // 9
      "echo '<<NOT' \"<<NOT\"\n"             // 10
      "```\n";                               // 11
  const auto blocks = extract_code_blocks(md);
  ASSERT_EQ(blocks.size(), 1u);
  const auto& c = blocks[0].commands;
  ASSERT_EQ(c.size(), 4u);
  EXPECT_EQ(c[0].line, 2);
  EXPECT_EQ(c[0].text, "cat > body.yaml <<'EOF'\nsegments:\n  # a YAML comment, not a command\nEOF");
  EXPECT_EQ(c[1].line, 6);
  EXPECT_EQ(c[1].text, "cat <<-END | wc -l\n\tone\n\tEND");
  EXPECT_EQ(c[2].line, 9) << "a here-string has no body";
  EXPECT_EQ(c[3].line, 10) << "quoted << is no here-document";
  EXPECT_THAT(extraction_error("```sh\ncat <<EOF\nno end\n```\n"),
              HasSubstr("doc.md:2: the here-document 'EOF' is not closed"));
}

TEST(ReadmeBlocks, IndentedAndLongerFences) {
  const std::string md =
      "- a list item:\n"          // 1
      "\n"                        // 2
      "  ```sh\n"                 // 3
      "  cmake --build x\n"       // 4
      "    --more\n"              // 5
      "  ```\n"                   // 6
      "````markdown\n"            // 7
      "```sh\n"                   // 8
      "not a block of its own\n"  // 9
      "```\n"                     // 10
      "````\n";                   // 11
  const auto blocks = extract_code_blocks(md);
  ASSERT_EQ(blocks.size(), 2u);
  ASSERT_EQ(blocks[0].commands.size(), 2u);
  EXPECT_EQ(blocks[0].commands[0].text, "cmake --build x") << "the block's indentation is removed";
  EXPECT_EQ(blocks[0].commands[1].text, "  --more");
  EXPECT_EQ(blocks[1].language, "markdown");
  EXPECT_THAT(extraction_error("text\n```sh\nls\n"), HasSubstr("doc.md:2: the code block is not closed"));
}

TEST(ReadmeBlocks, StripCommentLeavesQuotedAndParameterHashes) {
  EXPECT_EQ(strip_comment("./build/bsn eval x   # every filter"), "./build/bsn eval x");
  EXPECT_EQ(strip_comment("echo \"a # b\" 'c # d' # e"), "echo \"a # b\" 'c # d'");
  EXPECT_EQ(strip_comment("echo $# ${#x} a#b"), "echo $# ${#x} a#b");
  EXPECT_EQ(strip_comment("a \\\n  b   # c\n  d"), "a \\\n  b\n  d");
  EXPECT_EQ(strip_comment("# only a comment"), "");
}

TEST(ReadmeBlocks, TheManualsPagesAreTheDocsLinksInTheirOrderEachOnce) {
  const std::string md =
      "see [a](docs/b.md#x), [c](docs/a.md) and [again](docs/b.md)\n"
      "not a page: [d](docs/picture.png), [e](other/f.md), [g](#h)\n";
  EXPECT_EQ(manual_pages(md), (std::vector<std::string>{"docs/b.md", "docs/a.md"}));
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// Checks one Markdown file's blocks; returns how many of them run.
int check_blocks(const std::string& name, const std::string& text) {
  std::vector<CodeBlock> blocks;
  EXPECT_NO_THROW(blocks = extract_code_blocks(text, name)) << name << " has a malformed block or marker";
  int runnable = 0;
  for (const auto& b : blocks) {
    if (b.skip_reason) {
      EXPECT_FALSE(b.skip_reason->empty()) << name << ":" << b.fence_line;
    }
    // Commands hidden in a text block would escape the test: they belong in a sh block (with a marker if need be).
    if (!b.shell) {
      for (const auto& line : b.lines) {
        for (const char* command : {"./build/", "bsn ", "cmake ", "git ", "sudo ", "export "}) {
          EXPECT_NE(line.rfind(command, 0), 0u)
              << name << ":" << b.fence_line << ": a '" << b.language << "' block holds the shell command '" << line
              << "': make it a sh block (with a readme-test marker if it cannot run)";
        }
      }
    }
    if (b.runs()) {
      EXPECT_FALSE(b.commands.empty()) << name << ":" << b.fence_line << ": a shell block without a command";
      ++runnable;
    }
  }
  return runnable;
}

// The real README and the manual's pages in docs/: every marker is well formed and placed, every shell block runs
// or says why not, and every page of docs/ is linked from the README (the README test reaches a page only so).
TEST(ReadmeBlocks, TheReadmeAndTheManualParseAndEveryOptOutHasItsReason) {
  const std::filesystem::path readme(BSN_README);
  const std::string text = read_text(readme);
  ASSERT_FALSE(text.empty()) << "cannot read " << readme;
  int runnable = check_blocks("README.md", text);
  const std::vector<std::string> pages = manual_pages(text);
  for (const auto& page : pages) {
    const std::string page_text = read_text(readme.parent_path() / page);
    EXPECT_FALSE(page_text.empty()) << "README.md links " << page << ", which is missing or empty";
    runnable += check_blocks(page, page_text);
  }
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(readme.parent_path() / "docs", ec)) {
    if (e.path().extension() != ".md") continue;
    const std::string page = "docs/" + e.path().filename().string();
    EXPECT_NE(std::find(pages.begin(), pages.end(), page), pages.end())
        << page << " is not linked from README.md: the README test would never run its commands";
  }
  // The walkthroughs are shell blocks; none of them running would mean the markers took over.
  EXPECT_GE(runnable, 5);
}

}  // namespace
}  // namespace bsn::readme
