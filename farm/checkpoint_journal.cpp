// Checkpoint journal (see checkpoint_journal.h).
#include "farm/checkpoint_journal.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cinttypes>
#include <cstring>
#include <sstream>

#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr const char* kJournalMagic = "prt-farm-journal";

bool ParseHex16(const std::string& s, uint64_t& v) {
  if (s.size() != 16) return false;
  v = 0;
  for (char c : s) {
    int d;
    if (c >= '0' && c <= '9') {
      d = c - '0';
    } else if (c >= 'a' && c <= 'f') {
      d = c - 'a' + 10;
    } else {
      return false;
    }
    v = (v << 4) | static_cast<uint64_t>(d);
  }
  return true;
}

}  // namespace

std::string FormatJournalLine(const JournalEntry& e) {
  char busy[32];
  std::snprintf(busy, sizeof busy, "%.6f", e.busy_seconds);
  if (!e.phase.empty()) {
    std::string body = "sjob";
    for (const std::string& field :
         {e.phase, std::to_string(e.rows.first), std::to_string(e.rows.count),
          Hex16(e.rows_checksum), std::to_string(e.rank), std::string(busy),
          std::to_string(e.counters.size())}) {
      body.append(1, ' ').append(field);
    }
    for (uint64_t c : e.counters) body.append(1, ' ').append(std::to_string(c));
    return body + " " + Hex16(Checksum64(body.data(), body.size()));
  }
  std::string body = "job " + std::to_string(e.rows.first) + " " + std::to_string(e.rows.count) +
                     " " + Hex16(e.rows_checksum) + " " + std::to_string(e.rank) + " " +
                     std::to_string(e.rays_traced) + " " + std::to_string(e.texels_traced) + " " +
                     std::to_string(e.texels_below_horizon) + " " +
                     std::to_string(e.rays_below_horizon) + " " + busy;
  return body + " " + Hex16(Checksum64(body.data(), body.size()));
}

bool ParseJournalLine(const std::string& line, JournalEntry& e) {
  const std::size_t last = line.rfind(' ');
  if (last == std::string::npos) return false;
  uint64_t sum;
  if (!ParseHex16(line.substr(last + 1), sum)) return false;
  if (Checksum64(line.data(), last) != sum) return false;
  std::istringstream in(line.substr(0, last));
  std::string tag, checksum;
  if (line.rfind("sjob ", 0) == 0) {
    std::size_t k = 0;
    if (!(in >> tag >> e.phase >> e.rows.first >> e.rows.count >> checksum >> e.rank >>
          e.busy_seconds >> k) ||
        k > 64) {
      return false;
    }
    e.counters.assign(k, 0);
    for (uint64_t& c : e.counters)
      if (!(in >> c)) return false;
    return ParseHex16(checksum, e.rows_checksum) && e.rows.count > 0;
  }
  if (!(in >> tag >> e.rows.first >> e.rows.count >> checksum >> e.rank >> e.rays_traced >>
        e.texels_traced >> e.texels_below_horizon >> e.rays_below_horizon >> e.busy_seconds)) {
    return false;
  }
  return tag == "job" && ParseHex16(checksum, e.rows_checksum) && e.rows.count > 0;
}

JournalContents ReadJournal(const std::string& path) {
  JournalContents c;
  if (::access(path.c_str(), F_OK) != 0) return c;
  const std::string text = ReadWholeFile(path);
  std::size_t pos = 0;
  bool first = true;
  while (pos < text.size()) {
    std::size_t nl = text.find('\n', pos);
    const bool torn = nl == std::string::npos;  // the last line never got its newline
    if (torn) nl = text.size();
    const std::string line = text.substr(pos, nl - pos);
    pos = nl + 1;
    if (first) {
      first = false;
      std::istringstream in(line);
      std::string magic, key;
      int version = 0;
      if (torn || !(in >> magic >> version >> key) || magic != kJournalMagic || version != 1 ||
          !ParseHex16(key, c.run_key)) {
        throw InputError(path, "not a prt-farm checkpoint journal (bad first line)");
      }
      c.has_header = true;
      continue;
    }
    JournalEntry e;
    if (!torn && ParseJournalLine(line, e)) {
      c.entries.push_back(e);
    } else if (!line.empty()) {
      ++c.damaged_lines;
    }
  }
  return c;
}

CheckpointJournal::CheckpointJournal(const std::string& path, uint64_t run_key,
                                     const std::vector<JournalEntry>& entries)
    : path_(path) {
  std::string text = std::string(kJournalMagic) + " 1 " + Hex16(run_key) + "\n";
  for (const JournalEntry& e : entries) text += FormatJournalLine(e) + "\n";
  WriteFileDurably(path, text);
  fd_ = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd_ < 0)
    throw FileIoError(path, std::string("cannot open for appending: ") + std::strerror(errno));
}

CheckpointJournal::~CheckpointJournal() {
  if (fd_ >= 0) ::close(fd_);
}

void CheckpointJournal::Append(const std::vector<JournalEntry>& entries) {
  if (entries.empty()) return;
  std::string text;
  for (const JournalEntry& e : entries) text += FormatJournalLine(e) + "\n";
  const char* p = text.data();
  std::size_t left = text.size();
  while (left > 0) {
    const ssize_t n = ::write(fd_, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw FileIoError(path_, std::string("journal write failed: ") + std::strerror(errno));
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  if (::fsync(fd_) != 0) {
    throw FileIoError(path_, std::string("journal fsync failed: ") + std::strerror(errno));
  }
}

}  // namespace prt
