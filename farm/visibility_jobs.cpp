// The farm's visibility jobs (see visibility_jobs.h).
#include "farm/visibility_jobs.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr char kResultMagic[8] = {'P', 'R', 'T', 'V', 'J', 'O', 'B', '1'};
constexpr std::size_t kResultHeader = 8 + 8 * 7;  // magic, 6 u64 fields + busy seconds

void PutU64(std::vector<uint8_t>& out, uint64_t v) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));
}
uint64_t GetU64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t(p[i]) << (8 * i);
  return v;
}

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
  std::vector<uint8_t> out(kResultMagic, kResultMagic + 8);
  out.reserve(kResultHeader + r.chunk.size());
  PutU64(out, r.first);
  PutU64(out, r.count);
  PutU64(out, r.rays_traced);
  PutU64(out, r.texels_below_horizon);
  uint64_t busy = 0;
  std::memcpy(&busy, &r.busy_seconds, 8);
  PutU64(out, busy);
  PutU64(out, r.chunk.size());
  PutU64(out, Checksum64(r.chunk.data(), r.chunk.size()));
  out.insert(out.end(), r.chunk.begin(), r.chunk.end());
  return out;
}

VisibilityJobResult DecodeVisibilityJobResult(std::span<const uint8_t> bytes) {
  if (bytes.size() < kResultHeader || std::memcmp(bytes.data(), kResultMagic, 8) != 0) {
    throw std::runtime_error("not a visibility job result (" + std::to_string(bytes.size()) +
                             " bytes)");
  }
  const uint8_t* p = bytes.data() + 8;
  VisibilityJobResult r;
  r.first = GetU64(p);
  r.count = GetU64(p + 8);
  r.rays_traced = GetU64(p + 16);
  r.texels_below_horizon = GetU64(p + 24);
  const uint64_t busy = GetU64(p + 32);
  std::memcpy(&r.busy_seconds, &busy, 8);
  const uint64_t length = GetU64(p + 40);
  const uint64_t sum = GetU64(p + 48);
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
