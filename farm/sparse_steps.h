// Rank 0's side of the sparse phase (farm/sparse_phase.cpp): the method's steps (Huang &
// Ramamoorthi 2010 §4–5) as batches of jobs on the job loop, in the order the worker's one driver
// RunSparseSchedule (worker/sparse_precomputation.h) calls them. Only the sparse phase's files
// include this; one file per group of steps:
//   sparse_phase.cpp             the steps' shared driver: one step as a batch of jobs with its
//                                checkpoints (RunStep), the counters, and the phase itself
//   sparse_dense_steps.cpp       dense rows (§4.2) and the local rank of candidates (§4.1)
//   sparse_reconstruct_step.cpp  the sparse vertices' reconstruction (§5) and its jobs
//   sparse_cross_validation.cpp  the reconstruction's own error, by cross-validation
//   sparse_step_lists.h          the neighbour lists and compact jobs rank 0 and workers share
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/side_file.h"
#include "farm/sparse_jobs.h"
#include "farm/sparse_step_lists.h"
#include "worker/neighbor_index.h"
#include "worker/sparse_precomputation.h"

namespace prt {

// A job's rows (the dense neighbours it is sent, or the rows it returns) fit in 24 MiB: glibc
// serves blocks above its mmap threshold (at most 32 MiB) with fresh pages on every allocation,
// so jobs of ~100 MiB paid a page fault per 4 KiB of every copy of every job (encode, MPI,
// decode, result) — 14 % of a 2-rank run's samples (docs/farm.md). Below it the buffers are
// reused from the heap.
inline constexpr uint64_t kMaxSparseJobBytes = uint64_t{24} << 20;

// A cross-validation job's records (run/sparse/cross_validation.bin, see CrossValidate): per
// vertex the outcome byte, 3 zero bytes, then reconstruction − traced row as float32 (zeros where
// the reconstruction fell back). `rows`: the reconstructed rows in order; traced(i, out) reads
// vertex i's traced row.
std::vector<char> CrossValidationRecords(std::size_t T, std::span<const uint8_t> outcomes,
                                         const float* rows,
                                         const std::function<void(std::size_t, float*)>& traced);

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
  // Creates run/sparse/ and opens dense_aux.bin (and, rows in place, dense_low.bin).
  FarmSparseSteps(FarmContext& ctx, JobLoop& loop);

  // ---- dense rows (§4.2): T into the transport file, visibility + features into dense_aux.bin
  // (sparse_dense_steps.cpp)
  void Dense(const std::string& name, std::span<const uint32_t> ids) override;

  // ---- local rank of candidates (§4.1): each candidate's weight, kept in run/sparse/<name>.bin
  // (sparse_dense_steps.cpp)
  std::vector<double> Rank(const std::string& name, int, std::span<const uint32_t> dense,
                           std::span<const uint32_t> cand) override;

  // ---- sparse vertices (§5); returns the fallbacks, sorted (sparse_reconstruct_step.cpp)
  std::vector<uint32_t> Reconstruct(const std::string& name, std::span<const uint32_t> dense,
                                    std::span<const uint8_t> is_dense) override;

  // A sparse job for items h.first… of `order` (may lower h.count, see kMaxSparseJobBytes): each
  // vertex with its dense neighbours within the radius (nearest first) and the union of their
  // rows, read back from the run folder. `exclude_self`: the vertices are dense and their own
  // row is left out (cross-validation). (sparse_reconstruct_step.cpp)
  std::string MakeSparseJob(SparseJobHeader& h, std::string prefix, const NeighborIndex& index,
                            std::span<const uint32_t> order, bool exclude_self,
                            const std::string& step);
  // The reconstruction's own error, by cross-validation (docs/farm.md, "Accuracy estimates"):
  // up to kCrossValidated vertices of the initial dense set (a uniform random sample of the
  // scene, InitialDenseSet) are reconstructed from the other dense vertices exactly as a sparse
  // vertex is, and their reconstruction minus their traced dense row is kept in
  // run/sparse/cross_validation.bin (a record per vertex: the outcome byte, 3 zero bytes, then
  // the texels' differences as float32; 0 where the reconstruction fell back, as the pipeline
  // then traces the vertex). run/sparse/cross_validation.json lists the vertices and, per mesh,
  // how many vertices were reconstructed. Nothing here changes a row of T.
  // (sparse_cross_validation.cpp)
  void CrossValidate(const NeighborIndex& index, std::span<const uint32_t> dense,
                     std::span<const uint32_t> order, std::span<const uint8_t> outcome);

 private:
  NeighborIndex IndexOf(std::span<const uint32_t> dense) const {
    return NeighborIndex(DenseIndexPoints(ctx_.plan, ctx_.samples, dense), dense);
  }

  // Adds a job's counters to the report (this run's figures only for `this_run`).
  void Count(const SparseJobCounters& c, bool this_run, bool cross_validation);

  // One step as a batch on the job loop; its journaled jobs that still verify are not redone.
  // `t0`: when the step began (now if negative). (sparse_phase.cpp)
  void RunStep(StepJobs& p, double t0 = -1);

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

}  // namespace prt
