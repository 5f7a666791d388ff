// run/transport.prtt (docs/transport-format.md): rows of the transport matrix T, one per spatial
// sample in global sample order, in fixed-size blocks of rows with one XXH64 checksum per block.
// Written in place by the farm while it samples (TransportFileWriter), read back block by block
// (TransportFileReader). Little-endian; this code requires a little-endian host.
// Readers are safe on untrusted input: every size is checked against the file before use.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

// ---------------------------------------------------------------------------------------------
// Blocked transport file (docs/transport-format.md).

// Version 1: the rows as plain float32 (the farm's working file, transport.prtt.partial).
// Version 2: packed, every block one zstd frame of the same bytes (docs/transport-format.md,
// "Packed"): what a finished run keeps as transport.prtt, ~4× smaller. Readers take both.
inline constexpr uint32_t kTransportFileVersion = 1;
inline constexpr uint32_t kPackedTransportFileVersion = 2;
inline constexpr std::size_t kTransportHeaderBytes = 96;
inline constexpr uint64_t kTransportDataAlignment = 4096;

struct TransportFileInfo {
  uint64_t rows = 0;       // spatial samples
  uint32_t cubemap_n = 0;  // columns = 6·n² cubemap texels (vocabulary/cubemap.h order)
  uint32_t rows_per_block = 256;
  uint32_t rays_per_texel = 0;  // provenance only
  uint64_t seed = 0;            // provenance only

  uint64_t cols() const { return 6ull * cubemap_n * cubemap_n; }
  uint64_t row_bytes() const { return cols() * sizeof(float); }
  uint64_t block_count() const {
    return rows_per_block == 0 ? 0 : (rows + rows_per_block - 1) / rows_per_block;
  }
  uint64_t FirstRowOfBlock(uint64_t block) const { return block * rows_per_block; }
  uint64_t RowsInBlock(uint64_t block) const;
  // Byte offset of the first float of row 0 (after header and checksum table, 4 KiB aligned).
  uint64_t data_offset() const;
  uint64_t file_bytes() const { return data_offset() + rows * row_bytes(); }
  bool operator==(const TransportFileInfo&) const = default;
};

// Writes a transport file in place, rows in any order (the farm's checkpointed writer). The file
// stays marked incomplete (readers refuse it) until Finalize() has computed and stored every
// block checksum. Not thread-safe. Throws FileIoError on any system failure.
class TransportFileWriter {
 public:
  // Creates or truncates `path`, sized for `info`, marked incomplete.
  static TransportFileWriter Create(const std::string& path, const TransportFileInfo& info);
  // Opens an existing file (complete or not) to write more rows; it is marked incomplete again.
  // Throws InputError when its header is damaged or does not describe `info`.
  static TransportFileWriter Reopen(const std::string& path, const TransportFileInfo& info);
  // Opens a file another process is writing (the farm's ranks writing their own rows into the one
  // working file) to write and read rows only: it must be incomplete and describe `info`, and
  // its header is never written. Finalize() must not be called on it. Throws InputError
  // otherwise (naming the file), FileIoError when it cannot be opened.
  static TransportFileWriter OpenRows(const std::string& path, const TransportFileInfo& info);

  TransportFileWriter(TransportFileWriter&& other) noexcept;
  TransportFileWriter& operator=(TransportFileWriter&& other) noexcept;
  TransportFileWriter(const TransportFileWriter&) = delete;
  TransportFileWriter& operator=(const TransportFileWriter&) = delete;
  ~TransportFileWriter();

  const TransportFileInfo& info() const { return info_; }
  const std::string& path() const { return path_; }

  // Rows [first_row, first_row + count), count·cols floats, row-major.
  void WriteRows(uint64_t first_row, uint64_t count, const float* rows);
  void ReadRows(uint64_t first_row, uint64_t count, float* rows) const;
  // Makes every written row durable (fdatasync).
  void Sync();
  // Reads every block back, stores its XXH64, marks the file complete and syncs it.
  void Finalize();

 private:
  TransportFileWriter(std::string path, TransportFileInfo info, int fd);
  static TransportFileWriter OpenExisting(const std::string& path, const TransportFileInfo& info,
                                          bool& complete);
  void WriteHeader(bool complete, std::span<const uint64_t> checksums);

  std::string path_;
  TransportFileInfo info_;
  int fd_ = -1;
};

// Writes the packed form (version 2) of a complete transport: blocks are handed in order, each
// already compressed by CompressTransportBlock (so that callers can compress in parallel), with
// the XXH64 of its uncompressed bytes. The file is written to `path` + ".tmp" and renamed into
// place, durably, by Finish(); until then `path` is untouched. Throws FileIoError.
class PackedTransportWriter {
 public:
  PackedTransportWriter(std::string path, const TransportFileInfo& info);
  ~PackedTransportWriter();
  PackedTransportWriter(const PackedTransportWriter&) = delete;
  PackedTransportWriter& operator=(const PackedTransportWriter&) = delete;

  // Block `block` (blocks must come in order 0, 1, …): its zstd frame and its rows' XXH64.
  void Append(uint64_t block, std::string_view frame, uint64_t checksum);
  // Block `block` (in order, as Append) whose frame of `frame_bytes` another process wrote into
  // temp_path() at next_offset() (the farm's ranks packing their own blocks).
  void Place(uint64_t block, uint64_t frame_bytes, uint64_t checksum);
  uint64_t next_offset() const { return offsets_.back(); }
  const std::string& temp_path() const { return tmp_; }
  int fd() const { return fd_; }  // temp_path()'s descriptor (frames written by Place's caller)
  // Where block 0's frame starts in a packed file of `info`.
  static uint64_t FirstFrameOffset(const TransportFileInfo& info);
  // Writes the tables and the header, fsyncs, renames into place. Returns the file's size.
  uint64_t Finish();

 private:
  std::string path_, tmp_;
  TransportFileInfo info_;
  std::vector<uint64_t> checksums_, offsets_;
  int fd_ = -1;
};

// One block of rows (floats) as a zstd frame at `level`. The default, zstd's fast level −1,
// packs the default scene's rows 3.96× at ~2.3 GB/s per core (level 1: 4.38× at ~1.0 GB/s;
// measured with `zstd -b`, docs/transport-format.md "Packed").
std::string CompressTransportBlock(const float* rows, std::size_t floats, int level = -1);

// Reads a complete transport file, plain (version 1) or packed (version 2). Construction
// validates magic, version, sizes and the header checksum (InputError naming the file and the
// problem); reads verify block checksums. Safe on hostile input: a packed block is decompressed
// only into the exact size its rows need, and a frame that declares any other size is rejected.
class TransportFileReader {
 public:
  explicit TransportFileReader(const std::string& path);
  TransportFileReader(TransportFileReader&& other) noexcept;
  TransportFileReader& operator=(TransportFileReader&& other) noexcept;
  TransportFileReader(const TransportFileReader&) = delete;
  TransportFileReader& operator=(const TransportFileReader&) = delete;
  ~TransportFileReader();

  const TransportFileInfo& info() const { return info_; }
  uint64_t BlockChecksum(uint64_t block) const { return checksums_.at(block); }
  bool packed() const { return !offsets_.empty(); }
  // The block's bytes in the file (compressed for a packed file).
  uint64_t StoredBlockBytes(uint64_t block) const;

  // Block `block` (RowsInBlock(block)·cols floats) into out; throws InputError naming the block
  // when its checksum does not match.
  void ReadBlock(uint64_t block, std::span<float> out) const;
  std::vector<float> ReadBlock(uint64_t block) const;
  // Rows [first_row, first_row + count) into out (count·cols floats); every block touched is
  // read whole and verified.
  void ReadRows(uint64_t first_row, uint64_t count, float* out) const;
  // Verifies every block; returns the first bad block's index, or -1 when all match.
  int64_t FindCorruptBlock() const;

 private:
  std::string path_;
  TransportFileInfo info_;
  std::vector<uint64_t> checksums_;
  std::vector<uint64_t> offsets_;  // packed: block b's frame is [offsets_[b], offsets_[b + 1])
  int fd_ = -1;
};

}  // namespace prt
