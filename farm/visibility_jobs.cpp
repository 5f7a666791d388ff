// The farm's visibility jobs (see visibility_jobs.h).
#include "farm/visibility_jobs.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr char kResultMagic[8] = {'P', 'R', 'T', 'V', 'J', 'O', 'B', '1'};
constexpr std::size_t kResultHeader = 8 + 8 * 7;  // magic, 6 u64 fields + busy seconds

}  // namespace

VisibilityJobResult ComputeVisibilityJob(const VisibilitySampler& sampler,
                                         std::span<const SpatialSample> samples, uint64_t first,
                                         uint64_t count) {
  if (first > samples.size() || count > samples.size() - first) {
    throw std::out_of_range("visibility job " + std::to_string(first) + "+" +
                            std::to_string(count) + " outside the " +
                            std::to_string(samples.size()) + " samples");
  }
  const auto t0 = std::chrono::steady_clock::now();
  VisibilitySamplerStats stats;
  const VisibilityBlocks blocks = sampler.ComputeBlocks(samples.subspan(first, count), &stats);
  VisibilityJobResult r;
  r.first = first;
  r.count = count;
  r.rays_traced = stats.rays_traced;
  r.texels_below_horizon = stats.texels_below_horizon;
  r.chunk = EncodeVisibilityBlocks(blocks);
  r.busy_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

std::vector<uint8_t> EncodeVisibilityJobResult(const VisibilityJobResult& r) {
  ByteVectorWriter w(std::vector<uint8_t>(kResultMagic, kResultMagic + 8));
  w.Reserve(kResultHeader + r.chunk.size());
  w.Put<uint64_t>(r.first);
  w.Put<uint64_t>(r.count);
  w.Put<uint64_t>(r.rays_traced);
  w.Put<uint64_t>(r.texels_below_horizon);
  w.Put<double>(r.busy_seconds);
  w.Put<uint64_t>(r.chunk.size());
  w.Put<uint64_t>(Checksum64(r.chunk.data(), r.chunk.size()));
  w.PutBytes(r.chunk.data(), r.chunk.size());
  return std::move(w.bytes());
}

VisibilityJobResult DecodeVisibilityJobResult(std::span<const uint8_t> bytes) {
  if (bytes.size() < kResultHeader || std::memcmp(bytes.data(), kResultMagic, 8) != 0) {
    throw std::runtime_error("not a visibility job result (" + std::to_string(bytes.size()) +
                             " bytes)");
  }
  VisibilityJobResult r;
  r.first = LoadAt<uint64_t>(bytes, 8);
  r.count = LoadAt<uint64_t>(bytes, 16);
  r.rays_traced = LoadAt<uint64_t>(bytes, 24);
  r.texels_below_horizon = LoadAt<uint64_t>(bytes, 32);
  r.busy_seconds = LoadAt<double>(bytes, 40);
  const uint64_t length = LoadAt<uint64_t>(bytes, 48);
  const uint64_t sum = LoadAt<uint64_t>(bytes, 56);
  if (length != bytes.size() - kResultHeader) {
    throw std::runtime_error("visibility job result of " + std::to_string(bytes.size()) +
                             " bytes declares a chunk of " + std::to_string(length));
  }
  r.chunk.assign(bytes.begin() + kResultHeader, bytes.end());
  if (Checksum64(r.chunk.data(), r.chunk.size()) != sum) {
    throw std::runtime_error("visibility job result arrived damaged (checksum mismatch)");
  }
  if (!std::isfinite(r.busy_seconds) || r.busy_seconds < 0) r.busy_seconds = 0;
  return r;
}

JournalEntry VisibilityJournalEntry(const VisibilityJobResult& r, int rank, uint64_t offset,
                                    uint64_t checksum) {
  JournalEntry e;
  e.phase = kVisibilityPhaseName;
  e.rows = {r.first, r.count};
  e.rows_checksum = checksum;
  e.rank = rank;
  e.busy_seconds = r.busy_seconds;
  e.rays_traced = r.rays_traced;
  e.texels_below_horizon = r.texels_below_horizon;
  e.counters = {offset, r.chunk.size(), r.rays_traced, r.texels_below_horizon};
  return e;
}

bool ChunkOfJournalEntry(const JournalEntry& e, VisibilityChunkRef& ref) {
  if (e.phase != kVisibilityPhaseName || e.counters.size() != 4) return false;
  ref.first = e.rows.first;
  ref.count = e.rows.count;
  ref.checksum = e.rows_checksum;
  ref.offset = e.counters[0];
  ref.length = e.counters[1];
  ref.rays_traced = e.counters[2];
  ref.texels_below_horizon = e.counters[3];
  return true;
}

std::vector<uint8_t> AssembleVisibilityChunks(std::vector<VisibilityChunk> chunks, uint64_t samples,
                                              int n, int bits, const std::string& source,
                                              VisibilityBlockCounts* counts) {
  std::sort(chunks.begin(), chunks.end(),
            [](const VisibilityChunk& a, const VisibilityChunk& b) { return a.first < b.first; });
  VisibilityBlocks all = MakeVisibilityBlocks(n, bits);
  uint64_t next = 0;
  for (const VisibilityChunk& c : chunks) {
    const std::string where =
        source + " (samples " + std::to_string(c.first) + "+" + std::to_string(c.count) + ")";
    if (c.first != next) {
      throw InputError(source, c.first > next
                                   ? "samples " + std::to_string(next) + ".." +
                                         std::to_string(c.first - 1) + " are missing"
                                   : "chunks overlap at sample " + std::to_string(c.first));
    }
    const VisibilityBlocks part = DecodeVisibilityBlocks(c.bytes, where);
    if (part.n != n || part.bits != bits || part.vertex_count != c.count) {
      throw InputError(where, "chunk holds " + std::to_string(part.vertex_count) + " maps at n = " +
                                  std::to_string(part.n) + ", bits = " + std::to_string(part.bits));
    }
    AppendVisibilityBlocks(all, part);
    next = c.first + c.count;
  }
  if (next != samples) {
    throw InputError(source, "samples " + std::to_string(next) + ".." +
                                 std::to_string(samples - 1) + " are missing");
  }
  if (counts) *counts = CountVisibilityBlocks(all);
  return EncodeVisibilityBlocks(all);
}

}  // namespace prt
