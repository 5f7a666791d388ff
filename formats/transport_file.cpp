// Blocked transport file and geometry file (formats in docs/transport-format.md).
#include "formats/transport_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <utility>

#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr char kTransportMagic[8] = {'P', 'R', 'T', 'T', 'R', 'A', 'N', 'S'};
constexpr uint32_t kFlagComplete = 1;
constexpr uint32_t kFlagPacked = 2;
constexpr uint64_t kCodecZstd = 1;
constexpr std::size_t kHeaderChecksumOffset = 88;

// Packed (version 2): the tables after the header, then the frames (no alignment).
uint64_t PackedDataOffset(const TransportFileInfo& info) {
  return kTransportHeaderBytes + 8 * info.block_count() + 8 * (info.block_count() + 1);
}

// Bytes [0, 72) of the header, which both versions share (docs/transport-format.md).
void PutFixedFields(std::span<uint8_t> h, const TransportFileInfo& info, uint32_t version,
                    uint32_t flags, uint64_t data_offset) {
  std::memcpy(h.data(), kTransportMagic, 8);
  StoreAt<uint32_t>(h, 8, version);
  StoreAt<uint32_t>(h, 12, static_cast<uint32_t>(kTransportHeaderBytes));
  StoreAt<uint64_t>(h, 16, info.rows);
  StoreAt<uint64_t>(h, 24, info.cols());
  StoreAt<uint32_t>(h, 32, info.cubemap_n);
  StoreAt<uint32_t>(h, 36, info.rows_per_block);
  StoreAt<uint64_t>(h, 40, info.block_count());
  StoreAt<uint32_t>(h, 48, info.rays_per_texel);
  StoreAt<uint32_t>(h, 52, flags);
  StoreAt<uint64_t>(h, 56, info.seed);
  StoreAt<uint64_t>(h, 64, data_offset);
}

// Header layout (docs/transport-format.md): fixed 96 bytes, then the checksum table.
std::vector<unsigned char> EncodeHeader(const TransportFileInfo& info, bool complete,
                                        std::span<const uint64_t> checksums) {
  std::vector<unsigned char> h(kTransportHeaderBytes + 8 * checksums.size(), 0);
  PutFixedFields(h, info, kTransportFileVersion, complete ? kFlagComplete : 0u, info.data_offset());
  for (std::size_t b = 0; b < checksums.size(); ++b) {
    StoreAt<uint64_t>(h, kTransportHeaderBytes + 8 * b, checksums[b]);
  }
  // The header checksum covers bytes [0, 88) and the checksum table.
  XXH64_state_t* state = XXH64_createState();
  XXH64_reset(state, 0);
  XXH64_update(state, h.data(), kHeaderChecksumOffset);
  XXH64_update(state, h.data() + kTransportHeaderBytes, 8 * checksums.size());
  StoreAt<uint64_t>(h, kHeaderChecksumOffset, XXH64_digest(state));
  XXH64_freeState(state);
  return h;
}

// The packed header (version 2): the same fixed fields with the packed data offset and the
// codec, then the checksum table and the B + 1 frame offsets, all covered by the header checksum.
std::vector<unsigned char> EncodePackedHeader(const TransportFileInfo& info,
                                              std::span<const uint64_t> checksums,
                                              std::span<const uint64_t> offsets) {
  const std::size_t blocks = checksums.size();
  std::vector<unsigned char> h(kTransportHeaderBytes + 8 * blocks + 8 * offsets.size(), 0);
  PutFixedFields(h, info, kPackedTransportFileVersion, kFlagComplete | kFlagPacked,
                 PackedDataOffset(info));
  StoreAt<uint64_t>(h, 72, kCodecZstd);
  for (std::size_t b = 0; b < blocks; ++b) {
    StoreAt<uint64_t>(h, kTransportHeaderBytes + 8 * b, checksums[b]);
  }
  for (std::size_t b = 0; b < offsets.size(); ++b) {
    StoreAt<uint64_t>(h, kTransportHeaderBytes + 8 * blocks + 8 * b, offsets[b]);
  }
  XXH64_state_t* state = XXH64_createState();
  XXH64_reset(state, 0);
  XXH64_update(state, h.data(), kHeaderChecksumOffset);
  XXH64_update(state, h.data() + kTransportHeaderBytes, h.size() - kTransportHeaderBytes);
  StoreAt<uint64_t>(h, kHeaderChecksumOffset, XXH64_digest(state));
  XXH64_freeState(state);
  return h;
}

struct DecodedHeader {
  TransportFileInfo info;
  bool complete = false;
  std::vector<uint64_t> checksums;
  std::vector<uint64_t> offsets;  // packed only
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
  const auto version = LoadAt<uint32_t>(h, 8);
  if (version != kTransportFileVersion && version != kPackedTransportFileVersion) {
    throw InputError(path, "transport file version " + std::to_string(version) +
                               " is not supported (this build reads versions " +
                               std::to_string(kTransportFileVersion) + " and " +
                               std::to_string(kPackedTransportFileVersion) + ")");
  }
  const bool packed = version == kPackedTransportFileVersion;
  DecodedHeader d;
  d.info.rows = LoadAt<uint64_t>(h, 16);
  const auto cols = LoadAt<uint64_t>(h, 24);
  d.info.cubemap_n = LoadAt<uint32_t>(h, 32);
  d.info.rows_per_block = LoadAt<uint32_t>(h, 36);
  const auto blocks = LoadAt<uint64_t>(h, 40);
  d.info.rays_per_texel = LoadAt<uint32_t>(h, 48);
  d.complete = (LoadAt<uint32_t>(h, 52) & kFlagComplete) != 0;
  d.info.seed = LoadAt<uint64_t>(h, 56);
  const auto data_offset = LoadAt<uint64_t>(h, 64);
  const auto stored_checksum = LoadAt<uint64_t>(h, kHeaderChecksumOffset);
  if (LoadAt<uint32_t>(h, 12) != kTransportHeaderBytes || d.info.cubemap_n == 0 ||
      d.info.cubemap_n > 4096 || cols != d.info.cols() || d.info.rows_per_block == 0 ||
      blocks != d.info.block_count() ||
      d.info.rows > (std::numeric_limits<uint64_t>::max() / 2) / d.info.row_bytes() ||
      blocks > size / 16 ||
      data_offset != (packed ? PackedDataOffset(d.info) : d.info.data_offset()) ||
      (packed && (LoadAt<uint32_t>(h, 52) != (kFlagComplete | kFlagPacked) ||
                  LoadAt<uint64_t>(h, 72) != kCodecZstd))) {
    throw InputError(path, "damaged transport header (inconsistent dimensions)");
  }
  if (packed) {
    d.complete = true;
    if (size < data_offset) throw InputError(path, "truncated packed transport file (tables)");
    std::vector<unsigned char> tables(data_offset - kTransportHeaderBytes);
    if (!PreadAll(fd, tables.data(), tables.size(), kTransportHeaderBytes, path)) {
      throw InputError(path, "truncated packed transport file (tables)");
    }
    d.checksums.resize(blocks);
    d.offsets.resize(blocks + 1);
    for (uint64_t b = 0; b < blocks; ++b) d.checksums[b] = LoadAt<uint64_t>(tables, 8 * b);
    for (uint64_t b = 0; b <= blocks; ++b) {
      d.offsets[b] = LoadAt<uint64_t>(tables, 8 * blocks + 8 * b);
    }
    const auto expected = EncodePackedHeader(d.info, d.checksums, d.offsets);
    if (LoadAt<uint64_t>(expected, kHeaderChecksumOffset) != stored_checksum) {
      throw InputError(path, "damaged transport header (header checksum mismatch)");
    }
    if (d.offsets.front() != data_offset || d.offsets.back() != size) {
      throw InputError(path, "packed transport file of " + std::to_string(size) +
                                 " bytes, its frame table ends at " +
                                 std::to_string(d.offsets.back()) + " (truncated or damaged)");
    }
    for (uint64_t b = 0; b < blocks; ++b) {
      const uint64_t frame = d.offsets[b + 1] - d.offsets[b];
      if (d.offsets[b + 1] < d.offsets[b] ||
          frame > ZSTD_compressBound(d.info.RowsInBlock(b) * d.info.row_bytes())) {
        throw InputError(path, "damaged frame table at block " + std::to_string(b));
      }
    }
    return d;
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
  for (uint64_t b = 0; b < blocks; ++b) d.checksums[b] = LoadAt<uint64_t>(table, 8 * b);
  const auto expected = EncodeHeader(d.info, d.complete, d.checksums);
  if (LoadAt<uint64_t>(expected, kHeaderChecksumOffset) != stored_checksum) {
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

// An existing plain transport file of `info`, opened to write rows; `complete` says whether its
// header is marked complete.
TransportFileWriter TransportFileWriter::OpenExisting(const std::string& path,
                                                      const TransportFileInfo& info,
                                                      bool& complete) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) throw FileIoError(path, SystemReason("cannot open"));
  TransportFileWriter writer(path, info, fd);
  const DecodedHeader d = DecodeHeader(fd, path);
  if (!d.offsets.empty()) throw InputError(path, "a packed transport file cannot be written to");
  if (!(d.info == info)) throw InputError(path, "transport file dimensions do not match this run");
  complete = d.complete;
  return writer;
}

TransportFileWriter TransportFileWriter::Reopen(const std::string& path,
                                                const TransportFileInfo& info) {
  bool complete = false;
  TransportFileWriter writer = OpenExisting(path, info, complete);
  if (complete) writer.WriteHeader(false, std::vector<uint64_t>(info.block_count(), 0));
  return writer;
}

TransportFileWriter TransportFileWriter::OpenRows(const std::string& path,
                                                  const TransportFileInfo& info) {
  bool complete = false;
  TransportFileWriter writer = OpenExisting(path, info, complete);
  if (complete) throw InputError(path, "is complete: no rows may be written into it");
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
    offsets_ = std::move(d.offsets);
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
      offsets_(std::move(other.offsets_)),
      fd_(std::exchange(other.fd_, -1)) {}

TransportFileReader& TransportFileReader::operator=(TransportFileReader&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    path_ = std::move(other.path_);
    info_ = other.info_;
    checksums_ = std::move(other.checksums_);
    offsets_ = std::move(other.offsets_);
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
  if (packed()) {
    thread_local std::string frame;
    frame.resize(static_cast<std::size_t>(offsets_[block + 1] - offsets_[block]));
    if (!PreadAll(fd_, frame.data(), frame.size(), offsets_[block], path_)) {
      throw InputError(path_, "truncated transport file in block " + std::to_string(block));
    }
    const unsigned long long declared = ZSTD_getFrameContentSize(frame.data(), frame.size());
    if (declared != bytes) {
      throw InputError(path_, "block " + std::to_string(block) +
                                  " is not a zstd frame of its rows' size: the file is damaged");
    }
    const std::size_t got = ZSTD_decompress(out.data(), bytes, frame.data(), frame.size());
    if (ZSTD_isError(got) || got != bytes) {
      throw InputError(path_, "block " + std::to_string(block) + " does not decompress (" +
                                  (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short") +
                                  "): the file is damaged");
    }
  } else if (!PreadAll(fd_, out.data(), bytes,
                       info_.data_offset() + info_.FirstRowOfBlock(block) * info_.row_bytes(),
                       path_)) {
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

uint64_t TransportFileReader::StoredBlockBytes(uint64_t block) const {
  if (block >= info_.block_count()) throw std::out_of_range("TransportFileReader: no such block");
  return packed() ? offsets_[block + 1] - offsets_[block]
                  : info_.RowsInBlock(block) * info_.row_bytes();
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

// ----------------------------------------------------------------------------- packed writer

std::string CompressTransportBlock(const float* rows, std::size_t floats, int level) {
  const std::size_t bytes = floats * sizeof(float);
  std::string frame(ZSTD_compressBound(bytes), '\0');
  const std::size_t n = ZSTD_compress(frame.data(), frame.size(), rows, bytes, level);
  if (ZSTD_isError(n)) {
    throw std::runtime_error(std::string("CompressTransportBlock: ") + ZSTD_getErrorName(n));
  }
  frame.resize(n);
  return frame;
}

PackedTransportWriter::PackedTransportWriter(std::string path, const TransportFileInfo& info)
    : path_(std::move(path)), tmp_(path_ + ".tmp"), info_(info) {
  if (info.cubemap_n == 0 || info.rows_per_block == 0) {
    throw std::invalid_argument("PackedTransportWriter: cubemap_n and rows_per_block must be > 0");
  }
  fd_ = ::open(tmp_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw FileIoError(tmp_, SystemReason("cannot create"));
  offsets_.push_back(PackedDataOffset(info));
}

PackedTransportWriter::~PackedTransportWriter() {
  if (fd_ >= 0) {
    ::close(fd_);
    std::error_code ec;
    std::filesystem::remove(tmp_, ec);  // not finished: nothing half-written stays
  }
}

void PackedTransportWriter::Append(uint64_t block, std::string_view frame, uint64_t checksum) {
  if (block != checksums_.size() || block >= info_.block_count()) {
    throw std::logic_error("PackedTransportWriter: block " + std::to_string(block) +
                           " out of order");
  }
  PwriteAll(fd_, frame.data(), frame.size(), offsets_.back(), tmp_);
  checksums_.push_back(checksum);
  offsets_.push_back(offsets_.back() + frame.size());
}

void PackedTransportWriter::Place(uint64_t block, uint64_t frame_bytes, uint64_t checksum) {
  if (block != checksums_.size() || block >= info_.block_count()) {
    throw std::logic_error("PackedTransportWriter: block " + std::to_string(block) +
                           " out of order");
  }
  checksums_.push_back(checksum);
  offsets_.push_back(offsets_.back() + frame_bytes);
}

uint64_t PackedTransportWriter::FirstFrameOffset(const TransportFileInfo& info) {
  return PackedDataOffset(info);
}

uint64_t PackedTransportWriter::Finish() {
  if (checksums_.size() != info_.block_count()) {
    throw std::logic_error("PackedTransportWriter: " + std::to_string(checksums_.size()) + " of " +
                           std::to_string(info_.block_count()) + " blocks written");
  }
  const auto h = EncodePackedHeader(info_, checksums_, offsets_);
  PwriteAll(fd_, h.data(), h.size(), 0, tmp_);
  if (::fsync(fd_) != 0) throw FileIoError(tmp_, SystemReason("fsync failed"));
  ::close(fd_);
  fd_ = -1;
  std::error_code ec;
  std::filesystem::rename(tmp_, path_, ec);
  if (ec) throw FileIoError(path_, "cannot rename " + tmp_ + " into place: " + ec.message());
  const std::string dir = std::filesystem::path(path_).parent_path().string();
  SyncDirectory(dir.empty() ? "." : dir);
  return offsets_.back();
}

}  // namespace prt
