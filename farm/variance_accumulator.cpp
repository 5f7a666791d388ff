// Rank 0's variance sums of a sampling run (see variance_accumulator.h).
#include "farm/variance_accumulator.h"

#include <fcntl.h>
#include <unistd.h>

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
  if (!fresh && std::filesystem::exists(log_path_)) {
    const std::string bytes = ReadWholeFile(log_path_);
    for (VarianceLogRecord& r : DecodeVarianceLog(bytes, log_path_)) {
      if (r.sums.cubemap_n != total_.cubemap_n || r.sums.mesh_rows != total_.mesh_rows) continue;
      kept += EncodeVarianceLogRecord(r);
      logged_[{r.phase, r.first, r.count}] = std::move(r.sums);
    }
  }
  // The intact records are written back (a torn tail is dropped) and new ones follow.
  fd_ = ::open(log_path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw FileIoError(log_path_, SystemReason("cannot create"));
  PwriteAll(fd_, kept.data(), kept.size(), 0, log_path_);
  end_ = kept.size();
  dirty_ = !kept.empty();
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
