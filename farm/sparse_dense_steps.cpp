// The sparse phase's steps that choose the dense set (Huang & Ramamoorthi 2010 §4; docs/farm.md,
// "Sparse method"): dense rows (§4.2) and the local rank of candidates (§4.1), as batches of jobs
// on the job loop (FarmSparseSteps, farm/sparse_steps.h).
#include <cstring>
#include <filesystem>
#include <unordered_map>

#include "farm/sparse_steps.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/local_rank.h"

namespace prt {

namespace fs = std::filesystem;

// Dense rows (§4.2): T into the transport file, visibility + features into dense_aux.bin; each
// dense row's downsampled row (§4.1's local rank works on them) kept for the rank steps.
void FarmSparseSteps::Dense(const std::string& name, std::span<const uint32_t> ids) {
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
      RowsStage(ctx_).writer->ReadRows(s, 1, tr.data() + i * T_);
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
    if (r.transport.size() != c * T_ || r.visibility.size() != c * T_ || r.feature.size() != c * T_)
      throw RankFailure("a dense job came back with the wrong number of rows");
    std::vector<char> buf(aux_row);
    for (std::size_t i = 0; i < c; ++i) {
      const uint32_t s = ids[r.header.first + i];
      RowsStage(ctx_).writer->WriteRows(s, 1, r.transport.data() + i * T_);
      std::memcpy(buf.data(), r.visibility.data() + i * T_, T_ * sizeof(float));
      std::memcpy(buf.data() + T_ * sizeof(float), r.feature.data() + i * T_, T_);
      aux_->Write(buf.data(), aux_row, s * aux_row);
      apply(s, r.transport.data() + i * T_);
    }
    rows_written = c;
    return DenseResultChecksum(c, T_, r.transport.data(), r.visibility.data(), r.feature.data());
  };
  p.sync = [&] {
    RowsStage(ctx_).writer->Sync();
    aux_->Sync();
    if (low_file_) low_file_->Sync();
  };
  RunStep(p);
}

// The local rank of candidates (§4.1): each candidate's dense neighbours within the radius, their
// downsampled rows, and the rank of that local matrix as the candidate's weight (int32 per
// candidate in run/sparse/<name>.bin).
std::vector<double> FarmSparseSteps::Rank(const std::string& name, int,
                                          std::span<const uint32_t> dense,
                                          std::span<const uint32_t> cand) {
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
      for (uint32_t d : index.RadiusSearch(ctx_.plan.SearchPosition(ctx_.samples[cand[i]]),
                                           ctx_.plan.radius, ctx_.plan.max_neighbors)) {
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

}  // namespace prt
