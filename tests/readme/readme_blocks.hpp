// The shell commands of a Markdown file (the README), as the README-commands test runs them: fenced code blocks in
// order, each split into commands (a line, lines joined by a trailing backslash, or a here-document), with the
// opt-out markers that let prose examples stay unrun. Plain C++, no I/O: text in, blocks out.
//
// A block runs when its fence's language (the first word of the info string) is `sh`, `bash` or `shell`. An HTML
// comment on its own line(s) right before the fence (blank lines between are allowed) opts it out:
//   <!-- readme-test: skip, reason: needs a second machine -->
// Every opt-out names its reason. A marker that is malformed, lacks a reason, or is not followed by a shell block
// is an error, so a marker never silently stops applying.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bsn::readme {

/// One command as a shell reads it: `line` is the 1-based line of the Markdown file where it starts; `text` holds
/// its lines as written (continuation lines and a here-document's body included, joined by '\n'; the block's own
/// indentation removed).
struct Command {
  int line = 0;
  std::string text;
};

/// One fenced code block.
struct CodeBlock {
  int fence_line = 0;                      ///< 1-based line of the opening fence
  std::string language;                    ///< first word of the info string ("" for none)
  std::string attributes;                  ///< the rest of the info string, trimmed
  bool shell = false;                      ///< language is sh, bash or shell
  std::optional<std::string> skip_reason;  ///< set by a `readme-test: skip` marker
  std::vector<std::string> lines;          ///< the block's lines, its own indentation removed
  std::vector<Command> commands;           ///< for shell blocks: the commands, comment-only and blank lines left out

  bool runs() const { return shell && !skip_reason; }
};

/// Every fenced code block of `markdown`, in order. `name` prefixes error messages. Throws std::invalid_argument
/// with "NAME:LINE: problem" for an unclosed fence, a malformed or misplaced marker, a skip without a reason, a
/// trailing backslash at the end of a block or an unterminated here-document.
std::vector<CodeBlock> extract_code_blocks(std::string_view markdown, std::string_view name = "README.md");

/// The manual's pages the README links, in the order of their first link: every `docs/NAME.md` target of a
/// Markdown link `](docs/NAME.md)` or `](docs/NAME.md#anchor)`, each once. The README-commands test runs the README's
/// blocks and then each page's in this order, so a page's commands may use what the README's made.
std::vector<std::string> manual_pages(std::string_view readme);

/// The command without a trailing comment (`# ...` outside quotes, at the start or after a blank) and without
/// surrounding blanks, for matching a command against a known one. Continuation lines are kept as written.
std::string strip_comment(std::string_view command);

}  // namespace bsn::readme
