// See farm/sparse_step_lists.h.
#include "farm/sparse_step_lists.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <unordered_map>

#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/local_rank.h"

namespace prt {

namespace fs = std::filesystem;

std::vector<Vec3> DenseIndexPoints(const SparsePlan& plan, std::span<const SpatialSample> samples,
                                   std::span<const uint32_t> dense) {
  std::vector<Vec3> pts;
  pts.reserve(dense.size());
  for (uint32_t d : dense) pts.push_back(plan.SearchPosition(samples[d]));
  return pts;
}

uint64_t ListNeighbours(const NeighborIndex& index, std::span<const SpatialSample> samples,
                        const SparsePlan& plan, std::span<const uint32_t> items, uint64_t first,
                        uint64_t count, bool exclude_self, uint64_t max_union,
                        NeighbourLists& out) {
  std::unordered_map<uint32_t, uint32_t> local;
  std::vector<uint32_t> nbs;
  for (uint64_t i = first; i < first + count; ++i) {
    nbs = index.RadiusSearch(plan.SearchPosition(samples[items[i]]), plan.radius,
                             plan.max_neighbors + (exclude_self ? 1 : 0));
    if (exclude_self) {
      nbs.erase(std::remove(nbs.begin(), nbs.end(), items[i]), nbs.end());
      if (nbs.size() > static_cast<std::size_t>(plan.max_neighbors))
        nbs.resize(static_cast<std::size_t>(plan.max_neighbors));
    }
    std::size_t added = 0;
    for (uint32_t d : nbs) added += local.count(d) ? 0 : 1;
    if (max_union > 0 && i > first && out.union_ids.size() + added > max_union) return i - first;
    for (uint32_t d : nbs) {
      auto [at, is_new] = local.emplace(d, static_cast<uint32_t>(out.union_ids.size()));
      if (is_new) out.union_ids.push_back(d);
      out.neighbors.push_back(at->second);
    }
    out.offsets.push_back(static_cast<uint32_t>(out.neighbors.size()));
  }
  return count;
}

// The lists file's magic (its layout: sparse_step_lists.h).
constexpr char kListsMagic[8] = {'P', 'R', 'T', 'S', 'L', 'S', '1', '\0'};
std::string StepListsPath(const RunFolder& f, uint32_t step) {
  return (fs::path(f.sparse) / ("lists-" + std::to_string(step) + ".bin")).string();
}
void RemoveSparseScratch(const RunFolder& f) {
  std::error_code ec;
  std::vector<fs::path> scratch = {fs::path(f.sparse) / "dense_low.bin"};
  for (const auto& entry : fs::directory_iterator(f.sparse, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("lists-", 0) == 0 && entry.path().extension() == ".bin")
      scratch.push_back(entry.path());
  }
  for (const fs::path& p : scratch) fs::remove(p, ec);
}
void WriteStepLists(const std::string& path, std::span<const uint32_t> dense,
                    std::span<const uint32_t> items) {
  std::string b(kListsMagic, sizeof kListsMagic);
  const uint64_t counts[2] = {dense.size(), items.size()};
  b.append(reinterpret_cast<const char*>(counts), sizeof counts);
  b.append(reinterpret_cast<const char*>(dense.data()), dense.size_bytes());
  b.append(reinterpret_cast<const char*>(items.data()), items.size_bytes());
  const uint64_t sum = Checksum64(b.data(), b.size());
  b.append(reinterpret_cast<const char*>(&sum), sizeof sum);
  WriteFileDurably(path, b);
}
void ReadStepLists(const std::string& path, uint64_t samples, std::vector<uint32_t>& dense,
                   std::vector<uint32_t>& items) {
  const std::string b = ReadWholeFile(path);
  constexpr std::size_t kHead = sizeof kListsMagic + 2 * sizeof(uint64_t);
  uint64_t counts[2] = {0, 0}, sum = 0;
  if (b.size() < kHead + sizeof sum || std::memcmp(b.data(), kListsMagic, sizeof kListsMagic) != 0)
    throw InputError(path, "is not a sparse step's lists");
  std::memcpy(counts, b.data() + sizeof kListsMagic, sizeof counts);
  std::memcpy(&sum, b.data() + b.size() - sizeof sum, sizeof sum);
  if (Checksum64(b.data(), b.size() - sizeof sum) != sum || counts[0] > b.size() / 4 ||
      counts[1] > b.size() / 4 || b.size() != kHead + 4 * (counts[0] + counts[1]) + sizeof sum)
    throw InputError(path, "is damaged");
  dense.resize(counts[0]);
  items.resize(counts[1]);
  std::memcpy(dense.data(), b.data() + kHead, 4 * dense.size());
  std::memcpy(items.data(), b.data() + kHead + 4 * dense.size(), 4 * items.size());
  for (uint32_t id : dense)
    if (id >= samples) throw InputError(path, "names a sample beyond the run's");
  for (uint32_t id : items)
    if (id >= samples) throw InputError(path, "names a sample beyond the run's");
}

constexpr uint32_t kCompactJobMagic = 0x43535250u;
std::string EncodeCompactJob(const SparseJobHeader& h, bool exclude_self, const std::string& step,
                             std::string prefix) {
  ByteWriter w(std::move(prefix));
  w.Put(kCompactJobMagic);
  w.Put(h);
  w.Put(static_cast<uint32_t>(exclude_self ? 1 : 0));
  w.PutVector(std::vector<char>(step.begin(), step.end()));
  return std::move(w.bytes());
}

std::string CompactJobExpander::Expand(const FarmContext& ctx, std::string_view payload) {
  ByteReader r(payload, [](const char*, std::size_t) {
    throw std::runtime_error("truncated compact sparse job");
  });
  if (r.Get<uint32_t>("job") != kCompactJobMagic) throw std::runtime_error("not a compact job");
  const auto h = r.Get<SparseJobHeader>("job");
  const bool exclude_self = r.Get<uint32_t>("job") != 0;
  const std::vector<char> name = r.GetVector<char>("job");
  if (!index_ || h.phase != step_) {
    index_.reset();
    ReadStepLists(StepListsPath(ctx.folder, h.phase), ctx.samples.size(), dense_, items_);
    index_ =
        std::make_unique<NeighborIndex>(DenseIndexPoints(ctx.plan, ctx.samples, dense_), dense_);
    step_ = h.phase;
  }
  if (h.first + h.count > items_.size() || h.count == 0)
    throw std::runtime_error("a compact job beyond its step's items");
  NeighbourLists lists;
  ListNeighbours(*index_, ctx.samples, ctx.plan, items_, h.first, h.count, exclude_self, 0, lists);
  if (h.kind == static_cast<uint32_t>(SparseJobKind::kRank)) {
    const int m = SparseRankResolution(ctx.plan, ctx.params.cubemap_n);
    RankJob job;
    job.low_dim = static_cast<uint32_t>(6 * m * m);
    job.offsets = std::move(lists.offsets);
    job.neighbors = std::move(lists.neighbors);
    job.in_place = kReadRowsInPlace;
    job.union_ids = std::move(lists.union_ids);
    return EncodeRankJob(h, job);
  }
  SparseJob job;
  job.texels = static_cast<uint32_t>(6 * ctx.params.cubemap_n * ctx.params.cubemap_n);
  job.vertices.assign(items_.begin() + static_cast<std::ptrdiff_t>(h.first),
                      items_.begin() + static_cast<std::ptrdiff_t>(h.first + h.count));
  job.offsets = std::move(lists.offsets);
  job.neighbors = std::move(lists.neighbors);
  job.union_ids = std::move(lists.union_ids);
  job.in_place = kReadRowsInPlace | (exclude_self ? kCrossValidateInPlace : kWriteRowsInPlace);
  job.step.assign(name.begin(), name.end());
  return EncodeSparseJob(h, job);
}

bool CompactJobExpander::IsCompact(std::string_view payload) {
  uint32_t magic = 0;
  if (payload.size() >= sizeof magic) std::memcpy(&magic, payload.data(), sizeof magic);
  return magic == kCompactJobMagic;
}

}  // namespace prt
