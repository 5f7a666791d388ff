// The sparse method (Huang & Ramamoorthi 2010 §4–5) on the job loop; docs/farm.md, "Sparse
// method". Its order of steps is the worker's one driver, RunSparseSchedule
// (worker/sparse_precomputation.h), the same the in-process RunSparsePrecomputation runs: here each
// step is a batch of jobs (farm/sparse_jobs.h) on the JobLoop. Rank 0 plans every step
// deterministically from the seed and the previous steps' durable results, so the transport file
// is bit-identical to the in-process one for any number of ranks and after any resume:
//   dense-initial       InitialDenseSet                        jobs: chunks of sample ids
//   rank-k              candidates of round k (NeighborIndex over the dense positions)
//                                                              jobs: chunks of candidates
//   dense-rank-k        SparsePickByRank, on rank 0 only       jobs: chunks of sample ids
//   sparse-reconstruct  non-dense samples in Morton order      jobs: chunks of that order
//   dense-fallback      the vertices whose reconstruction fell back
// Dense T rows and reconstructed rows go into transport.prtt.partial; dense visibility and
// feature rows into run/sparse/dense_aux.bin (5·texels bytes per sample, at the sample's offset:
// a sparse file) — written by the worker that computed them where every rank sees the run folder
// (FarmSparseRowFiles, with the downsampled rows in dense_low.bin and each step's lists in
// lists-<step>.bin; docs/farm.md, "Where the rows go"), else by rank 0 as they arrive. Candidate
// weights go into run/sparse/rank-k.bin (int32 per candidate), sparse outcomes into
// run/sparse/sparse_outcome.bin (a byte per Morton position), by rank 0. Every job is journaled
// after its results are durable ("sjob <step> …").
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/side_file.h"
#include "farm/sparse_jobs.h"
#include "formats/transport_variance.h"
#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/local_rank.h"
#include "worker/neighbor_index.h"
#include "worker/sparse_precomputation.h"

namespace prt {

namespace {

namespace fs = std::filesystem;

// A job's rows (the dense neighbours it is sent, or the rows it returns) fit in 24 MiB: glibc
// serves blocks above its mmap threshold (at most 32 MiB) with fresh pages on every allocation,
// so jobs of ~100 MiB paid a page fault per 4 KiB of every copy of every job (encode, MPI,
// decode, result) — 14 % of a 2-rank run's samples (docs/farm.md). Below it the buffers are
// reused from the heap.
constexpr uint64_t kMaxSparseJobBytes = uint64_t{24} << 20;
// Jobs a rank holds at once: the one it computes and the next, encoded and sent while it
// computes, so that it never waits for rank 0 to read its neighbours' rows (a 2-rank run's
// sparse-reconstruct workers were idle 45 % of the time; docs/farm.md).
constexpr std::size_t kJobsAhead = 2;
// Results become durable every 0.5 s and when no job is out: an fdatasync per result cost 2 s of
// a 27 s 2-rank run.
constexpr double kCommitIntervalSeconds = 0.5;

// The points a step's NeighborIndex is built over: the dense samples' positions in the dense
// list's order (rank 0 and, with rows in place, every worker build the same index from them).
std::vector<Vec3> DenseIndexPoints(std::span<const SpatialSample> samples,
                                   std::span<const uint32_t> dense) {
  std::vector<Vec3> pts;
  pts.reserve(dense.size());
  for (uint32_t d : dense) pts.push_back(samples[d].position);
  return pts;
}

// Huang & Ramamoorthi 2010 §4.1 (a candidate's local rank over its dense neighbours) and §5.3
// (a sparse vertex's reconstruction from "dense vertices within some spatial radius", capped at
// k): the neighbour lists of items [first, first + count) of `items` (sample ids): each item's
// dense neighbours within the plan's radius, nearest first, at most max_neighbors (`exclude_self`:
// the item, dense itself, left out — cross-validation), as indices into the union of their sample
// ids in first-seen order. `max_union` > 0: the items stop before the union would exceed it (at
// least one item). Returns the items taken. Rank 0 and, with rows in place, the worker build the
// same lists from the same index (an exact search on one FLANN k-d tree over the same points in
// the same order).
struct NeighbourLists {
  std::vector<uint32_t> offsets{0}, neighbors, union_ids;
};
uint64_t ListNeighbours(const NeighborIndex& index, std::span<const SpatialSample> samples,
                        const SparsePlan& plan, std::span<const uint32_t> items, uint64_t first,
                        uint64_t count, bool exclude_self, uint64_t max_union,
                        NeighbourLists& out) {
  std::unordered_map<uint32_t, uint32_t> local;
  std::vector<uint32_t> nbs;
  for (uint64_t i = first; i < first + count; ++i) {
    nbs = index.RadiusSearch(samples[items[i]].position, plan.radius,
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

// A step's lists with rows in place (run/sparse/lists-<step number>.bin, written durably by rank 0
// before the step's first job): the dense samples its index is built over, in order, and its
// items (candidates, sparse vertices in Morton order, or the cross-validated vertices). The
// magic "PRTSLS1\0", uint64 dense count, uint64 item count, the uint32 ids, then the XXH64 of
// everything before it.
constexpr char kListsMagic[8] = {'P', 'R', 'T', 'S', 'L', 'S', '1', '\0'};
std::string StepListsPath(const RunFolder& f, uint32_t step) {
  return (fs::path(f.sparse) / ("lists-" + std::to_string(step) + ".bin")).string();
}
// The rows-in-place scratch of the steps (dense_low.bin, lists-<step>.bin): read only while the
// steps run, and written again by a resume. Removed once the steps are done, so that the run
// folder holds the same files for any number of ranks (docs/farm.md, "Determinism").
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

// A job without its neighbour lists (rows in place): the worker builds them from its step's
// lists file. [magic "PRSC"][SparseJobHeader][uint32 exclude_self][step name].
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

// A worker's side of compact jobs: the full job (neighbour lists, union ids, in-place flags) from
// the step's lists file and an index over its dense samples, both loaded once per step.
class CompactJobExpander {
 public:
  // `payload` is a compact job (IsCompact) of the run in `ctx`.
  std::string Expand(const FarmContext& ctx, std::string_view payload) {
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
      index_ = std::make_unique<NeighborIndex>(DenseIndexPoints(ctx.samples, dense_), dense_);
      step_ = h.phase;
    }
    if (h.first + h.count > items_.size() || h.count == 0)
      throw std::runtime_error("a compact job beyond its step's items");
    NeighbourLists lists;
    ListNeighbours(*index_, ctx.samples, ctx.plan, items_, h.first, h.count, exclude_self, 0,
                   lists);
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
  static bool IsCompact(std::string_view payload) {
    uint32_t magic = 0;
    if (payload.size() >= sizeof magic) std::memcpy(&magic, payload.data(), sizeof magic);
    return magic == kCompactJobMagic;
  }

 private:
  uint32_t step_ = 0;
  std::vector<uint32_t> dense_, items_;
  std::unique_ptr<NeighborIndex> index_;
};

// A cross-validation job's records (run/sparse/cross_validation.bin, see CrossValidate): per
// vertex the outcome byte, 3 zero bytes, then reconstruction − traced row as float32 (zeros where
// the reconstruction fell back). `rows`: the reconstructed rows in order; traced(i, out) reads
// vertex i's traced row.
std::vector<char> CrossValidationRecords(std::size_t T, std::span<const uint8_t> outcomes,
                                         const float* rows,
                                         const std::function<void(std::size_t, float*)>& traced) {
  const uint8_t ok = static_cast<uint8_t>(SparseOutcome::kReconstructed);
  const std::size_t record = 4 + 4 * T;
  std::vector<char> bytes(outcomes.size() * record, 0);
  std::vector<float> row(T);
  std::size_t k = 0;
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    char* rec = bytes.data() + i * record;
    rec[0] = static_cast<char>(outcomes[i]);
    if (outcomes[i] != ok) continue;
    traced(i, row.data());
    float* diff = reinterpret_cast<float*>(rec + 4);
    for (std::size_t j = 0; j < T; ++j) diff[j] = rows[k * T + j] - row[j];
    ++k;
  }
  return bytes;
}

// The run's files as a worker's SparseRowFiles (docs/farm.md, "Where the rows go"): T rows in
// transport.prtt.partial, visibility and feature rows in sparse/dense_aux.bin, downsampled rows in
// sparse/dense_low.bin (6·m·m floats per sample at the sample's offset), variance records in the
// rank's own log. Opened by each computing rank at its first job.
class FarmSparseRowFiles final : public SparseRowFiles {
 public:
  explicit FarmSparseRowFiles(FarmContext& ctx)
      : T_(6ull * ctx.params.cubemap_n * ctx.params.cubemap_n),
        m_(SparseRankResolution(ctx.plan, ctx.params.cubemap_n)),
        rows_(TransportFileWriter::OpenRows(ctx.folder.partial, ctx.RowsFileInfo())),
        aux_((fs::path(ctx.folder.sparse) / "dense_aux.bin").string()),
        low_((fs::path(ctx.folder.sparse) / "dense_low.bin").string()),
        cross_path_((fs::path(ctx.folder.sparse) / "cross_validation.bin").string()) {
    if (!ctx.rank_variance) {
      ctx.rank_variance =
          std::make_unique<RankVarianceLog>(ctx.folder, ctx.rank, ctx.EmptyVarianceSums());
    }
    variance_ = ctx.rank_variance.get();
  }
  void ReadDense(uint32_t s, float* transport, float* visibility, uint8_t* feature) override {
    rows_.ReadRows(s, 1, transport);
    std::vector<char> buf(5 * T_);
    if (!aux_.Read(buf.data(), buf.size(), s * 5 * T_))
      throw FileIoError(aux_.path(), "lacks dense sample " + std::to_string(s));
    std::memcpy(visibility, buf.data(), T_ * sizeof(float));
    std::memcpy(feature, buf.data() + T_ * sizeof(float), T_);
  }
  void ReadLow(uint32_t s, float* low) override {
    const std::size_t bytes = LowFloats() * sizeof(float);
    if (!low_.Read(low, bytes, s * bytes))
      throw FileIoError(low_.path(), "lacks dense sample " + std::to_string(s));
  }
  void WriteDense(uint32_t s, const float* transport, const float* visibility,
                  const uint8_t* feature, const float* low) override {
    std::vector<char> buf(5 * T_);
    std::memcpy(buf.data(), visibility, T_ * sizeof(float));
    std::memcpy(buf.data() + T_ * sizeof(float), feature, T_);
    const std::size_t low_bytes = LowFloats() * sizeof(float);
    std::lock_guard lock(mutex_);
    rows_.WriteRows(s, 1, transport);
    aux_.Write(buf.data(), buf.size(), s * 5 * T_);
    low_.Write(low, low_bytes, s * low_bytes);
  }
  void WriteRow(uint32_t s, const float* transport) override {
    std::lock_guard lock(mutex_);
    rows_.WriteRows(s, 1, transport);
  }
  void RecordVariance(const std::string& step, uint64_t first, uint64_t count,
                      const std::string& encoded) override {
    const TransportVariance sums = DecodeTransportVariance(encoded, "a job's variance sums");
    std::lock_guard lock(mutex_);
    variance_->Record(step, first, count, sums);
  }
  uint64_t WriteCrossValidation(uint64_t first, std::span<const uint32_t> vertices,
                                std::span<const uint8_t> outcomes, const float* rows) override {
    std::vector<char> bytes = CrossValidationRecords(
        T_, outcomes, rows,
        [&](std::size_t i, float* traced) { rows_.ReadRows(vertices[i], 1, traced); });
    std::lock_guard lock(mutex_);
    if (!cross_) cross_.emplace(cross_path_);
    cross_->Write(bytes.data(), bytes.size(), first * (4 + 4 * T_));
    return Checksum64(bytes.data(), bytes.size());
  }
  void Sync() override {
    std::lock_guard lock(mutex_);
    if (cross_) cross_->Sync();
    rows_.Sync();
    aux_.Sync();
    low_.Sync();
    variance_->Sync();
  }
  int low_resolution() const override { return m_; }

 private:
  std::size_t LowFloats() const { return static_cast<std::size_t>(6 * m_ * m_); }
  const std::size_t T_;
  const int m_;
  TransportFileWriter rows_;
  SideFile aux_, low_;
  std::string cross_path_;
  std::optional<SideFile> cross_;  // opened at the first cross-validation job
  RankVarianceLog* variance_ = nullptr;
  std::mutex mutex_;
};

// One step's jobs: what differs between the kinds.
struct StepJobs {
  std::string name;
  SparseJobKind kind = SparseJobKind::kDense;
  // Cross-validation: its jobs trace rays but write no row of T and no variance; the sparse
  // method's counters do not count them (report.json "sparse" "cross_validation" does).
  bool cross_validation = false;
  uint64_t items = 0;
  std::string unit = "samples";
  // Verifies a journaled job against the files and applies it to rank 0's state.
  std::function<bool(const JournalEntry&)> reuse;
  // Encodes the job for items h.first… after `prefix` (the envelope); may lower h.count (too
  // many bytes).
  std::function<std::string(SparseJobHeader&, std::string prefix)> make_job;
  // Writes a result into the files and rank 0's state; returns its durable checksum and the
  // number of transport rows it wrote.
  std::function<uint64_t(const SparseJobResult&, uint64_t& rows_written)> accept;
  std::function<void()> sync;  // makes what accept wrote durable
};

// Rank 0: the method's steps as batches of jobs.
class FarmSparseSteps final : public SparseSteps {
 public:
  FarmSparseSteps(FarmContext& ctx, JobLoop& loop)
      : ctx_(ctx),
        loop_(loop),
        N_(ctx.samples.size()),
        T_(6ull * ctx.params.cubemap_n * ctx.params.cubemap_n),
        n_(ctx.params.cubemap_n),
        m_(SparseRankResolution(ctx.plan, ctx.params.cubemap_n)),
        Tm_(static_cast<std::size_t>(6) * m_ * m_),
        low_(N_) {
    fs::create_directories(ctx.folder.sparse);
    aux_ = std::make_unique<SideFile>((fs::path(ctx.folder.sparse) / "dense_aux.bin").string());
    if (ctx.rows_in_place)
      low_file_ =
          std::make_unique<SideFile>((fs::path(ctx.folder.sparse) / "dense_low.bin").string());
  }

  // ---- dense rows (§4.2): T into the transport file, visibility + features into dense_aux.bin
  void Dense(const std::string& name, std::span<const uint32_t> ids) override {
    StepJobs p;
    p.name = name;
    p.kind = SparseJobKind::kDense;
    p.items = ids.size();
    const uint64_t aux_row = 5 * T_;
    // A dense row's downsampled row, for the rank steps: kept here, or (rows in place, where the
    // workers write it themselves) written into dense_low.bin for re-used jobs.
    auto apply = [&](uint32_t s, const float* row) {
      if (low_file_) {
        std::vector<float> low(Tm_);
        DownsampleRow(row, n_, m_, low.data());
        low_file_->Write(low.data(), Tm_ * sizeof(float), s * Tm_ * sizeof(float));
        return;
      }
      low_[s].resize(Tm_);
      DownsampleRow(row, n_, m_, low_[s].data());
    };
    p.reuse = [&, aux_row](const JournalEntry& e) {
      const std::size_t c = static_cast<std::size_t>(e.rows.count);
      std::vector<float> tr(c * T_), vis(c * T_);
      std::vector<uint8_t> feat(c * T_);
      std::vector<char> buf(aux_row);
      for (std::size_t i = 0; i < c; ++i) {
        const uint32_t s = ids[e.rows.first + i];
        ctx_.writer->ReadRows(s, 1, tr.data() + i * T_);
        if (!aux_->Read(buf.data(), aux_row, s * aux_row)) return false;
        std::memcpy(vis.data() + i * T_, buf.data(), T_ * sizeof(float));
        std::memcpy(feat.data() + i * T_, buf.data() + T_ * sizeof(float), T_);
      }
      if (DenseResultChecksum(c, T_, tr.data(), vis.data(), feat.data()) != e.rows_checksum)
        return false;
      for (std::size_t i = 0; i < c; ++i) apply(ids[e.rows.first + i], tr.data() + i * T_);
      return true;
    };
    p.make_job = [&](SparseJobHeader& h, std::string prefix) {
      DenseJob job;
      job.ids.assign(ids.begin() + static_cast<std::ptrdiff_t>(h.first),
                     ids.begin() + static_cast<std::ptrdiff_t>(h.first + h.count));
      job.in_place = ctx_.rows_in_place ? kWriteRowsInPlace : 0;
      job.step = name;
      return EncodeDenseJob(h, job, std::move(prefix));
    };
    p.accept = [&, aux_row](const SparseJobResult& r, uint64_t& rows_written) {
      const std::size_t c = static_cast<std::size_t>(r.header.count);
      if (r.in_place) {
        // The worker wrote T, aux and downsampled rows itself.
        if (!r.transport.empty() || !ctx_.rows_in_place)
          throw RankFailure("a dense job came back with rows it was to write itself");
        rows_written = c;
        return r.checksum;
      }
      if (r.transport.size() != c * T_ || r.visibility.size() != c * T_ ||
          r.feature.size() != c * T_)
        throw RankFailure("a dense job came back with the wrong number of rows");
      std::vector<char> buf(aux_row);
      for (std::size_t i = 0; i < c; ++i) {
        const uint32_t s = ids[r.header.first + i];
        ctx_.writer->WriteRows(s, 1, r.transport.data() + i * T_);
        std::memcpy(buf.data(), r.visibility.data() + i * T_, T_ * sizeof(float));
        std::memcpy(buf.data() + T_ * sizeof(float), r.feature.data() + i * T_, T_);
        aux_->Write(buf.data(), aux_row, s * aux_row);
        apply(s, r.transport.data() + i * T_);
      }
      rows_written = c;
      return DenseResultChecksum(c, T_, r.transport.data(), r.visibility.data(), r.feature.data());
    };
    p.sync = [&] {
      ctx_.writer->Sync();
      aux_->Sync();
      if (low_file_) low_file_->Sync();
    };
    RunStep(p);
  }

  // ---- local rank of candidates (§4.1)
  std::vector<double> Rank(const std::string& name, int, std::span<const uint32_t> dense,
                           std::span<const uint32_t> cand) override {
    const double t0 = FarmNow();
    // Built once per step over the dense positions, in the order the in-process run uses.
    const NeighborIndex index = IndexOf(dense);
    index_seconds_ += FarmNow() - t0;
    SideFile file((fs::path(ctx_.folder.sparse) / (name + ".bin")).string());
    std::vector<double> weight(cand.size(), 0.0);
    StepJobs p;
    p.name = name;
    p.kind = SparseJobKind::kRank;
    p.items = cand.size();
    p.unit = "candidates";
    p.reuse = [&](const JournalEntry& e) {
      std::vector<int32_t> w(static_cast<std::size_t>(e.rows.count));
      if (!file.Read(w.data(), w.size() * sizeof(int32_t), e.rows.first * sizeof(int32_t)) ||
          Checksum64(w.data(), w.size() * sizeof(int32_t)) != e.rows_checksum)
        return false;
      for (std::size_t i = 0; i < w.size(); ++i) weight[e.rows.first + i] = w[i];
      return true;
    };
    if (ctx_.rows_in_place) WriteStepLists(StepListsPath(ctx_.folder, step_number_), dense, cand);
    p.make_job = [&](SparseJobHeader& h, std::string prefix) {
      // Rows in place: the worker lists the neighbours itself and reads their downsampled rows.
      if (ctx_.rows_in_place) return EncodeCompactJob(h, false, name, std::move(prefix));
      RankJob job;
      job.low_dim = static_cast<uint32_t>(Tm_);
      std::unordered_map<uint32_t, uint32_t> local;
      job.offsets.push_back(0);
      // Rows in place: the worker reads the union's downsampled rows from dense_low.bin.
      job.in_place = ctx_.rows_in_place ? kReadRowsInPlace : 0;
      for (uint64_t i = h.first; i < h.first + h.count; ++i) {
        for (uint32_t d : index.RadiusSearch(ctx_.samples[cand[i]].position, ctx_.plan.radius,
                                             ctx_.plan.max_neighbors)) {
          auto [at, added] = local.emplace(d, static_cast<uint32_t>(local.size()));
          if (added && job.in_place) job.union_ids.push_back(d);
          if (added && !job.in_place)
            job.low_rows.insert(job.low_rows.end(), low_[d].begin(), low_[d].end());
          job.neighbors.push_back(at->second);
        }
        job.offsets.push_back(static_cast<uint32_t>(job.neighbors.size()));
      }
      return EncodeRankJob(h, job, std::move(prefix));
    };
    p.accept = [&](const SparseJobResult& r, uint64_t& rows_written) {
      if (r.weights.size() != r.header.count)
        throw RankFailure("a rank job came back with the wrong number of weights");
      file.Write(r.weights.data(), r.weights.size() * sizeof(int32_t),
                 r.header.first * sizeof(int32_t));
      for (std::size_t i = 0; i < r.weights.size(); ++i) weight[r.header.first + i] = r.weights[i];
      rows_written = 0;
      return Checksum64(r.weights.data(), r.weights.size() * sizeof(int32_t));
    };
    p.sync = [&] { file.Sync(); };
    RunStep(p, t0);
    return weight;
  }

  // ---- sparse vertices (§5); returns the fallbacks, sorted
  std::vector<uint32_t> Reconstruct(const std::string& name, std::span<const uint32_t> dense,
                                    std::span<const uint8_t> is_dense) override {
    const double t0 = FarmNow();
    const NeighborIndex index = IndexOf(dense);
    index_seconds_ += FarmNow() - t0;
    // Spatially coherent order: a job's vertices share most of their neighbours.
    std::vector<std::pair<uint32_t, uint32_t>> keyed;
    for (uint32_t s = 0; s < N_; ++s) {
      if (!is_dense[s]) {
        keyed.push_back({MortonKey(ctx_.samples[s].position, ctx_.geometry.bounds_min,
                                   ctx_.geometry.bounds_max),
                         s});
      }
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<uint32_t> order;
    for (const auto& k : keyed) order.push_back(k.second);
    std::vector<uint8_t> outcome(order.size(), 0xff);
    SideFile file((fs::path(ctx_.folder.sparse) / "sparse_outcome.bin").string());
    // Each sparse vertex's combination record, at its position in `order` (journal checks).
    SideFile comb_file((fs::path(ctx_.folder.sparse) / "combination_order.bin").string());
    const std::size_t slots = CombinationSlots(ctx_.plan);
    const std::size_t rec = slots * 2;  // uint32 per record
    combination_.assign(N_ * rec, 0);
    for (std::size_t i = 0; i < N_ * slots; ++i) combination_[2 * i] = kNoSample;
    auto keep_combination = [&](uint64_t first, uint64_t count, const uint32_t* records) {
      for (uint64_t i = 0; i < count; ++i)
        std::copy_n(records + i * rec, rec,
                    combination_.data() + static_cast<std::size_t>(order[first + i]) * rec);
    };
    const uint8_t ok = static_cast<uint8_t>(SparseOutcome::kReconstructed);

    if (ctx_.rows_in_place) WriteStepLists(StepListsPath(ctx_.folder, step_number_), dense, order);
    StepJobs p;
    p.name = name;
    p.kind = SparseJobKind::kSparse;
    p.items = order.size();
    p.reuse = [&](const JournalEntry& e) {
      std::vector<uint8_t> o(static_cast<std::size_t>(e.rows.count));
      if (!file.Read(o.data(), o.size(), e.rows.first)) return false;
      std::vector<float> rows;
      for (std::size_t i = 0; i < o.size(); ++i) {
        if (o[i] != ok) continue;
        rows.resize(rows.size() + T_);
        ctx_.writer->ReadRows(order[e.rows.first + i], 1, rows.data() + rows.size() - T_);
      }
      std::vector<uint32_t> comb(o.size() * rec);
      if (!comb_file.Read(comb.data(), comb.size() * sizeof(uint32_t),
                          e.rows.first * rec * sizeof(uint32_t)))
        return false;
      if (SparseResultChecksum(o, rows, comb) != e.rows_checksum) return false;
      std::copy(o.begin(), o.end(), outcome.begin() + static_cast<std::ptrdiff_t>(e.rows.first));
      keep_combination(e.rows.first, o.size(), comb.data());
      return true;
    };
    p.make_job = [&](SparseJobHeader& h, std::string prefix) {
      return MakeSparseJob(h, std::move(prefix), index, order, false, name);
    };
    p.accept = [&](const SparseJobResult& r, uint64_t& rows_written) {
      const std::size_t c = static_cast<std::size_t>(r.header.count);
      if (r.outcomes.size() != c) throw RankFailure("a sparse job came back incomplete");
      std::size_t k = 0;
      for (std::size_t i = 0; i < c; ++i) {
        if (r.outcomes[i] != ok) continue;
        if (r.in_place) {  // the worker wrote the row itself
          ++k;
          continue;
        }
        if ((k + 1) * T_ > r.transport.size())
          throw RankFailure("a sparse job came back with too few rows");
        ctx_.writer->WriteRows(order[r.header.first + i], 1, r.transport.data() + k * T_);
        ++k;
      }
      if (r.in_place ? !r.transport.empty() || !ctx_.rows_in_place : k * T_ != r.transport.size())
        throw RankFailure("a sparse job came back with too many rows");
      if (r.combination.size() != c * rec)
        throw RankFailure("a sparse job came back without its combinations");
      for (std::size_t i = 0; i < c * slots; ++i)
        if (r.combination[2 * i] != kNoSample && r.combination[2 * i] >= N_)
          throw RankFailure("a sparse job came back naming a missing sample");
      file.Write(r.outcomes.data(), c, r.header.first);
      comb_file.Write(r.combination.data(), r.combination.size() * sizeof(uint32_t),
                      r.header.first * rec * sizeof(uint32_t));
      std::copy(r.outcomes.begin(), r.outcomes.end(),
                outcome.begin() + static_cast<std::ptrdiff_t>(r.header.first));
      keep_combination(r.header.first, c, r.combination.data());
      rows_written = k;
      return r.in_place ? r.checksum : SparseResultChecksum(r.outcomes, r.transport, r.combination);
    };
    p.sync = [&] {
      ctx_.writer->Sync();
      file.Sync();
      comb_file.Sync();
    };
    RunStep(p, t0);
    CrossValidate(index, dense, order, outcome);
    ctx_.report.sparse.dense_rows_shipped = rows_shipped_;
    ctx_.report.sparse.index_seconds = index_seconds_;
    std::vector<uint32_t> fb;
    for (std::size_t i = 0; i < order.size(); ++i)
      if (outcome[i] != ok) fb.push_back(order[i]);
    std::sort(fb.begin(), fb.end());
    return fb;
  }

  // A sparse job for items h.first… of `order` (may lower h.count, see kMaxSparseJobBytes): each
  // vertex with its dense neighbours within the radius (nearest first) and the union of their
  // rows, read back from the run folder. `exclude_self`: the vertices are dense and their own
  // row is left out (cross-validation).
  std::string MakeSparseJob(SparseJobHeader& h, std::string prefix, const NeighborIndex& index,
                            std::span<const uint32_t> order, bool exclude_self,
                            const std::string& step) {
    // A job's rows stay within the job byte limit (at least one vertex per job).
    NeighbourLists lists;
    h.count = ListNeighbours(index, ctx_.samples, ctx_.plan, order, h.first, h.count, exclude_self,
                             kMaxSparseJobBytes / (9 * T_), lists);
    // Rows in place: the worker lists the neighbours itself (the same lists, from the step's
    // lists file), reads their rows from the run folder and writes its results there.
    if (ctx_.rows_in_place) return EncodeCompactJob(h, exclude_self, step, std::move(prefix));
    SparseJob job;
    job.texels = static_cast<uint32_t>(T_);
    job.step = step;
    job.vertices.assign(order.begin() + static_cast<std::ptrdiff_t>(h.first),
                        order.begin() + static_cast<std::ptrdiff_t>(h.first + h.count));
    job.offsets = std::move(lists.offsets);
    job.neighbors = std::move(lists.neighbors);
    std::vector<uint32_t> union_ids = std::move(lists.union_ids);
    // The dense neighbours' rows, read back from the run folder.
    const std::size_t u = union_ids.size();
    job.transport.resize(u * T_);
    job.visibility.resize(u * T_);
    job.feature.resize(u * T_);
    std::vector<char> buf(5 * T_);
    for (std::size_t k = 0; k < u; ++k) {
      const uint32_t d = union_ids[k];
      ctx_.writer->ReadRows(d, 1, job.transport.data() + k * T_);
      if (!aux_->Read(buf.data(), buf.size(), d * 5 * T_))
        throw FileIoError(ctx_.folder.sparse,
                          "dense_aux.bin lacks dense sample " + std::to_string(d));
      std::memcpy(job.visibility.data() + k * T_, buf.data(), T_ * sizeof(float));
      std::memcpy(job.feature.data() + k * T_, buf.data() + T_ * sizeof(float), T_);
    }
    rows_shipped_ += u;
    job.union_ids = std::move(union_ids);
    return EncodeSparseJob(h, job, std::move(prefix));
  }
  // The reconstruction's own error, by cross-validation (docs/farm.md, "Accuracy estimates"):
  // up to kCrossValidated vertices of the initial dense set (a uniform random sample of the
  // scene, InitialDenseSet) are reconstructed from the other dense vertices exactly as a sparse
  // vertex is, and their reconstruction minus their traced dense row is kept in
  // run/sparse/cross_validation.bin (a record per vertex: the outcome byte, 3 zero bytes, then
  // the texels' differences as float32; 0 where the reconstruction fell back, as the pipeline
  // then traces the vertex). run/sparse/cross_validation.json lists the vertices and, per mesh,
  // how many vertices were reconstructed. Nothing here changes a row of T.
  void CrossValidate(const NeighborIndex& index, std::span<const uint32_t> dense,
                     std::span<const uint32_t> order, std::span<const uint8_t> outcome) {
    const uint8_t ok = static_cast<uint8_t>(SparseOutcome::kReconstructed);
    const std::vector<uint32_t> initial =
        InitialDenseSet(N_, SparseInitialDenseCount(N_, ctx_.plan), ctx_.plan.seed);
    std::vector<uint32_t> cv;
    const std::size_t K = std::min<std::size_t>(kSparseCrossValidated, initial.size());
    for (std::size_t i = 0; i < K; ++i) cv.push_back(initial[i * initial.size() / K]);
    const std::size_t record = 4 + 4 * T_;
    SideFile file((fs::path(ctx_.folder.sparse) / "cross_validation.bin").string());
    if (ctx_.rows_in_place) WriteStepLists(StepListsPath(ctx_.folder, step_number_), dense, cv);
    StepJobs p;
    p.name = "cross-validate";
    p.kind = SparseJobKind::kSparse;
    p.items = cv.size();
    p.cross_validation = true;
    p.reuse = [&](const JournalEntry& e) {
      std::vector<char> bytes(static_cast<std::size_t>(e.rows.count) * record);
      return file.Read(bytes.data(), bytes.size(), e.rows.first * record) &&
             Checksum64(bytes.data(), bytes.size()) == e.rows_checksum;
    };
    p.make_job = [&](SparseJobHeader& h, std::string prefix) {
      return MakeSparseJob(h, std::move(prefix), index, cv, true, "cross-validate");
    };
    p.accept = [&](const SparseJobResult& r, uint64_t& rows_written) {
      const std::size_t c = static_cast<std::size_t>(r.header.count);
      if (r.outcomes.size() != c) throw RankFailure("a cross-validation job came back incomplete");
      rows_written = 0;
      if (r.in_place) {  // the worker wrote the records itself
        if (!r.transport.empty() || !ctx_.rows_in_place)
          throw RankFailure("a cross-validation job came back with rows it was to write itself");
        return r.checksum;
      }
      const std::size_t k =
          static_cast<std::size_t>(std::count(r.outcomes.begin(), r.outcomes.end(), ok));
      if (k * T_ != r.transport.size())
        throw RankFailure("a cross-validation job came back with the wrong number of rows");
      const std::vector<char> bytes = CrossValidationRecords(
          T_, r.outcomes, r.transport.data(), [&](std::size_t i, float* traced) {
            ctx_.writer->ReadRows(cv[r.header.first + i], 1, traced);
          });
      file.Write(bytes.data(), bytes.size(), r.header.first * record);
      return Checksum64(bytes.data(), bytes.size());
    };
    p.sync = [&] { file.Sync(); };
    RunStep(p);
    // Which vertices, and how many vertices of each mesh the pipeline reconstructed.
    std::vector<uint64_t> reconstructed(ctx_.RowGroups().size(), 0);
    for (std::size_t i = 0; i < order.size(); ++i)
      if (outcome[i] == ok) ++reconstructed[ctx_.GroupOfRow(order[i])];
    const nlohmann::json summary = {{"texels", T_},
                                    {"record_bytes", record},
                                    {"vertices", cv},
                                    {"reconstructed_per_mesh", reconstructed}};
    WriteFileDurably((fs::path(ctx_.folder.sparse) / "cross_validation.json").string(),
                     summary.dump() + "\n");
  }

 private:
  NeighborIndex IndexOf(std::span<const uint32_t> dense) const {
    return NeighborIndex(DenseIndexPoints(ctx_.samples, dense), dense);
  }

  void Count(const SparseJobCounters& c, bool this_run, bool cross_validation) {
    FarmReport& rep = ctx_.report;
    if (cross_validation) {  // its rays are not T's: report.json "sparse" "cross_validation"
      rep.sparse.cross_validation += c;
      return;
    }
    rep.sparse.counters += c;
    rep.rays_traced_all += c.rays_traced;
    rep.texels_below_horizon_all += c.texels_below_horizon;
    if (this_run) {
      rep.rays_traced += c.rays_traced;
      rep.texels_traced += c.texels_traced;
      rep.texels_below_horizon += c.texels_below_horizon;
      rep.rays_below_horizon += c.rays_below_horizon;
    }
  }

  // One step as a batch on the job loop; its journaled jobs that still verify are not redone.
  void RunStep(StepJobs& p, double t0 = -1) {
    if (t0 < 0) t0 = FarmNow();
    FarmReport& rep = ctx_.report;
    JobBatch batch;
    uint64_t reused_jobs = 0;
    for (const JournalEntry& e : ctx_.journal_entries) {
      if (e.phase != p.name || e.rows.end() > p.items) continue;
      const bool overlaps = std::any_of(
          batch.done.begin(), batch.done.end(),
          [&](const RowRange& d) { return e.rows.first < d.end() && d.first < e.rows.end(); });
      if (overlaps) continue;
      if (!p.reuse(e)) {
        ++rep.checkpoints_rejected;
        continue;
      }
      if (p.kind != SparseJobKind::kRank && !p.cross_validation &&
          !ctx_.variance->Reuse(p.name, e.rows.first, e.rows.count))
        ++variance_uncovered_jobs_;
      batch.done.push_back(e.rows);
      ++reused_jobs;
      ++rep.jobs_reused;
      if (p.kind != SparseJobKind::kRank && !p.cross_validation) {
        rep.rows_reused += p.kind == SparseJobKind::kDense
                               ? e.rows.count
                               : SparseJobCounters::FromVector(e.counters).reconstructed;
      }
      Count(SparseJobCounters::FromVector(e.counters), false, p.cross_validation);
    }
    if (reused_jobs > 0)
      spdlog::info("[{}] {} job(s) re-used from checkpoints", p.name, reused_jobs);

    batch.name = p.name;
    batch.items = p.items;
    batch.unit = p.unit;
    batch.rate_unit = p.kind == SparseJobKind::kRank ? "" : "rays";
    const uint64_t per_item_bytes = p.kind == SparseJobKind::kRank ? 64 : 9 * T_;
    batch.max_items = std::max<uint64_t>(1, kMaxSparseJobBytes / per_item_bytes);
    batch.jobs_ahead = kJobsAhead;
    batch.commit_interval_s = kCommitIntervalSeconds;
    batch.make_job = [&](RowRange& range, std::string& message) {
      SparseJobHeader h;
      h.kind = static_cast<uint32_t>(p.kind);
      h.phase = step_number_;
      h.first = range.first;
      h.count = range.count;
      message = p.make_job(h, std::move(message));
      range.count = h.count;
    };
    batch.accept = [&](int rank, const RowRange& range, std::string_view payload) {
      SparseJobResult r;
      try {
        r = DecodeSparseJobResult(payload);
      } catch (const std::exception& e) {
        throw RankFailure("rank " + std::to_string(rank) + ": " + e.what());
      }
      if (r.header.first != range.first || r.header.count != range.count ||
          r.header.phase != step_number_)
        throw RankFailure("rank " + std::to_string(rank) + " returned a job it was not given");
      uint64_t rows_written = 0;
      JournalEntry e;
      e.phase = p.name;
      e.rows = range;
      e.rows_checksum = p.accept(r, rows_written);
      if (p.kind != SparseJobKind::kRank && !p.cross_validation && !r.in_place) {
        try {
          ctx_.variance->Record(p.name, range.first, range.count,
                                DecodeTransportVariance(
                                    r.variance, "variance sums from rank " + std::to_string(rank)));
        } catch (const InputError& err) {
          throw RankFailure(err.what());
        }
      }
      e.counters = r.counters.ToVector();
      e.rays_traced = r.counters.rays_traced;
      e.texels_traced = r.counters.texels_traced;
      e.texels_below_horizon = rows_written;  // (rows written; not journaled for sjob lines)
      return e;
    };
    batch.sync = [&] {
      p.sync();
      ctx_.variance->Sync();
    };
    batch.committed = [&](const JournalEntry& e) {
      rep.rows_done += e.texels_below_horizon;
      Count(SparseJobCounters::FromVector(e.counters), true, p.cross_validation);
    };
    loop_.Run(batch);
    ++step_number_;
    rep.sparse.phases.push_back({p.name, FarmNow() - t0, p.items, reused_jobs});
  }

  FarmContext& ctx_;
  JobLoop& loop_;
  const std::size_t N_;
  const std::size_t T_;
  const int n_;
  const int m_;
  const std::size_t Tm_;
  std::unique_ptr<SideFile> aux_;
  std::unique_ptr<SideFile> low_file_;   // rows in place: sparse/dense_low.bin
  std::vector<std::vector<float>> low_;  // downsampled rows of the dense vertices (else)

 public:
  // Per sample, CombinationSlots pairs (sparse_jobs.h): filled by the sparse-reconstruct step.
  std::vector<uint32_t> combination_;

 private:
  uint32_t step_number_ = 0;
  uint64_t rows_shipped_ = 0;
  double index_seconds_ = 0;

 public:
  uint64_t variance_uncovered_jobs_ = 0;  // re-used jobs without a logged variance record
};

class SparsePhase final : public FarmPhase {
 public:
  const char* name() const override { return "sparse"; }
  const char* stage() const override { return kStageRows; }
  // The method's steps (RunSparseSchedule's order), each as a fraction of a brute-force row:
  // dense 0.75, rank 0.08, reconstruct 0.6 (docs/sparse-precomputation.md).
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    const double row = SecondsPerRow(ctx);
    const std::size_t N = ctx.params.rows;
    const SparsePlan& plan = ctx.plan;
    const std::size_t budget = SparseDenseBudget(N, plan);
    std::size_t dense = SparseInitialDenseCount(N, plan);
    steps.push_back({"dense-initial", "dense", double(dense), 0.75 * row});
    const int rounds = SparseRounds(plan);
    for (int it = 0; it < rounds && dense < budget; ++it) {
      const std::size_t picks = SparsePicksForRound(budget, dense, rounds, it);
      const std::string k = std::to_string(it + 1);
      const double cand = std::min<double>(double(N - dense),
                                           double(picks) * std::max(1, plan.candidates_per_pick));
      steps.push_back({"rank-" + k, "rank", cand, 0.08 * row});
      steps.push_back({"dense-rank-" + k, "dense", double(picks), 0.75 * row});
      dense += picks;
    }
    const double sparse = double(N - std::min(N, dense));
    steps.push_back({"sparse-reconstruct", "sparse", sparse, 0.6 * row});
    steps.push_back({"cross-validate", "sparse",
                     double(std::min(kSparseCrossValidated, SparseInitialDenseCount(N, plan))),
                     0.6 * row});
    steps.push_back({"dense-fallback", "dense", 0.04 * sparse, 0.75 * row});
  }

  void Run(FarmContext& ctx) override {
    // This rank's handles on the run's files (rows in place), opened at its first job: rank 0
    // created them before it sends one.
    std::unique_ptr<FarmSparseRowFiles> files;
    CompactJobExpander expander;
    RunJobPhase(
        ctx,
        [&ctx, &files, &expander, mesh_rows = ctx.RowGroups()](
            const RowRange&, std::string_view payload, std::string& out) {
          if (ctx.rows_in_place && !files) files = std::make_unique<FarmSparseRowFiles>(ctx);
          std::string expanded;
          if (CompactJobExpander::IsCompact(payload)) {
            expanded = expander.Expand(ctx, payload);
            payload = expanded;
          }
          out = ComputeSparseJob(*ctx.sampler, ctx.samples, ctx.plan, payload, std::move(out),
                                 &mesh_rows, files.get());
        },
        [&ctx](JobLoop& loop) {
          FarmReport& rep = ctx.report;
          rep.sparse.enabled = true;
          FarmSparseSteps steps(ctx, loop);
          // An image's background pixels take no part (their rows stay the zeros the partial
          // file was created with).
          const SparseScheduleCounts c =
              RunSparseSchedule(ctx.samples.size(), ctx.plan, steps, SparseSkipOf(ctx.samples));
          rep.sparse.dense_initial = c.dense_initial;
          rep.sparse.candidates_ranked += c.candidates_ranked;
          rep.sparse.dense_by_rank += c.dense_by_rank;
          rep.sparse.dense_fallback = c.dense_fallback;
          // The combinations the bounces reuse (farm/bounce/driver.cpp; a fallback's is empty).
          if (!steps.combination_.empty())
            WriteFileDurably(ctx.folder.SparseCombinationFile(),
                             EncodeCombinationFile(ctx.samples.size(), CombinationSlots(ctx.plan),
                                                   steps.combination_));
          RemoveSparseScratch(ctx.folder);
          if (steps.variance_uncovered_jobs_ > 0)
            spdlog::warn(
                "{} re-used job(s) have no logged variance: the Monte-Carlo estimate "
                "leaves their rows out",
                steps.variance_uncovered_jobs_);
          rep.jobs_total = rep.jobs_done + rep.jobs_reused;
        });
  }
};

}  // namespace

// Rows by the sparse method: a transport run with method "sparse" whose rows stage runs.
void AddSparsePhase(const FarmContext& ctx, PhaseList& phases) {
  if (ctx.params.visibility || !ctx.params.sparse || !ctx.params.run_rows) return;
  phases.push_back(std::make_unique<SparsePhase>());
}

}  // namespace prt
