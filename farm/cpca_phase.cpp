// The compression phase for scheme "cpca"; see farm/cpca_phase.h and docs/cpca.md.
#include "farm/cpca_phase.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "farm/collectives.h"
#include "farm/compressed_file.h"
#include "farm/farm_context.h"
#include "farm/progress.h"
#include "farm/sparse_jobs.h"
#include "formats/cpca_transport.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "worker/composed_transport.h"
#include "worker/cpca.h"
#include "worker/transport_compressor.h"

namespace prt {

namespace {

// ---- The CPCA path's collectives, named by what they share, on farm/collectives.h (every rank
// calls each in the same order).

// ComputeCpca's reductions over the ranks (worker/cpca.h): fixed-point sums (exact, so the same
// for any number of ranks) and maxima, on every rank.
class CollectiveCpcaReducer final : public CpcaReducer {
 public:
  explicit CollectiveCpcaReducer(const Collectives& c) : c_(c) {}
  void SumInt64(std::span<int64_t> v) override { c_.SumEverywhere(v, "sum the CPCA sums"); }
  void MaxDouble(std::span<double> v) override { c_.MaxEverywhere(v, "the CPCA maxima"); }

 private:
  const Collectives& c_;
};

// Rank 0 sends rank r its rows (tag 7401); rank r receives them into `rows`.
void SendRowsToRank(const std::vector<float>& buf, int r, const Collectives& c) {
  c.SendTo(r, buf.data(), buf.size() * sizeof(float), 7401, "send CPCA rows");
}
void ReceiveRowsFromRank0(std::vector<float>& rows, const Collectives& c) {
  c.ReceiveFrom(0, rows.data(), rows.size() * sizeof(float), 7401, "receive CPCA rows");
}

// Rank 0's combination pairs on every rank: meta = {slots per sample (0: none), pair count}.
void ShareCombinationPairs(uint64_t (&meta)[2], std::vector<uint32_t>& pairs,
                           const Collectives& c) {
  c.ShareValueFromRank0(meta, "share the CPCA sparse structure");
  if (meta[0] > 0) {
    pairs.resize(meta[1]);
    c.ShareFromRank0(pairs.data(), pairs.size() * sizeof(uint32_t), "share the CPCA combinations");
  }
}

// Every row's cluster id and its S coefficients on rank 0, in row order (rank r holds the rows
// CpcaRowRange(R, r, size) gives it); `all_*` are only written on rank 0.
void GatherClustersAndCoefficients(const CpcaLocalResult& mine, uint64_t R, uint32_t S,
                                   uint64_t count, std::vector<uint32_t>& all_clusters,
                                   std::vector<int32_t>& all_coefficients, const Collectives& c) {
  const int size = c.size();
  std::vector<uint64_t> counts(static_cast<std::size_t>(size));
  for (int r = 0; r < size; ++r) {
    const auto [f, l] = CpcaRowRange(R, r, size);
    counts[static_cast<std::size_t>(r)] = l - f;
  }
  c.ConcatenateOnRank0(std::span<const uint32_t>(mine.cluster_of.data(), count),
                       std::span<uint32_t>(all_clusters), counts, "gather the CPCA clusters");
  if (S > 0) {
    if (static_cast<uint64_t>(R) * S > static_cast<uint64_t>(INT_MAX))
      throw std::runtime_error("CPCA: more than 2^31 coefficients");
    for (uint64_t& k : counts) k *= S;
    c.ConcatenateOnRank0(std::span<const int32_t>(mine.coefficients.data(), count * S),
                         std::span<int32_t>(all_coefficients), counts,
                         "gather the CPCA coefficients");
  }
}

// Huang §6's input from the sparse phase's run/sparse/combination.bin (its pairs, `slots` per
// sample): a sample with no pair is dense (or a fallback, sampled densely); the others list the
// dense samples they combine, largest |α| first.
CpcaSparseStructure StructureFromPairs(const std::vector<uint32_t>& pairs, uint64_t samples,
                                       uint64_t slots, uint32_t channels) {
  std::vector<uint8_t> dense(samples, 1);
  std::vector<std::vector<uint32_t>> nb(samples);
  for (uint64_t s = 0; s < samples; ++s) {
    std::vector<std::pair<float, uint32_t>> by_weight;
    for (uint64_t k = 0; k < slots; ++k) {
      const uint32_t u = pairs[(s * slots + k) * 2];
      if (u == kNoSample) continue;
      float a;
      std::memcpy(&a, &pairs[(s * slots + k) * 2 + 1], 4);
      by_weight.push_back({-std::fabs(a), u});
    }
    if (by_weight.empty()) continue;
    dense[s] = 0;
    std::sort(by_weight.begin(), by_weight.end());
    for (const auto& p : by_weight) nb[s].push_back(p.second);
  }
  return CpcaSparseStructure::Of(dense, nb, channels);
}

// ---- The CPCA path's steps, in the order RunCpcaCompression runs them.

// The rows this rank holds (CpcaRowRange: [first, first + count) of R, d floats each): read by
// itself where it sees the run folder, else read by rank 0 and sent. Returns the bytes rank 0
// sent (0 elsewhere).
uint64_t ReadRowShare(const FarmContext& ctx, uint64_t R, uint32_t d, uint64_t first,
                      uint64_t count, bool every_rank_reads,
                      std::unique_ptr<ComposedTransport>& reader,
                      const std::function<std::unique_ptr<ComposedTransport>()>& open_reader,
                      std::vector<float>& rows) {
  const int rank = ctx.rank, size = ctx.size;
  uint64_t bytes_sent = 0;
  if (every_rank_reads) {
    if (!reader) reader = open_reader();
    if (reader->rows() != R)
      throw InputError(ctx.folder.transport, "rank " + std::to_string(rank) + " reads " +
                                                 std::to_string(reader->rows()) + " rows, rank 0 " +
                                                 std::to_string(R));
    if (count > 0) reader->ReadRows(first, count, rows.data());
  } else if (rank == 0) {
    if (count > 0) reader->ReadRows(first, count, rows.data());
    std::vector<float> buf;
    for (int r = 1; r < size; ++r) {
      const auto [f, l] = CpcaRowRange(R, r, size);
      buf.resize((l - f) * d);
      if (l > f) reader->ReadRows(f, l - f, buf.data());
      SendRowsToRank(buf, r, ctx.collectives);
      bytes_sent += buf.size() * sizeof(float);
    }
  } else {
    ReceiveRowsFromRank0(rows, ctx.collectives);
  }
  return bytes_sent;
}

// Huang §6 where the rows came from the sparse method (rank 0 reads the combinations and shares
// them); null otherwise.
std::unique_ptr<CpcaSparseStructure> ShareSparseStructure(const FarmContext& ctx,
                                                          const CompressedTransportHeader& header) {
  std::unique_ptr<CpcaSparseStructure> sparse;
  std::vector<uint32_t> pairs;
  uint64_t meta[2] = {0, 0};  // has structure, pair count
  std::string comb = ctx.folder.SparseCombinationFile();
  if (ctx.rank == 0 && header.cpca_method == CpcaMethod::kDenseRecluster &&
      std::filesystem::exists(comb)) {
    uint64_t slots = 0;
    pairs = ReadCombinationFile(comb, header.spatial_count(), slots);
    meta[0] = slots;
    meta[1] = pairs.size();
  }
  ShareCombinationPairs(meta, pairs, ctx.collectives);
  if (meta[0] > 0) {
    sparse = std::make_unique<CpcaSparseStructure>(
        StructureFromPairs(pairs, header.spatial_count(), meta[0], header.channels));
  }
  return sparse;
}

// What rank 0's report needs besides the file: how the rows travelled, the slowest rank's
// seconds (read, row transform, clustering) and the distance evaluations of all ranks.
struct CpcaFigures {
  bool every_rank_reads = false;
  uint64_t rank0_rows_bytes = 0;  // the rows rank 0 holds itself
  uint64_t bytes_sent = 0;
  double maxs[3] = {};
  uint64_t evals_all = 0;
  bool sparse = false;  // a sparse structure was given
};

// Rank 0 writes transport.prtc durably, then report.json "compression" (with its "cpca" part)
// and the summary line. `tw`: when the gathering began; `start`: when the phase did.
void WriteCpcaFileAndReport(FarmContext& ctx, const CpcaTransport& t, const CpcaStats& st,
                            const CpcaFigures& fig, double tw, double start) {
  const FarmOptions& options = ctx.options;
  const CompressedTransportHeader& header = t.header;
  CompressionFarmReport& rep = ctx.report.compression;
  const uint64_t R = header.sample_count;
  const uint32_t S = header.cpca_bases;
  const std::vector<uint8_t> file = EncodeCpcaTransport(t);
  WriteCompressedFile(ctx, file);
  rep.write_seconds = FarmNow() - tw;
  rep.every_rank_reads = fig.every_rank_reads && ctx.size > 1;
  rep.rank0_bytes_read = fig.rank0_rows_bytes + (fig.every_rank_reads ? 0 : fig.bytes_sent);
  rep.rank0_bytes_sent = fig.bytes_sent;
  rep.bytes_moved = fig.bytes_sent;
  rep.read_seconds = fig.maxs[0];
  rep.row_transform_seconds = fig.maxs[1];
  rep.compress_seconds = fig.maxs[2];
  rep.terms = t.term_count() + t.coefficients.size();
  rep.compressed_bytes = file.size();
  rep.raw_kept = !options.discard_raw;
  rep.relative_frobenius_error = st.relative_error;
  rep.cpca.enabled = true;
  rep.cpca.clusters = header.cpca_clusters;
  rep.cpca.bases = S;
  rep.cpca.method = fig.sparse && st.rows_dense_pass < R ? "dense-recluster" : "standard";
  rep.cpca.rows_dense_pass = st.rows_dense_pass;
  rep.cpca.lbg_iterations = st.lbg_iterations;
  rep.cpca.distance_evaluations = fig.evals_all;
  rep.cpca.empty_clusters = st.empty_clusters;
  rep.cpca.seconds_dense = st.seconds_dense;
  rep.cpca.seconds_recluster = st.seconds_recluster;
  rep.cpca.basis_terms = t.term_count();
  rep.wall_seconds = FarmNow() - start;
  ctx.run_eta.StepFinished("compress");
  rep.enabled = true;
  if (!options.quiet)
    spdlog::info(
        "compression: {} in {}: {:.1f} MB raw -> {:.2f} MB ({:.3f}% of raw), relative Frobenius "
        "error {:.3f}%, cpca {} ({} clusters x {} bases, {} LBG iterations over {} of {} rows, "
        "{} basis terms)",
        ctx.folder.compressed, Progress::FormatDuration(rep.wall_seconds),
        static_cast<double>(rep.raw_bytes) / 1e6, static_cast<double>(rep.compressed_bytes) / 1e6,
        100 * rep.Ratio(), 100 * rep.relative_frobenius_error, rep.cpca.method, rep.cpca.clusters,
        rep.cpca.bases, rep.cpca.lbg_iterations, rep.cpca.rows_dense_pass, R, rep.cpca.basis_terms);
}

}  // namespace

// The rows read and row-transformed (§4.1), clustered by ComputeCpca with MPI reductions, every
// row's cluster id and coefficients gathered on rank 0, which writes and reports (cpca_phase.h).
void RunCpcaCompression(FarmContext& ctx, const CompressedTransportHeader& header,
                        std::unique_ptr<ComposedTransport>& reader,
                        const std::function<std::unique_ptr<ComposedTransport>()>& open_reader,
                        double start) {
  const FarmOptions& options = ctx.options;
  const int rank = ctx.rank, size = ctx.size;
  CompressionFarmReport& rep = ctx.report.compression;
  const uint64_t R = header.sample_count;
  const uint32_t d = header.column_count();
  const auto [first, last] = CpcaRowRange(R, rank, size);
  const uint64_t count = last - first;
  if (rank == 0) ctx.run_eta.StepStarted("compress");
  if (rank == 0 && !options.quiet)
    spdlog::info(
        "compression: {} rows x {} columns ({:.1f} MB), cpca scheme: {} clusters x {} bases, {} "
        "rank(s), {:.1f} MB of rows per rank",
        R, d, static_cast<double>(rep.raw_bytes) / 1e6, header.cpca_clusters, header.cpca_bases,
        size, static_cast<double>(count * d * sizeof(float)) / 1e6);

  // CPCA passes over its rows many times: they stay in memory whatever --memory-budget says.
  if (count * d * sizeof(float) > options.memory_budget_bytes)
    spdlog::warn(
        "rank {}: cpca holds this rank's {:.1f} MB of rows in memory, above --memory-budget "
        "({:.1f} MB); more ranks share them",
        rank, static_cast<double>(count * d * sizeof(float)) / 1e6,
        static_cast<double>(options.memory_budget_bytes) / 1e6);
  // Rows: each rank reads its own where it sees the run folder; else rank 0 reads and sends.
  const double tr = FarmNow();
  std::vector<float> rows(count * d);
  const bool every_rank_reads = ctx.rows_in_place || size == 1;
  const uint64_t bytes_sent =
      ReadRowShare(ctx, R, d, first, count, every_rank_reads, reader, open_reader, rows);
  const double read_seconds = FarmNow() - tr;
  const double tt = FarmNow();
  CompressionOptions copt;
  copt.row_wavelet = header.row_wavelet;
  if (count > 0) PrepareRows(header, copt, rows.data(), count);
  const double transform_seconds = FarmNow() - tt;

  const std::unique_ptr<CpcaSparseStructure> sparse = ShareSparseStructure(ctx, header);

  ProgressOptions po = FarmProgressOptions(ctx, "LBG iterations", false);
  std::unique_ptr<Progress> progress;
  if (rank == 0) progress = std::make_unique<Progress>("cpca", 1, po);
  int reported = 0;
  CollectiveCpcaReducer reducer(ctx.collectives);
  const CpcaOptions o = CpcaOptionsFrom(header);
  const double tc = FarmNow();
  CpcaLocalResult mine = ComputeCpca(header, o, rows.data(), first, count, reducer, sparse.get(),
                                     [&](int done, int total) {
                                       if (!progress) return;
                                       if (reported == 0)
                                         progress = std::make_unique<Progress>("cpca", total, po);
                                       progress->Advance(static_cast<uint64_t>(done - reported));
                                       reported = done;
                                     });
  if (progress) progress->Finish();
  const double compress_seconds = FarmNow() - tc;
  rows = std::vector<float>();

  // Gather the rows' cluster ids and coefficients on rank 0.
  const double tw = FarmNow();
  const uint32_t S = header.cpca_bases;
  CpcaTransport t;
  if (rank == 0) {
    t.header = header;
    t.cluster_of.resize(R);
    t.coefficients.resize(R * S);
  }
  GatherClustersAndCoefficients(mine, R, S, count, t.cluster_of, t.coefficients, ctx.collectives);
  CpcaFigures fig;
  fig.evals_all = mine.stats.distance_evaluations;
  ctx.collectives.SumOnRank0(std::span<uint64_t>(&fig.evals_all, 1), "sum the CPCA distances");
  fig.maxs[0] = read_seconds;
  fig.maxs[1] = transform_seconds;
  fig.maxs[2] = compress_seconds;
  ctx.collectives.MaxOnRank0(std::span<double>(fig.maxs), "the slowest rank's CPCA seconds");
  if (rank != 0) return;

  t.clusters = std::move(mine.clusters);
  fig.every_rank_reads = every_rank_reads;
  fig.rank0_rows_bytes = count * d * sizeof(float);
  fig.bytes_sent = bytes_sent;
  fig.sparse = sparse != nullptr;
  WriteCpcaFileAndReport(ctx, t, mine.stats, fig, tw, start);
}

}  // namespace prt
