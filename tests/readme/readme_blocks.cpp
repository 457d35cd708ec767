#include "readme_blocks.hpp"

#include <algorithm>
#include <cctype>
#include <stdexcept>

namespace bsn::readme {
namespace {

struct Line {
  int number = 0;
  std::string_view text;
};

std::vector<Line> split_lines(std::string_view text) {
  std::vector<Line> lines;
  int number = 1;
  while (!text.empty()) {
    const std::size_t end = text.find('\n');
    std::string_view line = text.substr(0, end);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    lines.push_back({number++, line});
    if (end == std::string_view::npos) break;
    text.remove_prefix(end + 1);
  }
  return lines;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

std::size_t indentation(std::string_view s) {
  std::size_t n = 0;
  while (n < s.size() && s[n] == ' ') ++n;
  return n;
}

/// A fence line: up to `max_indent` spaces, then three or more ` or ~.
struct Fence {
  std::size_t indent = 0;
  char mark = 0;
  std::size_t length = 0;
  std::string_view info;  // the rest of the line, trimmed
};

std::optional<Fence> parse_fence(std::string_view line) {
  Fence f;
  f.indent = indentation(line);
  std::string_view rest = line.substr(f.indent);
  if (rest.empty() || (rest[0] != '`' && rest[0] != '~')) return std::nullopt;
  f.mark = rest[0];
  while (f.length < rest.size() && rest[f.length] == f.mark) ++f.length;
  if (f.length < 3) return std::nullopt;
  f.info = trim(rest.substr(f.length));
  return f;
}

[[noreturn]] void fail(std::string_view name, int line, const std::string& problem) {
  throw std::invalid_argument(std::string(name) + ":" + std::to_string(line) + ": " + problem);
}

constexpr std::string_view kMarkerTag = "readme-test:";
constexpr std::string_view kMarkerForm = "<!-- readme-test: skip, reason: WHY -->";

/// The reason of a `readme-test: skip, reason: WHY` comment body (the text between <!-- and -->).
std::string parse_marker(std::string_view body, std::string_view name, int line) {
  std::string_view rest = trim(body);
  rest.remove_prefix(kMarkerTag.size());
  rest = trim(rest);
  if (rest.substr(0, 4) != "skip")
    fail(name, line,
         "unknown readme-test marker '" + std::string(trim(body)) + "'; the form is " + std::string(kMarkerForm));
  rest = trim(rest.substr(4));
  if (!rest.empty() && rest.front() == ',') rest = trim(rest.substr(1));
  if (rest.substr(0, 7) != "reason:")
    fail(name, line, "a readme-test skip needs its reason: " + std::string(kMarkerForm));
  const std::string_view reason = trim(rest.substr(7));
  if (reason.empty()) fail(name, line, "a readme-test skip needs its reason: " + std::string(kMarkerForm));
  return std::string(reason);
}

/// Positions of here-document operators (`<<WORD`, `<<-WORD`, `<<'WORD'`) in a command already stripped of
/// comments, with their delimiters and whether leading tabs are stripped (`<<-`).
struct HereDoc {
  std::string delimiter;
  bool strip_tabs = false;
};

std::vector<HereDoc> here_documents(std::string_view command) {
  std::vector<HereDoc> docs;
  char quote = 0;
  for (std::size_t i = 0; i < command.size(); ++i) {
    const char c = command[i];
    if (quote) {
      if (c == quote)
        quote = 0;
      else if (c == '\\' && quote == '"')
        ++i;
      continue;
    }
    if (c == '\\') {
      ++i;
      continue;
    }
    if (c == '\'' || c == '"') {
      quote = c;
      continue;
    }
    if (c != '<' || i + 1 >= command.size() || command[i + 1] != '<') continue;
    if (i + 2 < command.size() && command[i + 2] == '<') {  // a here-string <<<: no body lines
      i += 2;
      continue;
    }
    std::size_t j = i + 2;
    HereDoc doc;
    if (j < command.size() && command[j] == '-') {
      doc.strip_tabs = true;
      ++j;
    }
    while (j < command.size() && command[j] == ' ') ++j;
    char delimiter_quote = 0;
    if (j < command.size() && (command[j] == '\'' || command[j] == '"')) delimiter_quote = command[j++];
    while (j < command.size() && (std::isalnum(static_cast<unsigned char>(command[j])) || command[j] == '_')) {
      doc.delimiter += command[j++];
    }
    if (delimiter_quote && j < command.size() && command[j] == delimiter_quote) ++j;
    if (!doc.delimiter.empty()) docs.push_back(doc);
    i = j - 1;
  }
  return docs;
}

bool ends_with_continuation(std::string_view line) {
  const std::string code = strip_comment(line);
  return !code.empty() && code.back() == '\\';
}

std::vector<Command> split_commands(const std::vector<Line>& body, std::string_view name, int fence_line) {
  std::vector<Command> commands;
  for (std::size_t i = 0; i < body.size();) {
    const std::string_view first = trim(body[i].text);
    if (first.empty() || first.front() == '#') {
      ++i;
      continue;
    }
    Command command{body[i].number, std::string(body[i].text)};
    std::string_view last = body[i].text;
    ++i;
    while (ends_with_continuation(last)) {
      if (i >= body.size())
        fail(
            name, command.line,
            "the command ends in a backslash, but the block (from line " + std::to_string(fence_line) + ") ends there");
      last = body[i].text;
      command.text += "\n" + std::string(last);
      ++i;
    }
    for (const HereDoc& doc : here_documents(strip_comment(command.text))) {
      bool closed = false;
      while (i < body.size() && !closed) {
        std::string_view line = body[i].text;
        command.text += "\n" + std::string(line);
        ++i;
        if (doc.strip_tabs) {
          while (!line.empty() && line.front() == '\t') line.remove_prefix(1);
        }
        closed = line == doc.delimiter;
      }
      if (!closed) fail(name, command.line, "the here-document '" + doc.delimiter + "' is not closed in its block");
    }
    commands.push_back(std::move(command));
  }
  return commands;
}

}  // namespace

std::string strip_comment(std::string_view command) {
  std::string out;
  char quote = 0;
  bool in_comment = false;
  for (std::size_t i = 0; i < command.size(); ++i) {
    const char c = command[i];
    if (c == '\n') {
      in_comment = false;
      out += c;
      continue;
    }
    if (in_comment) continue;
    if (quote) {
      out += c;
      if (c == quote)
        quote = 0;
      else if (c == '\\' && quote == '"' && i + 1 < command.size())
        out += command[++i];
      continue;
    }
    if (c == '\\' && i + 1 < command.size() && command[i + 1] != '\n') {
      out += c;
      out += command[++i];
      continue;
    }
    if (c == '\'' || c == '"') quote = c;
    if (c == '#' && (out.empty() || std::isspace(static_cast<unsigned char>(out.back())))) {
      in_comment = true;
      continue;
    }
    out += c;
  }
  // Trailing blanks of each line go (they precede a removed comment), and those around the whole command.
  std::string trimmed;
  std::size_t start = 0;
  while (start <= out.size()) {
    const std::size_t end = std::min(out.find('\n', start), out.size());
    std::string_view line(out.data() + start, end - start);
    while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.remove_suffix(1);
    if (!trimmed.empty() || start > 0) trimmed += '\n';
    trimmed += line;
    start = end + 1;
  }
  return std::string(trim(trimmed));
}

std::vector<CodeBlock> extract_code_blocks(std::string_view markdown, std::string_view name) {
  const std::vector<Line> lines = split_lines(markdown);
  std::vector<CodeBlock> blocks;
  std::optional<std::pair<int, std::string>> pending;  // a marker's line and reason, waiting for its block
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string_view text = trim(lines[i].text);
    if (text.substr(0, 4) == "<!--") {
      // An HTML comment, maybe over several lines: a marker if its text starts with `readme-test:`.
      const int marker_line = lines[i].number;
      std::string body(text.substr(4));
      std::size_t end = i;
      while (body.find("-->") == std::string::npos && end + 1 < lines.size()) {
        body += " " + std::string(trim(lines[++end].text));
      }
      if (trim(body).substr(0, kMarkerTag.size()) == kMarkerTag) {
        if (body.find("-->") == std::string::npos)
          fail(name, marker_line, "the readme-test comment is not closed with -->");
        if (pending)
          fail(name, marker_line,
               "a second readme-test marker before the block of the marker at line " + std::to_string(pending->first));
        pending.emplace(marker_line, parse_marker(body.substr(0, body.find("-->")), name, marker_line));
        i = end;
        continue;
      }
    }
    const std::optional<Fence> open = parse_fence(lines[i].text);
    if (!open) {
      if (pending && !text.empty())
        fail(name, pending->first,
             "the readme-test marker is not followed by a code block (line " + std::to_string(lines[i].number) +
                 " comes first)");
      continue;
    }
    CodeBlock block;
    block.fence_line = lines[i].number;
    const std::size_t space = open->info.find_first_of(" \t{");
    block.language = std::string(open->info.substr(0, space));
    block.attributes = space == std::string_view::npos ? "" : std::string(trim(open->info.substr(space)));
    block.shell = block.language == "sh" || block.language == "bash" || block.language == "shell";
    if (pending) {
      if (!block.shell)
        fail(name, pending->first,
             "the readme-test marker is before a '" + block.language +
                 "' block, which is not run anyway; only sh, bash and shell blocks run");
      block.skip_reason = pending->second;
      pending.reset();
    }
    std::vector<Line> body;
    bool closed = false;
    for (++i; i < lines.size(); ++i) {
      const std::optional<Fence> close = parse_fence(lines[i].text);
      if (close && close->mark == open->mark && close->length >= open->length && close->info.empty()) {
        closed = true;
        break;
      }
      std::string_view line = lines[i].text;
      line.remove_prefix(std::min(indentation(line), open->indent));  // the block's own indentation
      body.push_back({lines[i].number, line});
      block.lines.emplace_back(line);
    }
    if (!closed) fail(name, block.fence_line, "the code block is not closed");
    if (block.shell) block.commands = split_commands(body, name, block.fence_line);
    blocks.push_back(std::move(block));
  }
  if (pending) fail(name, pending->first, "the readme-test marker is not followed by a code block");
  return blocks;
}

std::vector<std::string> manual_pages(std::string_view readme) {
  std::vector<std::string> pages;
  constexpr std::string_view kOpen = "](docs/";
  for (std::size_t at = readme.find(kOpen); at != std::string_view::npos; at = readme.find(kOpen, at + 1)) {
    const std::size_t start = at + 2;  // the "docs/" of the target
    const std::size_t end = readme.find_first_of("#)", start);
    if (end == std::string_view::npos) break;
    const std::string page(readme.substr(start, end - start));
    if (page.size() > 3 && page.compare(page.size() - 3, 3, ".md") == 0 &&
        std::find(pages.begin(), pages.end(), page) == pages.end())
      pages.push_back(page);
  }
  return pages;
}

}  // namespace bsn::readme
