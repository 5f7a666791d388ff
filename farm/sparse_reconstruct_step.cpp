// The sparse phase's reconstruction step (Huang & Ramamoorthi 2010 §5; docs/farm.md, "Sparse
// method"): every sample that is not dense reconstructed from its dense neighbours, in Morton
// order, as batches of jobs on the job loop (FarmSparseSteps, farm/sparse_steps.h); the outcomes
// in run/sparse/sparse_outcome.bin, the combinations (§5, Eq. 4) in combination_order.bin.
#include <algorithm>
#include <cstring>
#include <filesystem>

#include "farm/sparse_steps.h"
#include "vocabulary/errors.h"

namespace prt {

namespace fs = std::filesystem;

std::vector<uint32_t> FarmSparseSteps::Reconstruct(const std::string& name,
                                                   std::span<const uint32_t> dense,
                                                   std::span<const uint8_t> is_dense) {
  const double t0 = FarmNow();
  const NeighborIndex index = IndexOf(dense);
  index_seconds_ += FarmNow() - t0;
  // Spatially coherent order: a job's vertices share most of their neighbours.
  std::vector<std::pair<uint32_t, uint32_t>> keyed;
  for (uint32_t s = 0; s < N_; ++s) {
    if (!is_dense[s]) {
      keyed.push_back(
          {MortonKey(ctx_.samples[s].position, ctx_.geometry.bounds_min, ctx_.geometry.bounds_max),
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
      RowsStage(ctx_).writer->ReadRows(order[e.rows.first + i], 1, rows.data() + rows.size() - T_);
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
      RowsStage(ctx_).writer->WriteRows(order[r.header.first + i], 1, r.transport.data() + k * T_);
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
    RowsStage(ctx_).writer->Sync();
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

std::string FarmSparseSteps::MakeSparseJob(SparseJobHeader& h, std::string prefix,
                                           const NeighborIndex& index,
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
    RowsStage(ctx_).writer->ReadRows(d, 1, job.transport.data() + k * T_);
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

}  // namespace prt
