// The bounce phases' shared driver (farm/bounce/driver.h): the phase's file, its journal and
// resume, the job batch, writing rows in place or on rank 0, committing, the report figures and
// the indirect share; and the factory that picks the estimator.
#include "farm/bounce/driver.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <utility>

#include "farm/bounce/estimators.h"
#include "farm/mpi_support.h"
#include "farm/sparse_jobs.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/bounce_gather.h"
#include "worker/composed_transport.h"
#include "worker/sparse_indirect.h"

namespace prt {

namespace fs = std::filesystem;

namespace {

// ---- Helpers of rank 0's side.

double Dot(const float* a, const float* b, std::size_t n) {
  double s = 0;
  for (std::size_t i = 0; i < n; ++i) s += double(a[i]) * b[i];
  return s;
}

// Copies `count` vertices' rows between vertex-major (C rows per vertex, as a job returns them)
// and one channel's rows.
void ChannelOf(const float* vertex_major, uint64_t count, int C, int c, std::size_t cols,
               float* channel) {
  for (uint64_t i = 0; i < count; ++i)
    std::copy_n(vertex_major + (i * C + c) * cols, cols, channel + i * cols);
}

// Writes a job's vertex-major rows into the file by channel (row c·V + v).
void WriteByChannel(TransportFileWriter& w, uint64_t V, int C, std::size_t cols,
                    const RowRange& range, const float* rows) {
  std::vector<float> channel(static_cast<std::size_t>(range.count) * cols);
  for (int c = 0; c < C; ++c) {
    ChannelOf(rows, range.count, C, c, cols, channel.data());
    w.WriteRows(c * V + range.first, range.count, channel.data());
  }
}

// Rows [first, first + count) of every channel from the file, vertex-major (as a job returns
// them).
void ReadVertexMajor(const TransportFileWriter& w, uint64_t V, int C, std::size_t cols,
                     const RowRange& range, std::vector<float>& out) {
  out.resize(static_cast<std::size_t>(range.count * C * cols));
  std::vector<float> channel(static_cast<std::size_t>(range.count * cols));
  for (int c = 0; c < C; ++c) {
    w.ReadRows(c * V + range.first, range.count, channel.data());
    for (uint64_t i = 0; i < range.count; ++i)
      std::copy_n(channel.data() + i * cols, cols, out.data() + (i * C + c) * cols);
  }
}

// The indirect stage's journal lines still valid: those of a journal keyed by the inputs given
// now (the setup removed the folder and the journal when they changed).
std::vector<JournalEntry> KeptJournalLines(const FarmContext& ctx) {
  const JournalContents journal = ReadJournal(ctx.folder.indirect_journal);
  if (journal.has_header && journal.run_key == ctx.indirect_key) return journal.entries;
  return {};
}

// Rank 0: this phase's journal in ctx.journal for as long as it lives (the job loop writes the
// lines there), rewritten with the lines still valid; the one before comes back after.
class ScopedIndirectJournal {
 public:
  ScopedIndirectJournal(FarmContext& ctx, const std::vector<JournalEntry>& kept)
      : ctx_(ctx),
        journal_(std::make_unique<CheckpointJournal>(ctx.folder.indirect_journal, ctx.indirect_key,
                                                     kept)) {
    std::swap(journal_, ctx_.journal);
  }
  ~ScopedIndirectJournal() { std::swap(journal_, ctx_.journal); }
  ScopedIndirectJournal(const ScopedIndirectJournal&) = delete;
  ScopedIndirectJournal& operator=(const ScopedIndirectJournal&) = delete;

 private:
  FarmContext& ctx_;
  std::unique_ptr<CheckpointJournal> journal_;
};

// Σ T per channel over a committed file of C·V rows.
nlohmann::ordered_json EnergyPerChannel(const std::string& path, uint64_t V, int C,
                                        std::size_t cols) {
  const TransportFileReader reader(path);
  std::vector<float> all(static_cast<std::size_t>(reader.info().rows * cols));
  reader.ReadRows(0, reader.info().rows, all.data());
  nlohmann::ordered_json energy = nlohmann::ordered_json::array();
  for (int c = 0; c < C; ++c) {
    double s = 0;
    for (std::size_t i = c * V * cols; i < (c + 1) * V * cols; ++i) s += all[i];
    energy.push_back(s);
  }
  return energy;
}

}  // namespace

nlohmann::ordered_json TracedFigures(const BounceTotals& t, int k) {
  nlohmann::ordered_json figures = nlohmann::ordered_json::object();
  if (k > 0) figures["bounce"] = k;
  figures["energy"] = t.energy;
  figures["rays_traced"] = t.rays;
  figures["rays_escaped"] = t.escaped;
  figures["back_face_hits"] = t.back_faces;
  figures["jobs_reused"] = t.jobs_reused;
  figures["wall_seconds"] = t.wall_seconds;
  return figures;
}

float* AppendJobResult(std::string& out, std::size_t floats, std::size_t energies) {
  const std::size_t at = out.size();
  out.resize(at + sizeof(BounceResultHeader) + floats * sizeof(float) + energies * sizeof(double));
  return reinterpret_cast<float*>(out.data() + at + sizeof(BounceResultHeader));
}

void ComputeJobRows(const std::string& phase, const RowRange& range, std::size_t per_sample,
                    std::string& out,
                    const std::function<GatherStats(uint64_t sample, float* dst)>& row) {
  const std::size_t at = out.size();
  const std::size_t floats = static_cast<std::size_t>(range.count) * per_sample;
  float* rows = AppendJobResult(out, floats, 0);
  tbb::enumerable_thread_specific<GatherStats> stats;
  tbb::parallel_for(tbb::blocked_range<uint64_t>(0, range.count, 8),
                    [&](const tbb::blocked_range<uint64_t>& r) {
                      for (uint64_t i = r.begin(); i != r.end(); ++i)
                        stats.local() += row(range.first + i, rows + i * per_sample);
                    });
  GatherStats s;
  for (const GatherStats& l : stats) s += l;
  BounceResultHeader h;
  h.rows_checksum = ChecksumFiniteRows(rows, floats, per_sample, range, phase);
  h.rays_traced = s.rays_traced;
  h.rays_escaped = s.rays_escaped;
  h.back_face_hits = s.back_face_hits;
  std::memcpy(out.data() + at, &h, sizeof h);
}

uint64_t ChecksumFiniteRows(const float* rows, std::size_t floats, std::size_t per_vertex,
                            const RowRange& range, const std::string& phase) {
  for (std::size_t i = 0; i < floats; ++i)
    if (!std::isfinite(rows[i]))
      throw NumericalError(phase + ": a non-finite value for sample " +
                           std::to_string(range.first + i / per_vertex));
  return Checksum64(rows, floats * sizeof(float));
}

namespace {

std::string PhaseName(int k, bool features_step, BouncePass pass) {
  switch (pass) {
    case BouncePass::kVertexDirect:
      return "vertex-direct";
    case BouncePass::kVertexBounce:
      return "vertex-bounce-" + std::to_string(k);
    case BouncePass::kPixelGather:
      return "pixel-gather";
    case BouncePass::kSamples:
      break;
  }
  return (k > 0 ? "bounce-" + std::to_string(k) : std::string("path-trace")) +
         (features_step ? "-sparse" : "");
}

}  // namespace

BounceDriver::BounceDriver(int k, bool features_step,
                           std::shared_ptr<nlohmann::ordered_json> figures, BouncePass pass)
    : figures_(std::move(figures)),
      k_(k),
      step_(features_step),
      pass_(pass),
      name_(PhaseName(k, features_step, pass)) {}

uint64_t BounceDriver::Rows(const FarmContext& ctx) const {
  return on_vertices_of_image() ? ctx.geometry.vertex_count() : ctx.params.rows;
}

int BounceDriver::Channels(const FarmContext& ctx) const {
  return pass_ == BouncePass::kVertexDirect ? 1 : ctx.params.channels;
}

std::string BounceDriver::FinalPath(const FarmContext& ctx) const {
  const RunFolder& f = ctx.folder;
  if (pass_ == BouncePass::kVertexDirect) return f.VertexDirectFile();
  if (pass_ == BouncePass::kVertexBounce) return f.VertexBounceFile(k_);
  if (pass_ == BouncePass::kPixelGather) return f.PixelGatherFile();
  // With features: the dense rows first (bounce-k, path-trace), then every row (-sparse).
  const bool features = ctx.params.sparse_indirect == 2;
  return features && !step_ ? (k_ > 0 ? f.BounceDenseFile(k_) : f.PathTracedDenseFile())
                            : (k_ > 0 ? f.BounceFile(k_) : f.PathTracedFile());
}

TransportFileInfo BounceDriver::FileInfo(const FarmContext& ctx) const {
  const bool on_grid = k_ > 0 || ctx.params.sparse_indirect || pass_ != BouncePass::kSamples;
  return TransportFileInfo{
      static_cast<uint64_t>(Channels(ctx)) * Rows(ctx),
      static_cast<uint32_t>(on_grid ? ctx.params.indirect_n : ctx.params.cubemap_n),
      ctx.options.rows_per_block, static_cast<uint32_t>(ctx.params.gather_paths), ctx.params.seed};
}

void BounceDriver::ReadSceneRows(FarmContext& ctx, uint64_t bytes, const std::string& what,
                                 const std::function<void()>& read,
                                 std::initializer_list<std::vector<float>*> shared) {
  uint64_t status = kExitOk;
  if (ctx.rank == 0 || ctx.rows_in_place) {
    try {
      if (bytes > ctx.options.memory_budget_bytes)
        throw UsageError(name_ + " needs " + what + " (" + std::to_string(bytes >> 20) +
                         " MiB in all) on every rank, more than " + "--memory-budget (" +
                         std::to_string(ctx.options.memory_budget_bytes >> 20) +
                         " MiB): raise it or lower [sampling] indirect_n");
      if (ctx.rank == 0) ctx.run_eta.StepStarted(name_);
      read();
    } catch (...) {
      std::string message;
      status = static_cast<uint64_t>(ExitCodeOf(std::current_exception(), message, name_));
      spdlog::error("rank {}: {}: {}", ctx.rank, name_, message);
      if (ctx.rank == 0) ctx.report.error = message;
    }
  }
  AgreeOrStop(ctx, static_cast<int>(status));
  if (ctx.rows_in_place) return;
  for (std::vector<float>* rows : shared)
    ctx.collectives.ShareVectorFromRank0(*rows, "share the bounce rows");
}

void BounceDriver::LoadCombination(FarmContext& ctx) {
  mask_.clear();
  pairs_.clear();
  if (!ctx.params.sparse_indirect || on_vertices_of_image()) return;
  const uint64_t V = ctx.params.rows;
  if (ctx.rank == 0) {
    try {
      pairs_ = ReadCombinationFile(ctx.folder.SparseCombinationFile(), V, slots_);
      mask_.assign(static_cast<std::size_t>(V), 0);
      for (uint64_t v = 0; v < V; ++v) mask_[v] = pairs_[v * slots_ * 2] != kNoSample ? 1 : 0;
      uint64_t combined = 0;
      for (uint8_t m : mask_) combined += m;
      if (step_)
        spdlog::info("[{}] {} of {} vertices are dense; {} evaluate their features", name_,
                     V - combined, V, combined);
      else
        spdlog::info("[{}] {} of {} vertices gather; {} combine the dense vertices' rows", name_,
                     V - combined, V, combined);
      (*figures_)["sparse_combined_vertices"] = combined;
    } catch (const InputError& e) {
      spdlog::warn("{}: every vertex gathers", e.what());
      pairs_.clear();
      mask_.clear();
    }
  }
  ctx.collectives.ShareVectorFromRank0(mask_, "share the bounce mask");
}

void BounceDriver::RunJobs(FarmContext& ctx, const Jobs& jobs, double start) {
  RunJobPhase(
      ctx,
      [&](const RowRange& range, std::string_view, std::string& out) {
        const std::size_t at = out.size();
        jobs.compute(range, out);
        WriteInPlace(ctx, jobs.cols, range, out, at);
      },
      [&](JobLoop& loop) { Coordinate(ctx, loop, jobs, start); });
}

// Rows in place (docs/farm.md, "Where the rows go"): the job's rows, vertex-major after the
// header at `at` of `out`, go into the phase's partial file by channel (row c·V + v), durably;
// `out` keeps the header (in_place = 1) and what followed the rows (path tracing's energies).
void BounceDriver::WriteInPlace(const FarmContext& ctx, std::size_t cols, const RowRange& range,
                                std::string& out, std::size_t at) {
  if (!ctx.rows_in_place) return;
  if (!rows_out_)
    rows_out_.emplace(TransportFileWriter::OpenRows(FinalPath(ctx) + ".partial", FileInfo(ctx)));
  const int C = Channels(ctx);
  const std::size_t floats = static_cast<std::size_t>(range.count) * C * cols;
  if (out.size() < at + sizeof(BounceResultHeader) + floats * sizeof(float))
    throw std::logic_error(name_ + ": a job's result is shorter than its rows");
  const float* rows = reinterpret_cast<const float*>(out.data() + at + sizeof(BounceResultHeader));
  WriteByChannel(*rows_out_, Rows(ctx), C, cols, range, rows);
  rows_out_->Sync();
  BounceResultHeader h;
  std::memcpy(&h, out.data() + at, sizeof h);
  h.in_place = 1;
  std::memcpy(out.data() + at, &h, sizeof h);
  out.erase(at + sizeof h, floats * sizeof(float));
}

// Rank 0's side of the jobs: re-use what a killed run left, run the rest, commit, report.
void BounceDriver::Coordinate(FarmContext& ctx, JobLoop& loop, const Jobs& jobs, double start) {
  const uint64_t V = Rows(ctx);
  const int C = Channels(ctx);
  const std::string final_path = FinalPath(ctx);
  const std::string partial = final_path + ".partial";
  std::error_code ec;
  fs::create_directories(ctx.folder.indirect, ec);
  BounceTotals totals;
  totals.job_energies.assign(jobs.energies, 0.0);
  JobBatch batch;
  std::optional<TransportFileWriter> writer;
  const std::vector<JournalEntry> kept = KeptJournalLines(ctx);
  if (FileComplete(ctx)) {
    batch.done.push_back({0, V});
    spdlog::info("[{}] re-used: {} is complete", name_, final_path);
  } else {
    if (fs::exists(partial, ec)) {
      try {
        writer.emplace(TransportFileWriter::Reopen(partial, FileInfo(ctx)));
      } catch (const InputError& e) {
        spdlog::warn("{}; its jobs are redone", e.what());
      }
    }
    if (!writer) writer.emplace(TransportFileWriter::Create(partial, FileInfo(ctx)));
    ReuseJobs(ctx, jobs, kept, *writer, batch, totals);
  }
  ctx.report.jobs_reused += totals.jobs_reused;

  batch.name = name_;
  batch.items = V;
  batch.unit = "samples";
  batch.max_items = std::max<uint64_t>(1, kMaxJobBytes / (C * jobs.cols * sizeof(float)));
  // Image runs: background pixels next to free (the vertex passes' items cost alike).
  if (!on_vertices_of_image()) batch.cost = SampleCost(ctx);
  batch.accept = [&](int rank, const RowRange& range, std::string_view payload) {
    return Accept(ctx, jobs, *writer, rank, range, payload);
  };
  batch.sync = [&] { writer->Sync(); };
  batch.committed = [&](const JournalEntry& e) {
    totals.rays += e.rays_traced;
    totals.escaped += e.texels_traced;
    totals.back_faces += e.texels_below_horizon;
    for (std::size_t i = 0; i < jobs.energies && i < e.counters.size(); ++i)
      totals.job_energies[i] += std::bit_cast<double>(e.counters[i]);
  };
  {
    const ScopedIndirectJournal journal(ctx, kept);
    loop.Run(batch);
  }
  Commit(ctx, writer, jobs.cols);

  // The phase's figures: energy Σ T per channel, rays, and (after the stage's last phase) the
  // indirect share of B under each scene environment.
  totals.energy = EnergyPerChannel(final_path, V, C, jobs.cols);
  totals.wall_seconds = FarmNow() - start;
  jobs.report(ctx, totals);
  spdlog::info("[{}] energy {} (sum of the bounce's T per channel), {} rays, {:.1f} s", name_,
               totals.energy.dump(), totals.rays, FarmNow() - start);
  ctx.report.jobs_total = ctx.report.jobs_done + ctx.report.jobs_reused;
  if (jobs.completes_stage) ReportIndirectShare(ctx, *figures_);
}

// Whether the phase's file is there already with this run's dimensions (a resume re-uses it).
bool BounceDriver::FileComplete(const FarmContext& ctx) const {
  std::error_code ec;
  const std::string final_path = FinalPath(ctx);
  if (!fs::exists(final_path, ec)) return false;
  try {
    const TransportFileInfo info = FileInfo(ctx);
    const TransportFileReader r(final_path);
    return r.info().rows == info.rows && r.info().cubemap_n == info.cubemap_n;
  } catch (const InputError&) {
    return false;
  }
}

// The journaled jobs of this phase whose rows in the partial file still have their checksum go
// into batch.done (their counters into `totals`); the others are redone.
void BounceDriver::ReuseJobs(FarmContext& ctx, const Jobs& jobs,
                             const std::vector<JournalEntry>& kept,
                             const TransportFileWriter& writer, JobBatch& batch,
                             BounceTotals& totals) const {
  const uint64_t V = Rows(ctx);
  const int C = Channels(ctx);
  const std::size_t cols = jobs.cols;
  std::vector<float> rows;
  for (const JournalEntry& e : kept) {
    if (e.phase != name_ || e.rows.end() > V || e.rows.count * C * cols * 4 > kMaxJobBytes)
      continue;
    const bool overlaps = std::any_of(batch.done.begin(), batch.done.end(), [&](const RowRange& d) {
      return e.rows.first < d.end() && d.first < e.rows.end();
    });
    if (overlaps) continue;
    ReadVertexMajor(writer, V, C, cols, e.rows, rows);
    // As the job returned them: zeros for combined vertices, except in a features step, whose
    // jobs return every row.
    for (uint64_t i = 0; i < e.rows.count && jobs.combined_rows_are_zero; ++i)
      if (Combined(e.rows.first + i))
        std::fill_n(rows.data() + i * C * cols, static_cast<std::size_t>(C) * cols, 0.0f);
    if (Checksum64(rows.data(), rows.size() * sizeof(float)) != e.rows_checksum) {
      ++ctx.report.checkpoints_rejected;
      continue;
    }
    batch.done.push_back(e.rows);
    for (std::size_t i = 0; i < jobs.energies && i < e.counters.size(); ++i)
      totals.job_energies[i] += std::bit_cast<double>(e.counters[i]);
    ++totals.jobs_reused;
  }
  if (totals.jobs_reused > 0)
    spdlog::info("[{}] {} job(s) re-used from checkpoints", name_, totals.jobs_reused);
}

// Rank 0: checks a job's result, writes its rows unless the worker did (rows in place), and
// returns its journal line: the rows' checksum, the header's counters (a features step's texels
// evaluated and fallbacks in the places of escapes and back faces) and the energies, bit-cast.
JournalEntry BounceDriver::Accept(const FarmContext& ctx, const Jobs& jobs,
                                  TransportFileWriter& writer, int rank, const RowRange& range,
                                  std::string_view payload) const {
  BounceResultHeader h;
  if (payload.size() >= sizeof h) std::memcpy(&h, payload.data(), sizeof h);
  // Rows in place: the worker wrote them; only the header and the energies came.
  const std::size_t per_vertex = static_cast<std::size_t>(Channels(ctx)) * jobs.cols;
  const std::size_t floats = h.in_place ? 0 : static_cast<std::size_t>(range.count) * per_vertex;
  if (payload.size() != sizeof h + floats * sizeof(float) + jobs.energies * sizeof(double))
    throw RankFailure("rank " + std::to_string(rank) + " returned " +
                      std::to_string(payload.size()) + " bytes for " + std::to_string(range.count) +
                      " samples of " + name_);
  const float* rows = reinterpret_cast<const float*>(payload.data() + sizeof h);
  if (!h.in_place) {
    if (Checksum64(rows, floats * sizeof(float)) != h.rows_checksum)
      throw RankFailure("rows of " + name_ + " from rank " + std::to_string(rank) +
                        " arrived damaged (checksum mismatch)");
    WriteByChannel(writer, Rows(ctx), Channels(ctx), jobs.cols, range, rows);
  }
  JournalEntry e;
  e.phase = name_;
  e.rows = range;
  e.rows_checksum = h.rows_checksum;
  for (std::size_t i = 0; i < jobs.energies; ++i) {
    double x = 0;
    std::memcpy(&x, payload.data() + sizeof h + floats * sizeof(float) + i * sizeof x, sizeof x);
    e.counters.push_back(std::bit_cast<uint64_t>(x));
  }
  e.rays_traced = h.rays_traced;
  e.texels_traced = h.rays_escaped;
  e.texels_below_horizon = h.back_face_hits;
  return e;
}

// Rank 0: fills the combined vertices (sparse "combination"), finalizes the partial file and
// renames it into place (nothing to do when the file was re-used whole).
void BounceDriver::Commit(const FarmContext& ctx, std::optional<TransportFileWriter>& writer,
                          std::size_t cols) const {
  if (!writer) return;
  if (!pairs_.empty() && ctx.params.sparse_indirect == 1) FillCombined(ctx, *writer, cols);
  const std::string final_path = FinalPath(ctx);
  writer->Finalize();
  writer.reset();
  fs::rename(final_path + ".partial", final_path);
  SyncDirectory(ctx.folder.indirect);
}

// Rank 0: the combined vertices' rows from the dense ones, written over their zeros.
void BounceDriver::FillCombined(const FarmContext& ctx, TransportFileWriter& writer,
                                std::size_t cols) const {
  const uint64_t V = ctx.params.rows;
  const int C = ctx.params.channels;
  std::vector<float> all(static_cast<std::size_t>(V * cols));
  std::vector<SampleWeight> w;
  for (int c = 0; c < C; ++c) {
    writer.ReadRows(c * V, V, all.data());
    std::vector<float> filled = all;
    for (uint64_t v = 0; v < V; ++v) {
      if (!Combined(v)) continue;
      w.clear();
      for (std::size_t j = 0; j < slots_; ++j) {
        const uint32_t d = pairs_[(v * slots_ + j) * 2];
        if (d == kNoSample) continue;
        if (Combined(d))
          throw InputError(ctx.folder.SparseCombinationFile(),
                           "combines vertex " + std::to_string(v) + " from vertex " +
                               std::to_string(d) + ", which is not dense");
        w.push_back({d, std::bit_cast<float>(pairs_[(v * slots_ + j) * 2 + 1])});
      }
      CombineRows(
          w, [&](uint32_t d) { return all.data() + static_cast<std::size_t>(d) * cols; }, cols,
          filled.data() + v * cols);
    }
    writer.WriteRows(c * V, V, filled.data());
  }
}

void ReportIndirectShare(FarmContext& ctx, nlohmann::ordered_json& figures) {
  const EstimateLights& estimate = LoadEstimateLights(ctx);
  const uint64_t V = ctx.params.rows;
  const int C = ctx.params.channels;
  const std::vector<std::string> files = IndirectFiles(
      ctx.folder, ctx.params.bounces, ctx.params.path_estimator != 0, ctx.params.image != 0);
  const CubemapLayout fine(ctx.params.cubemap_n), coarse(ctx.params.indirect_n);
  const std::size_t cols = coarse.texel_count();
  // T⁰ coarsened, and Σ_k Tᵏ.
  std::vector<float> direct(static_cast<std::size_t>(V * cols), 0.0f);
  AddCoarsenedRows(TransportFileReader(ctx.folder.transport), coarse, direct.data());
  // Bounce rows are on the indirect grid already; path-traced ones at n are coarsened.
  std::vector<float> indirect(static_cast<std::size_t>(C * V * cols), 0.0f);
  for (const std::string& file : files)
    AddCoarsenedRows(TransportFileReader(file), coarse, indirect.data());
  nlohmann::ordered_json share = nlohmann::ordered_json::array();
  for (std::size_t l = 0; l < estimate.lights.size(); ++l) {
    double d = 0, ind = 0;
    for (int c = 0; c < 3; ++c) {
      const std::vector<float> L = CoarsenLight(fine, coarse, estimate.lights[l].Channel(c));
      const int tc = C == 1 ? 0 : c;
      for (uint64_t v = 0; v < V; ++v) {
        const double rho = ctx.RowAlbedo(v)[c];
        d += rho * Dot(direct.data() + v * cols, L.data(), cols);
        ind += rho * Dot(indirect.data() + (tc * V + v) * cols, L.data(), cols);
      }
    }
    share.push_back(
        {{"light", estimate.names[l]}, {"indirect_share", d + ind > 0 ? ind / (d + ind) : 0.0}});
    spdlog::info("interreflection: {:.1f}% of B is bounce light under {}",
                 d + ind > 0 ? 100 * ind / (d + ind) : 0.0, estimate.names[l]);
  }
  figures["indirect_share"] = share;
}

// The indirect stage, when it runs: one phase per bounce (gathering) or one path-tracing phase,
// each followed by its features step with [sparse] indirect = "features". They share the figures
// of report.json "interreflection": the settings, then each phase's.
void AddBouncePhases(const FarmContext& ctx, PhaseList& phases) {
  const SetupParams& p = ctx.params;
  if (!p.run_indirect) return;
  auto figures = std::make_shared<nlohmann::ordered_json>(
      nlohmann::ordered_json{{"bounces", p.bounces},
                             {"estimator", p.path_estimator ? "path" : "gather"},
                             {"indirect_n", p.indirect_n},
                             {"paths", p.gather_paths},
                             {"channels", p.channels},
                             {"per_bounce", nlohmann::ordered_json::array()}});
  const bool features = p.sparse_indirect == 2;
  if (p.image && !p.path_estimator) {
    // docs/image-relighting.md, "Interreflection": the vertices' support rows, then the pixels.
    phases.push_back(MakeVertexDirectPhase(figures));
    for (int k = 1; k < p.bounces; ++k) phases.push_back(MakeVertexBouncePhase(k, figures));
    phases.push_back(MakePixelGatherPhase(figures));
    return;
  }
  if (p.path_estimator) {
    phases.push_back(MakePathTracingPhase(figures));
    if (features) phases.push_back(MakeFeaturesPhase(0, figures));
    return;
  }
  for (int k = 1; k <= p.bounces; ++k) {
    phases.push_back(MakeGatheringPhase(k, figures));
    if (features) phases.push_back(MakeFeaturesPhase(k, figures));
  }
}

// A gathered bounce: P closest-hit rays per vertex (~2 M/s per thread) and the gather's
// multiply-adds (~3·P·6m² per vertex and channel at ~1 G/s per thread). Path tracing: a direct
// row (~3n² shadow rays) per path vertex, K per path, P paths per vertex (on the indirect grid
// with the sparse method). With the sparse method's indirect part only the dense vertices (about
// the dense budget) do the whole work; a features step costs its features' share
// (docs/sparse-precomputation.md, "With interreflection").
void BounceDriver::PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const {
  const SetupParams& p = ctx.params;
  double rows = static_cast<double>(p.rows);
  const double threads = std::max(1, ctx.computing_ranks()) * std::max(1, ctx.threads);
  const double dense_share = p.sparse_indirect && !on_vertices_of_image()
                                 ? std::min(1.0, ctx.plan.dense_budget + 0.05)
                                 : 1.0;
  const double share = step_ ? 1 - dense_share : dense_share;
  if (k_ == 0) {
    const double cols = 6.0 * p.cubemap_n * p.cubemap_n;
    const double path_cols = p.sparse_indirect ? 6.0 * p.indirect_n * p.indirect_n : cols;
    const double per_texel = p.bounces * p.gather_paths * 0.5 * p.channels / (1e7 * threads);
    const double per_row =
        step_ ? IndirectFeatures(ctx.plan.sparse.features, p.cubemap_n, p.indirect_n) * per_texel
              : path_cols * per_texel;
    steps.push_back({name_, "path-trace", rows * share, per_row});
    return;
  }
  const double m = p.indirect_n;
  if (pass_ == BouncePass::kVertexDirect) {  // rays_per_texel shadow rays per coarse texel
    steps.push_back(
        {name_, "bounce", double(Rows(ctx)), 6 * m * m * p.rays_per_texel * 0.5 / (1e7 * threads)});
    return;
  }
  if (on_vertices_of_image()) rows = double(Rows(ctx));
  // The pixels' gather applies its terms to T⁰ and, with K > 1, to Σ_{k≥1} Tᵏ.
  const double applies = pass_ == BouncePass::kPixelGather && p.bounces > 1 ? 2.0 : 1.0;
  const double per_vertex =
      (p.gather_paths / 2e6 + applies * 3.0 * p.gather_paths * 6 * m * m * p.channels / 1e9) /
      threads;
  // The features' directions are a fraction of P.
  const double scale =
      step_ ? double(std::max(1, p.sparse_feature_paths)) / std::max(1, p.gather_paths) : 1.0;
  steps.push_back({name_, "bounce", rows * share, per_vertex * scale});
}

}  // namespace prt
