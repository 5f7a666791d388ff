// Rank 0's variance sums of a sampling run (see variance_accumulator.h).
#include "farm/variance_accumulator.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>

#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"

namespace prt {

VarianceAccumulator::VarianceAccumulator(const RunFolder& folder, std::vector<uint64_t> group_rows,
                                         int cubemap_n, int rays_per_texel, bool fresh)
    : log_path_(folder.variance_log), file_path_(folder.variance) {
  total_ = MakeTransportVariance(static_cast<uint32_t>(cubemap_n),
                                 static_cast<uint32_t>(rays_per_texel), std::move(group_rows));
  std::string kept;
  // The main log, then the ranks' own logs of the runs before (their records of jobs they
  // wrote themselves).
  std::vector<std::string> logs = {log_path_};
  const std::filesystem::path dir = std::filesystem::path(log_path_).parent_path();
  std::error_code ec;
  std::vector<std::string> rank_logs;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("variance.rank-", 0) == 0) rank_logs.push_back(entry.path().string());
  }
  std::sort(rank_logs.begin(), rank_logs.end());
  logs.insert(logs.end(), rank_logs.begin(), rank_logs.end());
  for (const std::string& log : logs) {
    if (fresh || !std::filesystem::exists(log)) continue;
    const std::string bytes = ReadWholeFile(log);
    for (VarianceLogRecord& r : DecodeVarianceLog(bytes, log)) {
      if (r.sums.cubemap_n != total_.cubemap_n || r.sums.mesh_rows != total_.mesh_rows) continue;
      kept += EncodeVarianceLogRecord(r);
      logged_[{r.phase, r.first, r.count}] = std::move(r.sums);
    }
  }
  // The intact records are written back (a torn tail is dropped) and new ones follow; the rank
  // logs go once their records are durable here.
  fd_ = ::open(log_path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw FileIoError(log_path_, SystemReason("cannot create"));
  PwriteAll(fd_, kept.data(), kept.size(), 0, log_path_);
  end_ = kept.size();
  dirty_ = !kept.empty();
  if (!rank_logs.empty()) {
    Sync();
    for (const std::string& log : rank_logs) std::filesystem::remove(log, ec);
  }
}

VarianceAccumulator::~VarianceAccumulator() {
  if (fd_ >= 0) ::close(fd_);
}

TransportVariance VarianceAccumulator::Empty() const {
  return MakeTransportVariance(total_.cubemap_n, total_.rays_per_texel, total_.mesh_rows);
}

void VarianceAccumulator::Record(const std::string& phase, uint64_t first, uint64_t count,
                                 const TransportVariance& sums) {
  total_.Add(sums);
  const std::string bytes = EncodeVarianceLogRecord({phase, first, count, sums});
  PwriteAll(fd_, bytes.data(), bytes.size(), end_, log_path_);
  end_ += bytes.size();
  dirty_ = true;
}

bool VarianceAccumulator::Reuse(const std::string& phase, uint64_t first, uint64_t count) {
  const auto it = logged_.find({phase, first, count});
  if (it == logged_.end()) return false;
  total_.Add(it->second);
  return true;
}

void VarianceAccumulator::Sync() {
  if (!dirty_) return;
  if (::fdatasync(fd_) != 0) throw FileIoError(log_path_, SystemReason("fdatasync failed"));
  dirty_ = false;
}

void VarianceAccumulator::WriteFile() const {
  WriteFileDurably(file_path_, EncodeTransportVariance(total_));
}

}  // namespace prt

namespace prt {

std::string RankVarianceLogPath(const RunFolder& folder, int rank) {
  return (std::filesystem::path(folder.variance_log).parent_path() /
          ("variance.rank-" + std::to_string(rank) + ".log"))
      .string();
}

RankVarianceLog::RankVarianceLog(const RunFolder& folder, int rank, TransportVariance empty)
    : path_(RankVarianceLogPath(folder, rank)), total_(std::move(empty)) {
  fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd_ < 0) throw FileIoError(path_, SystemReason("cannot open"));
}

RankVarianceLog::~RankVarianceLog() {
  if (fd_ >= 0) ::close(fd_);
}

void RankVarianceLog::Record(const std::string& phase, uint64_t first, uint64_t count,
                             const TransportVariance& sums) {
  total_.Add(sums);
  const std::string bytes = EncodeVarianceLogRecord({phase, first, count, sums});
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw FileIoError(path_, SystemReason("write failed"));
    done += static_cast<std::size_t>(n);
  }
  dirty_ = true;
}

void RankVarianceLog::Sync() {
  if (!dirty_) return;
  if (::fdatasync(fd_) != 0) throw FileIoError(path_, SystemReason("fdatasync failed"));
  dirty_ = false;
}

}  // namespace prt
