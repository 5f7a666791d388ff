// What prt-farm's bounce phases share (docs/interreflection.md; docs/farm.md, "Phases" and "Where
// the rows go"): one driver that every estimator of the indirect stage runs its jobs on.
//
// The estimators, one file each, hold only what is theirs (farm/bounce/estimators.h):
//   gathering.cpp     bounce k ≥ 1, one phase per bounce ("bounce-<k>");
//   path_tracing.cpp  every bounce at once by per-element path tracing (k = 0, "path-trace");
//   features.cpp      the sparse method's features step after either ("bounce-<k>-sparse",
//                     "path-trace-sparse"), [sparse] indirect = "features".
// A job is a range of vertices; its payload is a BounceResultHeader, then the job's rows
// vertex-major (channels rows of `cols` floats per vertex), then `energies` doubles (path
// tracing's per-bounce energies). The driver owns everything after that:
//   - the phase's file and its dimensions: indirect/bounce-<k>.prtt or path-traced.prtt (with
//     features, the dense phase writes bounce-<k>-dense.prtt / path-traced-dense.prtt and the
//     -sparse step the full file), written as FinalPath + ".partial" while the jobs run, rows
//     channel-major (row c·V + v);
//   - the rows of the whole scene a phase reads first (the previous bounce, the dense rows):
//     with rows in place every rank reads them from the run folder itself, else rank 0 reads
//     and broadcasts them;
//   - writing a job's rows: with rows in place the worker writes them into the partial file by
//     channel and returns only the header (with their XXH64) and the energies; else they come
//     to rank 0 with the header, which checks the XXH64 and writes them;
//   - checkpoints/indirect-journal.txt, keyed by the indirect stage's inputs (ctx.indirect_key):
//     a killed run resumes phase by phase, re-using the jobs whose journaled checksum matches the
//     rows in the partial file, and a complete file is re-used whole;
//   - sparse "combination" (docs/sparse-precomputation.md, "With interreflection"): which
//     vertices are combined (every rank), and rank 0 filling their rows after the job loop;
//   - committing the file (finalize, rename), its energy, and the indirect share of B after the
//     stage's last phase (report.json "interreflection").
// Internal to farm/bounce/.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "worker/bounce_gather.h"

namespace prt {

// What a bounce job's payload starts with.
struct BounceResultHeader {
  uint64_t rows_checksum = 0;
  uint64_t rays_traced = 0;
  uint64_t rays_escaped = 0;    // features step: the texels evaluated
  uint64_t back_face_hits = 0;  // features step: the vertices that fell back to whole rows
  // 1: the worker wrote the rows into the phase's partial file itself and they do not follow
  // (docs/farm.md, "Where the rows go").
  uint64_t in_place = 0;
};

// Rank 0: what a phase's jobs (re-used and new) add up to, for its report figures.
struct BounceTotals {
  nlohmann::ordered_json energy;  // Σ T over the phase's file, per channel
  uint64_t rays = 0;
  uint64_t escaped = 0;     // the header's rays_escaped summed (features: texels evaluated)
  uint64_t back_faces = 0;  // the header's back_face_hits summed (features: fallbacks)
  uint64_t jobs_reused = 0;
  std::vector<double> job_energies;  // the jobs' `energies` doubles summed (path tracing)
  double wall_seconds = 0;
};

// The figures gathering and path tracing report for a phase (report.json "interreflection":
// an entry of per_bounce, or path_trace): bounce k (k > 0), its energy, rays, escapes,
// back-face hits, re-used jobs and seconds.
nlohmann::ordered_json TracedFigures(const BounceTotals& totals, int k);

// Appends room for a job's header, `floats` rows floats and `energies` doubles to `out` (zeros);
// returns where its rows go.
float* AppendJobResult(std::string& out, std::size_t floats, std::size_t energies);
// A job of `range` whose rows are computed sample by sample, in parallel (TBB): appends the
// header and range.count × per_sample floats to `out`; row(s, dst) fills sample s's rows and
// returns its counters (called on any thread, in any order). The header gets the counters' sum
// and the rows' checksum (ChecksumFiniteRows, naming `phase`).
void ComputeJobRows(const std::string& phase, const RowRange& range, std::size_t per_sample,
                    std::string& out,
                    const std::function<GatherStats(uint64_t sample, float* dst)>& row);
// The XXH64 of a job's rows, after checking that each is finite (a NumericalError names the
// first vertex that is not).
uint64_t ChecksumFiniteRows(const float* rows, std::size_t floats, std::size_t per_vertex,
                            const RowRange& range, const std::string& phase);

// Which rows a bounce phase computes. Vertex runs: the samples' own (kSamples). An image run
// that gathers (docs/image-relighting.md, "Interreflection"): first support rows at the mesh
// vertices, never shipped — T⁰ on the indirect grid (kVertexDirect, "vertex-direct") and bounces
// 1 … K−1 (kVertexBounce, "vertex-bounce-<k>") —, then the pixels' Σ_k Tᵏ gathered from them
// (kPixelGather, "pixel-gather").
enum class BouncePass { kSamples, kVertexDirect, kVertexBounce, kPixelGather };

class BounceDriver {
 public:
  // k ≥ 1: bounce k gathered; k = 0: every bounce by per-element path tracing; features_step:
  // the -sparse phase after it.
  // `figures`: report.json "interreflection", shared by the run's bounce phases (rank 0).
  BounceDriver(int k, bool features_step, std::shared_ptr<nlohmann::ordered_json> figures,
               BouncePass pass = BouncePass::kSamples);
  const std::string& name() const { return name_; }
  BouncePass pass() const { return pass_; }
  bool on_vertices_of_image() const {
    return pass_ == BouncePass::kVertexDirect || pass_ == BouncePass::kVertexBounce;
  }
  // The rows the phase computes per channel (the run's samples, or an image run's mesh
  // vertices) and its channels (1 for vertex-direct).
  uint64_t Rows(const FarmContext& ctx) const;
  int Channels(const FarmContext& ctx) const;
  nlohmann::ordered_json& figures() const { return *figures_; }

  // What every bounce phase says of itself (farm_context.h, FarmPhase): its cost model, its
  // section of report.json.
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const;
  void Report(FarmReport& report) const { report.SetSection("interreflection", figures_->dump()); }

  // The file the phase writes (its partial file while the jobs run) and its dimensions: rows
  // C·V on the indirect grid (gathering, or any phase of the sparse method) or at n.
  std::string FinalPath(const FarmContext& ctx) const;
  TransportFileInfo FileInfo(const FarmContext& ctx) const;

  // Every rank: the rows of the whole scene the phase needs before its jobs. `bytes` (what
  // `read` loads, `what` names it) is checked against --memory-budget; rank 0 starts the ETA's
  // step; `read` runs on the ranks that read the run folder (rank 0, or every rank with rows in
  // place), then `shared` goes from rank 0 to every rank unless each read its own. A failure on
  // any rank stops every rank (CollectiveStop).
  void ReadSceneRows(FarmContext& ctx, uint64_t bytes, const std::string& what,
                     const std::function<void()>& read,
                     std::initializer_list<std::vector<float>*> shared);

  // Every rank (collective), method sparse: which vertices are combined, from rank 0's run/
  // sparse/combination.bin (every vertex computes without it). With "combination" a combined
  // vertex's job rows are zeros and rank 0 fills them after the job loop, Tᵏ(x) =
  // max(0, Σ α_j Tᵏ(d_j)) over the dense vertices d_j x's direct row was reconstructed from;
  // with "features" the dense phase leaves them zero and the features step reconstructs them.
  void LoadCombination(FarmContext& ctx);
  bool Combined(uint64_t v) const { return !mask_.empty() && mask_[v] != 0; }

  // A phase's jobs, as its estimator supplies them.
  struct Jobs {
    std::size_t cols = 0;      // floats per row
    std::size_t energies = 0;  // doubles after a job's rows (path tracing)
    // A features step's jobs return every vertex's row; the others return zeros for combined
    // vertices (what a resume checks a re-used job's checksum against).
    bool combined_rows_are_zero = true;
    // The stage's last phase: rank 0 computes the indirect share of B after it.
    bool completes_stage = false;
    // Any computing rank: appends a job's header, rows (vertex-major) and energies to `out`.
    std::function<void(const RowRange& range, std::string& out)> compute;
    // Rank 0, once the file is committed: puts the phase's figures into figures().
    std::function<void(FarmContext& ctx, const BounceTotals& totals)> report;
  };
  // Every rank: runs the jobs on the job loop; rank 0 resumes, writes, journals and commits the
  // phase's file and reports it (`start`: when the phase began, FarmNow()).
  void RunJobs(FarmContext& ctx, const Jobs& jobs, double start);

 private:
  void WriteInPlace(const FarmContext& ctx, std::size_t cols, const RowRange& range,
                    std::string& out, std::size_t at);
  void Coordinate(FarmContext& ctx, JobLoop& loop, const Jobs& jobs, double start);
  bool FileComplete(const FarmContext& ctx) const;
  void ReuseJobs(FarmContext& ctx, const Jobs& jobs, const std::vector<JournalEntry>& kept,
                 const TransportFileWriter& writer, JobBatch& batch, BounceTotals& totals) const;
  JournalEntry Accept(const FarmContext& ctx, const Jobs& jobs, TransportFileWriter& writer,
                      int rank, const RowRange& range, std::string_view payload) const;
  void Commit(const FarmContext& ctx, std::optional<TransportFileWriter>& writer,
              std::size_t cols) const;
  void FillCombined(const FarmContext& ctx, TransportFileWriter& writer, std::size_t cols) const;

  std::shared_ptr<nlohmann::ordered_json> figures_;
  int k_;
  bool step_;
  BouncePass pass_;
  std::string name_;
  // This rank's handle on the phase's partial file (rows in place), opened at its first job.
  std::optional<TransportFileWriter> rows_out_;
  std::vector<uint8_t> mask_;    // per vertex: 1 = combined (every rank)
  std::vector<uint32_t> pairs_;  // rank 0: combination.bin's pairs
  uint64_t slots_ = 0;
};

// What the bounce phases (gathering, path tracing, features) say of themselves alike: their
// driver's name, the indirect stage, its cost model and report section.
class BouncePhase : public FarmPhase {
 public:
  BouncePhase(int k, bool features_step, std::shared_ptr<nlohmann::ordered_json> figures,
              BouncePass pass = BouncePass::kSamples)
      : driver_(k, features_step, std::move(figures), pass) {}
  const char* name() const override { return driver_.name().c_str(); }
  const char* stage() const override { return kStageIndirect; }
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    driver_.PredictSteps(ctx, steps);
  }
  void Report(FarmReport& report) const override { driver_.Report(report); }

 protected:
  BounceDriver driver_;
};

// Rank 0, after the indirect stage's last phase: Σ_v ρ·(indirect · L) / Σ_v ρ·(T · L) under
// each scene environment and a uniform sky, on the indirect grid (report.json
// "interreflection.indirect_share").
void ReportIndirectShare(FarmContext& ctx, nlohmann::ordered_json& figures);

}  // namespace prt
