// Blocked transport file and geometry file (formats in docs/transport-format.md).
#include "formats/transport_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <utility>

#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

static_assert(std::endian::native == std::endian::little,
              "prtfarm's file formats are little-endian; this host is not");

namespace {

constexpr char kTransportMagic[8] = {'P', 'R', 'T', 'T', 'R', 'A', 'N', 'S'};
constexpr uint32_t kFlagComplete = 1;
constexpr std::size_t kHeaderChecksumOffset = 88;

template <typename T>
void Put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

template <typename T>
void PutAt(unsigned char* out, std::size_t offset, T value) {
  std::memcpy(out + offset, &value, sizeof(T));
}

template <typename T>
T GetAt(const unsigned char* in, std::size_t offset) {
  T value;
  std::memcpy(&value, in + offset, sizeof(T));
  return value;
}

// Header layout (docs/transport-format.md): fixed 96 bytes, then the checksum table.
std::vector<unsigned char> EncodeHeader(const TransportFileInfo& info, bool complete,
                                        std::span<const uint64_t> checksums) {
  std::vector<unsigned char> h(kTransportHeaderBytes + 8 * checksums.size(), 0);
  std::memcpy(h.data(), kTransportMagic, 8);
  PutAt<uint32_t>(h.data(), 8, kTransportFileVersion);
  PutAt<uint32_t>(h.data(), 12, static_cast<uint32_t>(kTransportHeaderBytes));
  PutAt<uint64_t>(h.data(), 16, info.rows);
  PutAt<uint64_t>(h.data(), 24, info.cols());
  PutAt<uint32_t>(h.data(), 32, info.cubemap_n);
  PutAt<uint32_t>(h.data(), 36, info.rows_per_block);
  PutAt<uint64_t>(h.data(), 40, info.block_count());
  PutAt<uint32_t>(h.data(), 48, info.rays_per_texel);
  PutAt<uint32_t>(h.data(), 52, complete ? kFlagComplete : 0u);
  PutAt<uint64_t>(h.data(), 56, info.seed);
  PutAt<uint64_t>(h.data(), 64, info.data_offset());
  for (std::size_t b = 0; b < checksums.size(); ++b) {
    PutAt<uint64_t>(h.data(), kTransportHeaderBytes + 8 * b, checksums[b]);
  }
  // The header checksum covers bytes [0, 88) and the checksum table.
  XXH64_state_t* state = XXH64_createState();
  XXH64_reset(state, 0);
  XXH64_update(state, h.data(), kHeaderChecksumOffset);
  XXH64_update(state, h.data() + kTransportHeaderBytes, 8 * checksums.size());
  PutAt<uint64_t>(h.data(), kHeaderChecksumOffset, XXH64_digest(state));
  XXH64_freeState(state);
  return h;
}

struct DecodedHeader {
  TransportFileInfo info;
  bool complete = false;
  std::vector<uint64_t> checksums;
};

DecodedHeader DecodeHeader(int fd, const std::string& path) {
  unsigned char h[kTransportHeaderBytes];
  const uint64_t size = FileSize(fd, path);
  if (size < kTransportHeaderBytes || !PreadAll(fd, h, sizeof h, 0, path)) {
    throw InputError(path, "not a prtfarm transport file (shorter than its header)");
  }
  if (std::memcmp(h, kTransportMagic, 8) != 0) {
    throw InputError(path, "not a prtfarm transport file (bad magic)");
  }
  const auto version = GetAt<uint32_t>(h, 8);
  if (version != kTransportFileVersion) {
    throw InputError(path, "transport file version " + std::to_string(version) +
                               " is not supported (this build reads version " +
                               std::to_string(kTransportFileVersion) + ")");
  }
  DecodedHeader d;
  d.info.rows = GetAt<uint64_t>(h, 16);
  const auto cols = GetAt<uint64_t>(h, 24);
  d.info.cubemap_n = GetAt<uint32_t>(h, 32);
  d.info.rows_per_block = GetAt<uint32_t>(h, 36);
  const auto blocks = GetAt<uint64_t>(h, 40);
  d.info.rays_per_texel = GetAt<uint32_t>(h, 48);
  d.complete = (GetAt<uint32_t>(h, 52) & kFlagComplete) != 0;
  d.info.seed = GetAt<uint64_t>(h, 56);
  const auto data_offset = GetAt<uint64_t>(h, 64);
  const auto stored_checksum = GetAt<uint64_t>(h, kHeaderChecksumOffset);
  if (GetAt<uint32_t>(h, 12) != kTransportHeaderBytes || d.info.cubemap_n == 0 ||
      d.info.cubemap_n > 4096 || cols != d.info.cols() || d.info.rows_per_block == 0 ||
      blocks != d.info.block_count() || data_offset != d.info.data_offset() ||
      d.info.rows > (std::numeric_limits<uint64_t>::max() / 2) / d.info.row_bytes()) {
    throw InputError(path, "damaged transport header (inconsistent dimensions)");
  }
  if (size < d.info.file_bytes()) {
    throw InputError(path, "truncated transport file: " + std::to_string(size) + " bytes, " +
                               std::to_string(d.info.file_bytes()) + " expected");
  }
  std::vector<unsigned char> table(8 * blocks);
  if (!table.empty() && !PreadAll(fd, table.data(), table.size(), kTransportHeaderBytes, path)) {
    throw InputError(path, "truncated checksum table");
  }
  d.checksums.resize(blocks);
  for (uint64_t b = 0; b < blocks; ++b) d.checksums[b] = GetAt<uint64_t>(table.data(), 8 * b);
  const auto expected = EncodeHeader(d.info, d.complete, d.checksums);
  if (GetAt<uint64_t>(expected.data(), kHeaderChecksumOffset) != stored_checksum) {
    throw InputError(path, "damaged transport header (header checksum mismatch)");
  }
  return d;
}

}  // namespace

uint64_t TransportFileInfo::RowsInBlock(uint64_t block) const {
  const uint64_t first = FirstRowOfBlock(block);
  return first >= rows ? 0 : std::min<uint64_t>(rows_per_block, rows - first);
}

uint64_t TransportFileInfo::data_offset() const {
  const uint64_t end = kTransportHeaderBytes + 8 * block_count();
  return (end + kTransportDataAlignment - 1) / kTransportDataAlignment * kTransportDataAlignment;
}

// ----------------------------------------------------------------------------- writer

TransportFileWriter::TransportFileWriter(std::string path, TransportFileInfo info, int fd)
    : path_(std::move(path)), info_(info), fd_(fd) {}

TransportFileWriter::TransportFileWriter(TransportFileWriter&& other) noexcept
    : path_(std::move(other.path_)), info_(other.info_), fd_(std::exchange(other.fd_, -1)) {}

TransportFileWriter& TransportFileWriter::operator=(TransportFileWriter&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    path_ = std::move(other.path_);
    info_ = other.info_;
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

TransportFileWriter::~TransportFileWriter() {
  if (fd_ >= 0) ::close(fd_);
}

TransportFileWriter TransportFileWriter::Create(const std::string& path,
                                                const TransportFileInfo& info) {
  if (info.cubemap_n == 0 || info.rows_per_block == 0) {
    throw std::invalid_argument("TransportFileWriter: cubemap_n and rows_per_block must be > 0");
  }
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw FileIoError(path, SystemReason("cannot create"));
  TransportFileWriter writer(path, info, fd);
  if (::ftruncate(fd, static_cast<off_t>(info.file_bytes())) != 0) {
    throw FileIoError(path, SystemReason("cannot size the file"));
  }
  writer.WriteHeader(false, std::vector<uint64_t>(info.block_count(), 0));
  return writer;
}

TransportFileWriter TransportFileWriter::Reopen(const std::string& path,
                                                const TransportFileInfo& info) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) throw FileIoError(path, SystemReason("cannot open"));
  TransportFileWriter writer(path, info, fd);
  const DecodedHeader d = DecodeHeader(fd, path);
  if (!(d.info == info)) {
    throw InputError(path, "transport file dimensions do not match this run");
  }
  if (d.complete) writer.WriteHeader(false, std::vector<uint64_t>(info.block_count(), 0));
  return writer;
}

void TransportFileWriter::WriteHeader(bool complete, std::span<const uint64_t> checksums) {
  const auto h = EncodeHeader(info_, complete, checksums);
  PwriteAll(fd_, h.data(), h.size(), 0, path_);
}

void TransportFileWriter::WriteRows(uint64_t first_row, uint64_t count, const float* rows) {
  if (first_row + count > info_.rows) {
    throw std::out_of_range("TransportFileWriter::WriteRows beyond the last row");
  }
  PwriteAll(fd_, rows, count * info_.row_bytes(),
            info_.data_offset() + first_row * info_.row_bytes(), path_);
}

void TransportFileWriter::ReadRows(uint64_t first_row, uint64_t count, float* rows) const {
  if (first_row + count > info_.rows) {
    throw std::out_of_range("TransportFileWriter::ReadRows beyond the last row");
  }
  if (!PreadAll(fd_, rows, count * info_.row_bytes(),
                info_.data_offset() + first_row * info_.row_bytes(), path_)) {
    throw InputError(path_, "truncated transport file");
  }
}

void TransportFileWriter::Sync() {
  if (::fdatasync(fd_) != 0) throw FileIoError(path_, SystemReason("fdatasync failed"));
}

void TransportFileWriter::Finalize() {
  std::vector<uint64_t> checksums(info_.block_count());
  std::vector<float> block(static_cast<std::size_t>(info_.rows_per_block * info_.cols()));
  for (uint64_t b = 0; b < checksums.size(); ++b) {
    const uint64_t n = info_.RowsInBlock(b);
    ReadRows(info_.FirstRowOfBlock(b), n, block.data());
    checksums[b] = Checksum64(block.data(), n * info_.row_bytes());
  }
  // Rows first, then the header that declares them complete.
  Sync();
  WriteHeader(true, checksums);
  if (::fsync(fd_) != 0) throw FileIoError(path_, SystemReason("fsync failed"));
}

// ----------------------------------------------------------------------------- reader

TransportFileReader::TransportFileReader(const std::string& path) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw InputError(path, SystemReason("cannot open transport file"));
  try {
    DecodedHeader d = DecodeHeader(fd_, path);
    if (!d.complete) {
      throw InputError(path,
                       "incomplete transport file (the farm has not finished it; rerun "
                       "prt-farm with --resume)");
    }
    info_ = d.info;
    checksums_ = std::move(d.checksums);
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
}

TransportFileReader::TransportFileReader(TransportFileReader&& other) noexcept
    : path_(std::move(other.path_)),
      info_(other.info_),
      checksums_(std::move(other.checksums_)),
      fd_(std::exchange(other.fd_, -1)) {}

TransportFileReader& TransportFileReader::operator=(TransportFileReader&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    path_ = std::move(other.path_);
    info_ = other.info_;
    checksums_ = std::move(other.checksums_);
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

TransportFileReader::~TransportFileReader() {
  if (fd_ >= 0) ::close(fd_);
}

void TransportFileReader::ReadBlock(uint64_t block, std::span<float> out) const {
  if (block >= info_.block_count()) throw std::out_of_range("TransportFileReader: no such block");
  const uint64_t n = info_.RowsInBlock(block);
  const uint64_t bytes = n * info_.row_bytes();
  if (out.size() * sizeof(float) < bytes) {
    throw std::invalid_argument("TransportFileReader::ReadBlock: output too small");
  }
  if (!PreadAll(fd_, out.data(), bytes,
                info_.data_offset() + info_.FirstRowOfBlock(block) * info_.row_bytes(), path_)) {
    throw InputError(path_, "truncated transport file in block " + std::to_string(block));
  }
  if (Checksum64(out.data(), bytes) != checksums_[block]) {
    throw InputError(path_, "checksum mismatch in block " + std::to_string(block) + " (rows " +
                                std::to_string(info_.FirstRowOfBlock(block)) + ".." +
                                std::to_string(info_.FirstRowOfBlock(block) + n - 1) +
                                "): the file is damaged");
  }
}

std::vector<float> TransportFileReader::ReadBlock(uint64_t block) const {
  std::vector<float> out(static_cast<std::size_t>(info_.RowsInBlock(block) * info_.cols()));
  ReadBlock(block, out);
  return out;
}

void TransportFileReader::ReadRows(uint64_t first_row, uint64_t count, float* out) const {
  if (first_row + count > info_.rows) {
    throw std::out_of_range("TransportFileReader::ReadRows beyond the last row");
  }
  if (count == 0) return;
  std::vector<float> block;
  const uint64_t cols = info_.cols();
  for (uint64_t b = first_row / info_.rows_per_block;
       b <= (first_row + count - 1) / info_.rows_per_block; ++b) {
    block.resize(static_cast<std::size_t>(info_.RowsInBlock(b) * cols));
    ReadBlock(b, block);
    const uint64_t b0 = info_.FirstRowOfBlock(b);
    const uint64_t lo = std::max(first_row, b0);
    const uint64_t hi = std::min(first_row + count, b0 + info_.RowsInBlock(b));
    std::copy(block.begin() + static_cast<std::ptrdiff_t>((lo - b0) * cols),
              block.begin() + static_cast<std::ptrdiff_t>((hi - b0) * cols),
              out + (lo - first_row) * cols);
  }
}

int64_t TransportFileReader::FindCorruptBlock() const {
  std::vector<float> block;
  for (uint64_t b = 0; b < info_.block_count(); ++b) {
    block.resize(static_cast<std::size_t>(info_.RowsInBlock(b) * info_.cols()));
    try {
      ReadBlock(b, block);
    } catch (const InputError&) {
      return static_cast<int64_t>(b);
    }
  }
  return -1;
}

}  // namespace prt
