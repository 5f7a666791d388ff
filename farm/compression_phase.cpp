// prt-farm's compression phase (Cheslack-Postava et al. 2008 §4.4 steps 2–5); see
// compression_phase.h and docs/farm-compression.md.
#include "farm/compression_phase.h"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <span>

#include "farm/collectives.h"
#include "farm/compressed_file.h"
#include "farm/cpca_phase.h"
#include "farm/distributed_transpose.h"
#include "farm/farm_context.h"
#include "farm/mpi_support.h"
#include "farm/progress.h"
#include "formats/compressed_transport.h"
#include "formats/transport_file.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/huge_pages.h"
#include "vocabulary/scene.h"
#include "worker/column_order.h"
#include "worker/composed_transport.h"
#include "worker/transport_compressor.h"
#include "worker/transport_error_estimate.h"

namespace prt {

namespace fs = std::filesystem;

namespace {

// The compression options every rank needs besides the header (PrepareRows' per-row budget).
struct OptionsPod {
  uint8_t row_wavelet, column_wavelet, scheme, bits;
  uint32_t terms_per_column;
  double keep_fraction;
  uint64_t dither_seed;
};

// ---- The phase's collectives, named by what they share, on farm/collectives.h (every rank
// calls each, in this order, or none: farm/farm_context.h, CollectiveStop). The transpose's own
// are in farm/distributed_transpose.cpp, the CPCA path's in farm/cpca_phase.cpp.

// Rank 0's setup outcome {exit code, rows per file block, header bytes} on every rank.
void ShareSetupOutcome(uint64_t (&setup)[3], const Collectives& c) {
  c.ShareValueFromRank0(setup, "share the compression setup");
}

// Rank 0's encoded header (`bytes` header bytes) and options on every rank.
void ShareHeaderAndOptions(std::vector<uint8_t>& header_bytes, uint64_t bytes, OptionsPod& pod,
                           const Collectives& c) {
  header_bytes.resize(bytes);
  c.ShareFromRank0(header_bytes.data(), header_bytes.size(), "share the compressed header");
  c.ShareValueFromRank0(pod, "share the compression options");
}

// Rank 0's estimate lights (`rank0_lights`, ignored elsewhere) on every rank, each an n × n
// cubemap.
std::vector<CubemapRgb> ShareEstimateLights(const std::vector<CubemapRgb>& rank0_lights, int n,
                                            const Collectives& c) {
  uint64_t count = rank0_lights.size();
  c.ShareValueFromRank0(count, "share the estimate lights");
  std::vector<CubemapRgb> lights(static_cast<std::size_t>(count));
  for (std::size_t l = 0; l < lights.size(); ++l) {
    CubemapRgb& light = lights[l];
    light = c.rank() == 0 ? rank0_lights[l] : CubemapRgb{};
    light.n = n;
    for (int k = 0; k < 3; ++k) {
      std::vector<float>& ch = light.Channel(k);
      ch.resize(light.TexelCount());
      c.ShareFromRank0(ch.data(), ch.size() * sizeof(float), "share the estimate lights");
    }
  }
  return lights;
}

// The global budget's magnitude histogram summed over all ranks, on every rank. Integer counts:
// the same sum, hence the same threshold, for any number of ranks.
std::vector<uint64_t> SumHistograms(const std::vector<uint64_t>& histogram, const Collectives& c) {
  std::vector<uint64_t> all = histogram;
  c.SumEverywhere(std::span<uint64_t>(all), "sum the magnitude histograms");
  return all;
}

// The estimate stage's Σ B² summed over the ranks' rows, on rank 0 (a report figure: double sums
// in any order; the other ranks get their own back).
std::vector<double> SumRadianceNorms(const std::vector<double>& mine, const Collectives& c) {
  std::vector<double> all = mine;
  c.SumOnRank0(std::span<double>(all), "sum the radiance norms");
  return all;
}

// Every rank's encoded column block size, on rank 0 (empty elsewhere).
std::vector<uint64_t> GatherColumnBlockSizes(uint64_t my_size, const Collectives& c) {
  return c.GatherOnRank0(std::span<const uint64_t>(&my_size, 1), "gather the column block sizes");
}

// A rank's encoded column block travels to rank 0 (tag 7301).
void SendColumnBlockToRank0(const std::vector<uint8_t>& bytes, const Collectives& c) {
  c.SendTo(0, bytes.data(), bytes.size(), 7301, "send the compressed columns");
}
// Rank 0's side: rank r's `size` bytes.
std::vector<uint8_t> ReceiveColumnBlock(int r, uint64_t size, const Collectives& c) {
  std::vector<uint8_t> in(static_cast<std::size_t>(size));
  c.ReceiveFrom(r, in.data(), in.size(), 7301, "receive the compressed columns");
  return in;
}

// The global budget's first pass keeps each rank's transformed column blocks (and depths) until
// the threshold over all ranks is known: in memory up to `budget` bytes, beyond it appended to a
// file in the spill folder and read back in the same order.
class TransformedBlockStash {
 public:
  TransformedBlockStash(std::string dir, uint64_t budget) : dir_(std::move(dir)), budget_(budget) {}
  ~TransformedBlockStash() {
    if (file_) std::fclose(file_);
    if (!path_.empty()) {
      std::error_code ec;
      fs::remove(path_, ec);
    }
  }
  TransformedBlockStash(const TransformedBlockStash&) = delete;
  TransformedBlockStash& operator=(const TransformedBlockStash&) = delete;

  void Add(uint32_t first, uint32_t count, std::vector<float>& columns,
           std::vector<uint8_t>& depths) {
    const uint64_t bytes = columns.size() * sizeof(float) + depths.size();
    Entry e{first, count, columns.size(), {}, {}};
    if (in_memory_ + bytes <= budget_) {
      in_memory_ += bytes;
      e.columns.swap(columns);
      e.depths.swap(depths);
    } else {
      if (!file_) {
        path_ = (fs::path(dir_) / "transformed-columns.bin").string();
        file_ = std::fopen(path_.c_str(), "w+b");
        if (!file_) throw FileIoError(dir_, "cannot create " + path_);
      }
      if (std::fwrite(columns.data(), sizeof(float), columns.size(), file_) != columns.size() ||
          std::fwrite(depths.data(), 1, depths.size(), file_) != depths.size())
        throw FileIoError(dir_, "cannot write " + path_);
      spilled_ += bytes;
    }
    entries_.push_back(std::move(e));
  }
  uint64_t spilled_bytes() const { return spilled_; }

  // Calls f(first, count, columns, depths) for every block in the order added.
  template <class F>
  void Replay(F&& f) {
    if (file_ && std::fseek(file_, 0, SEEK_SET) != 0)
      throw FileIoError(dir_, "cannot rewind " + path_);
    for (Entry& e : entries_) {
      if (e.columns.size() != e.floats) {
        e.columns.resize(e.floats);
        e.depths.resize(e.count);
        if (std::fread(e.columns.data(), sizeof(float), e.floats, file_) != e.floats ||
            std::fread(e.depths.data(), 1, e.count, file_) != e.count)
          throw FileIoError(dir_, "cannot read back " + path_);
      }
      f(e.first, e.count, e.columns.data(), e.depths.data());
      e.columns = std::vector<float>();
      e.depths = std::vector<uint8_t>();
    }
  }

 private:
  struct Entry {
    uint32_t first, count;
    std::size_t floats;
    std::vector<float> columns;
    std::vector<uint8_t> depths;
  };
  std::string dir_;
  uint64_t budget_;
  uint64_t in_memory_ = 0, spilled_ = 0;
  std::vector<Entry> entries_;
  std::string path_;
  std::FILE* file_ = nullptr;
};

double SquaredNorm(const float* v, std::size_t n) {
  double s = 0;
  for (std::size_t i = 0; i < n; ++i) s += double(v[i]) * v[i];
  return s;
}

// ---- The phase's steps, in the order Compress runs them (docs/farm-compression.md, "Design").

// T⁰ + the bounces (docs/interreflection.md), as the compression reads them: one row of T per
// sample, the direct and indirect transport summed.
std::unique_ptr<ComposedTransport> OpenComposedRows(const FarmContext& ctx) {
  return std::make_unique<ComposedTransport>(
      ctx.folder.transport,
      IndirectFiles(ctx.folder, ctx.params.bounces, ctx.params.path_estimator != 0,
                    ctx.params.image != 0),
      ctx.params.channels);
}

// What rank 0 sets up and every rank then shares ("Design" 1): the rows' reader, the header
// (MakeCompressedHeader's, from the plan setup keyed the compression stage with) and the options.
struct CompressionSetup {
  std::unique_ptr<ComposedTransport> reader;  // rank 0; every rank where ranks read their own
  CompressedTransportHeader header;
  CompressionOptions copt;
  OptionsPod pod{};
  std::vector<uint8_t> header_bytes;
  uint64_t setup[3] = {0, 0, 0};  // exit code, rows per file block, header bytes
};

// Step 1 on rank 0: the rows' file, the scene's [compression] settings, the spatial domain,
// checked against each other. A failure is recorded in s.setup[0] (the exit code) and the report.
void SetUpOnRank0(FarmContext& ctx, CompressionSetup& s) {
  const RunFolder& folder = ctx.folder;
  try {
    s.reader = OpenComposedRows(ctx);
    // The plan setup keyed the compression stage with (nothing is read again but the rows).
    const CompressionPlan* keyed = ctx.results.Find<CompressionPlan>();
    if (!keyed) throw std::logic_error("compression phase without a plan");
    CompressionPlan plan = *keyed;
    if (plan.header.cubemap_n != s.reader->direct_info().cubemap_n)
      throw InputError(folder.transport,
                       "cubemap n " + std::to_string(s.reader->direct_info().cubemap_n) +
                           ", but the run's is " + std::to_string(plan.header.cubemap_n));
    if (plan.header.sample_count != s.reader->rows())
      throw InputError(folder.transport,
                       std::to_string(s.reader->rows()) + " rows, but " + folder.geometry +
                           " has " + std::to_string(plan.header.sample_count) + " spatial samples");
    s.copt = plan.options;
    s.header = std::move(plan.header);
    s.header_bytes = EncodeHeader(s.header);
    s.pod = {static_cast<uint8_t>(s.copt.row_wavelet),
             static_cast<uint8_t>(s.copt.column_wavelet),
             static_cast<uint8_t>(s.copt.scheme),
             static_cast<uint8_t>(s.copt.bits),
             s.copt.terms_per_column,
             s.copt.keep_fraction,
             s.copt.dither_seed};
    s.setup[1] = s.reader->direct_info().rows_per_block;
    s.setup[2] = s.header_bytes.size();
  } catch (...) {
    std::string message;
    s.setup[0] =
        static_cast<uint64_t>(ExitCodeOf(std::current_exception(), message, "compression phase"));
    spdlog::error("compression: {}", message);
    ctx.report.error = message;
  }
}

// Step 1 on every rank: rank 0's header and options, decoded where they did not come from.
void ShareSetup(const FarmContext& ctx, CompressionSetup& s) {
  ShareHeaderAndOptions(s.header_bytes, s.setup[2], s.pod, ctx.collectives);
  if (ctx.rank != 0) {
    const OptionsPod& pod = s.pod;
    s.header = DecodeHeader(s.header_bytes, "compressed transport header from rank 0");
    s.copt.row_wavelet = static_cast<RowWavelet>(pod.row_wavelet);
    s.copt.column_wavelet = static_cast<ColumnWavelet>(pod.column_wavelet);
    s.copt.scheme = static_cast<CompressionScheme>(pod.scheme);
    s.copt.bits = pod.bits;
    s.copt.terms_per_column = pod.terms_per_column;
    s.copt.keep_fraction = pod.keep_fraction;
    s.copt.dither_seed = pod.dither_seed;
  }
}

// The report's settings, before any work (report.json "compression").
void StartReport(FarmContext& ctx, const CompressedTransportHeader& header) {
  CompressionFarmReport& rep = ctx.report.compression;
  const uint64_t rows = header.sample_count;
  const uint32_t cols = header.column_count();
  rep.ranks = ctx.size;
  rep.scheme = ToString(header.scheme);
  rep.row_wavelet = ToString(header.row_wavelet);
  rep.column_wavelet = ToString(header.column_wavelet);
  rep.bits = header.bits;
  rep.keep_fraction = header.keep_fraction;
  rep.memory_budget_bytes = ctx.options.memory_budget_bytes;
  rep.raw_bytes = rows * cols * sizeof(float);
}

// How the rows reach the transpose ("Design" 2): this rank's spill folder and column block width,
// who reads the rows, and the rows per chunk.
struct TransposePlan {
  BlockSpillOptions spill;
  fs::path spill_dir;
  TransposeReading reading;
  uint64_t chunk = 0;
};

TransposePlan PlanTranspose(const FarmContext& ctx, CompressionSetup& s) {
  const FarmOptions& options = ctx.options;
  const RunFolder& folder = ctx.folder;
  const int rank = ctx.rank;
  const int size = ctx.size;
  const uint64_t rows = s.header.sample_count;
  const uint32_t cols = s.header.column_count();
  TransposePlan p;
  // Spill folder of this rank: inside the run folder when this rank can write there (shared
  // or same-named local folder), else the system's temporary folder.
  BlockSpillOptions& spill = p.spill;
  spill.memory_budget_bytes = std::max<uint64_t>(1, options.memory_budget_bytes / 2);
  // A column block leaves the transposer as columns × rows floats and the column compression
  // holds a transformed copy of it: both within a quarter of the budget (at least one column,
  // at most 256; columns are compressed independently, so the width changes no byte). A
  // million rows at n = 32 would otherwise hold 2 × 1 GiB whatever the budget.
  spill.columns_per_block = static_cast<uint32_t>(std::clamp<uint64_t>(
      options.memory_budget_bytes / 4 / std::max<uint64_t>(1, 2 * rows * sizeof(float)), 1, 256));
  fs::path& spill_dir = p.spill_dir;
  spill_dir = fs::path(folder.dir) / ("compress-spill-rank" + std::to_string(rank));
  std::error_code ec;
  fs::remove_all(spill_dir, ec);  // what a killed run left there
  fs::create_directories(spill_dir, ec);
  if (ec) {
    spill_dir = fs::temp_directory_path() /
                ("prt-farm-spill-" + std::to_string(::getpid()) + "-" + std::to_string(rank));
    fs::create_directories(spill_dir);
  }
  spill.spill_dir = spill_dir.string();

  // Where every rank sees the run folder, each reads its own share of the rows (no row passes
  // through rank 0) and a chunk is every rank's share of the budget; else rank 0 reads each
  // chunk and scatters it.
  TransposeReading& reading = p.reading;
  reading.every_rank_reads = ctx.rows_in_place && size > 1;
  reading.align = reading.every_rank_reads ? s.setup[1] : 1;  // whole blocks when ranks read
  if (reading.every_rank_reads && rank != 0) {
    s.reader = OpenComposedRows(ctx);
    if (s.reader->rows() != rows)
      throw InputError(folder.transport, "rank " + std::to_string(rank) + " reads " +
                                             std::to_string(s.reader->rows()) + " rows, rank 0 " +
                                             std::to_string(rows));
  }
  p.chunk = std::min<uint64_t>(
      rows, ChunkRows(uint64_t{cols} * sizeof(float), static_cast<uint32_t>(s.setup[1]),
                      options.memory_budget_bytes, rows) *
                (reading.every_rank_reads ? static_cast<uint64_t>(size) : 1));
  return p;
}

// The estimate stage's Σ B² (farm/estimate_phase.cpp) from the rows as they pass: rank 0
// loads the lights and every rank accumulates over its share of the rows. Null without the
// estimate stage.
std::unique_ptr<RadianceNormAccumulator> StartRadianceNorms(
    FarmContext& ctx, const CompressedTransportHeader& header) {
  if (!ctx.params.run_estimate) return nullptr;
  // Rank 0's lights, kept for the estimate phase with the norms (a typed result).
  EstimateLights* estimate = ctx.rank == 0 ? &LoadEstimateLights(ctx) : nullptr;
  const std::vector<CubemapRgb> none;
  std::vector<CubemapRgb> lights = ShareEstimateLights(
      estimate ? estimate->lights : none, static_cast<int>(header.cubemap_n), ctx.collectives);
  return std::make_unique<RadianceNormAccumulator>(std::move(lights), ctx.RowGroups(),
                                                   ctx.params.channels, ctx.SampleGroups());
}

// What a rank's transpose and column compression leave: its compressed columns and the figures
// the report sums or maximises over the ranks.
struct RankColumns {
  std::vector<CompressedColumn> mine;
  TransposeStats st;
  uint64_t terms = 0;
  double row_energy = 0, row_dropped = 0;  // this rank's rows
  double column_error = 0;                 // this rank's columns
};

// The global budget's second pass ("Design" 3): the threshold from the histograms of all ranks
// (ThresholdFromHistogram), then every stashed block quantised against it (QuantiseColumnBlock).
void QuantiseStashedBlocks(const FarmContext& ctx, const CompressedTransportHeader& header,
                           std::vector<uint64_t>& histogram, TransformedBlockStash& stash,
                           RankColumns& out) {
  const std::vector<uint64_t> all = SumHistograms(histogram, ctx.collectives);
  const float threshold = ThresholdFromHistogram(all.data(), GlobalTermBudget(header));
  const double tq = FarmNow();
  stash.Replay([&](uint32_t first, uint32_t count, const float* columns, const uint8_t* depths) {
    std::vector<CompressedColumn> block =
        QuantiseColumnBlock(header, first, count, columns, depths, threshold);
    out.column_error += ColumnBlockError(header, first, count, columns, depths, block);
    for (CompressedColumn& c : block) {
      out.terms += c.index.size();
      out.mine.push_back(std::move(c));
    }
  });
  out.st.sink_seconds += FarmNow() - tq;
  out.st.bytes_spilled += stash.spilled_bytes();
}

// Steps 2–3 ("Design" 2–3; Cheslack-Postava et al. 2008 §4.4 steps 2–4): the rows read in
// chunks and row-transformed (§4.1, PrepareRows), transposed over the ranks
// (DistributedTranspose), and every column block this rank owns compressed (§4.2–4.3,
// CompressColumnBlock; with the global budget transformed, histogrammed and stashed, then
// quantised). Also measures ‖T‖² and what the compression drops (ColumnBlockError), and feeds
// `norms` (may be null) the rows.
RankColumns TransposeAndCompress(FarmContext& ctx, CompressionSetup& s, const TransposePlan& plan,
                                 RadianceNormAccumulator* norms, Progress& progress,
                                 const ProgressOptions& po) {
  const FarmOptions& options = ctx.options;
  const int rank = ctx.rank;
  const CompressedTransportHeader& header = s.header;
  const uint64_t rows = header.sample_count;
  const uint32_t cols = header.column_count();
  RankColumns out;
  const bool truncates_rows =
      header.scheme == CompressionScheme::k2D && header.budget == CompressionBudget::kColumn;
  const auto owned = OwnedColumns(cols, rank, ctx.size);
  ProgressOptions pc = po;
  pc.unit = "columns of rank 0";
  std::optional<Progress> col_progress;
  // Global budget: first pass transforms and histograms, the quantisation waits for the
  // threshold over all ranks (docs/compression.md).
  const bool global = header.budget == CompressionBudget::kGlobal;
  std::vector<uint64_t> histogram(global ? kMagnitudeBins : 0, 0);
  TransformedBlockStash stash(plan.spill.spill_dir, plan.spill.memory_budget_bytes);
  out.st = DistributedTranspose(
      ctx.comm, rows, cols, plan.chunk,
      [&](uint64_t first, uint64_t count, float* o) { s.reader->ReadRows(first, count, o); },
      [&](uint64_t first, uint64_t count, float* r) {
        if (options.fail_in == "transpose" && rank == options.fail_rank && first > 0)
          ExitAbruptly(rank, "in the transpose's second chunk of rows");
        if (norms) norms->AddRows(first, count, r);
        // ‖T‖² (the orthonormal row transform keeps it) and, for the 2D scheme's per-row
        // budget, what PrepareRows' truncation drops (its terms are disjoint from the kept ones,
        // so its square adds to the column stage's).
        const std::size_t floats = static_cast<std::size_t>(count) * cols;
        const double before = SquaredNorm(r, floats);
        out.row_energy += before;
        PrepareRows(header, s.copt, r, count);
        if (truncates_rows) out.row_dropped += before - SquaredNorm(r, floats);
      },
      plan.spill,
      [&](uint32_t first, uint32_t count, std::vector<float>& columns) {
        if (!col_progress) {
          progress.Finish();
          col_progress.emplace("compress", owned.second - owned.first, pc);
        }
        if (global) {
          std::vector<uint8_t> depths(count);
          TransformColumnBlock(header, count, columns.data(), depths.data());
          AddColumnBlockHistogram(header, first, count, columns.data(), histogram.data());
          stash.Add(first, count, columns, depths);
        } else {
          std::vector<CompressedColumn> block =
              CompressColumnBlock(header, first, count, columns.data());
          out.column_error +=
              ColumnBlockError(header, first, count, columns.data(), nullptr, block);
          for (CompressedColumn& c : block) {
            out.terms += c.index.size();
            out.mine.push_back(std::move(c));
          }
        }
        col_progress->Advance(count);
      },
      rank == 0 ? &progress : nullptr, plan.reading);
  progress.Finish();
  if (col_progress) col_progress->Finish();
  if (global) QuantiseStashedBlocks(ctx, header, histogram, stash, out);
  return out;
}

// The ranks' figures on rank 0: counters summed, seconds maximised (a step takes its slowest
// rank's time), and the error's energies summed.
struct RankTotals {
  uint64_t total[4] = {};     // bytes sent, bytes spilled, runs spilled, terms
  double maxs[7] = {};        // read, row transform, exchange, buffer, merge, sink, transpose
  double energy_all[3] = {};  // ‖T‖², the rows' truncation, the columns' error
};

RankTotals ReduceRankFigures(const RankColumns& c, const Collectives& collectives) {
  RankTotals t;
  const TransposeStats& st = c.st;
  uint64_t* total = t.total;
  total[0] = st.bytes_sent;
  total[1] = st.bytes_spilled;
  total[2] = st.runs_spilled;
  total[3] = c.terms;
  collectives.SumOnRank0(std::span<uint64_t>(t.total), "sum the transpose counters");
  double* secs = t.maxs;
  secs[0] = st.read_seconds;
  secs[1] = st.row_transform_seconds;
  secs[2] = st.exchange_seconds;
  secs[3] = st.buffer_seconds;
  secs[4] = st.merge_seconds;
  secs[5] = st.sink_seconds;
  secs[6] = st.exchange_seconds + st.buffer_seconds + st.merge_seconds;
  collectives.MaxOnRank0(std::span<double>(t.maxs), "the slowest rank's seconds");
  t.energy_all[0] = c.row_energy;
  t.energy_all[1] = c.row_dropped;
  t.energy_all[2] = c.column_error;
  collectives.SumOnRank0(std::span<double>(t.energy_all), "sum the compression's error");
  return t;
}

// Step 4 ("Design" 4), every rank but 0: its columns to rank 0 as one encoded column block.
// Rank 0: every rank's block decoded (validated) in rank order into one compressed transport.
CompressedTransport CollectColumnsOnRank0(const FarmContext& ctx,
                                          const CompressedTransportHeader& header,
                                          std::vector<uint8_t>& bytes,
                                          const std::vector<uint64_t>& sizes) {
  CompressedTransport t;
  if (ctx.rank != 0) {
    SendColumnBlockToRank0(bytes, ctx.collectives);
    return t;
  }
  t.header = header;
  for (int r = 0; r < ctx.size; ++r) {
    std::vector<uint8_t> in;
    if (r == 0) {
      in.swap(bytes);
    } else {
      in = ReceiveColumnBlock(r, sizes[static_cast<std::size_t>(r)], ctx.collectives);
    }
    if (in.empty()) continue;
    for (CompressedColumn& c :
         DecodeColumnBlock(header, in, "column block of rank " + std::to_string(r)).columns)
      t.columns.push_back(std::move(c));
  }
  return t;
}

// Rank 0's report.json "compression" (CompressionFarmReport) once transport.prtc is durable,
// and its summary line. `tw`: when the gathering began; `start`: when the phase did.
void FinishReport(FarmContext& ctx, const CompressedTransport& t, std::size_t file_bytes,
                  const RankTotals& totals, const TransposeStats& st,
                  const TransposeReading& reading, double tw, double start) {
  const FarmOptions& options = ctx.options;
  const RunFolder& folder = ctx.folder;
  const std::string& prtc = folder.compressed;
  CompressionFarmReport& rep = ctx.report.compression;
  const uint64_t* total = totals.total;
  const double* maxs = totals.maxs;
  const double* energy_all = totals.energy_all;
  rep.write_seconds = FarmNow() - tw;
  rep.bytes_moved = total[0];
  rep.every_rank_reads = reading.every_rank_reads;
  rep.rank0_bytes_read = st.bytes_read;
  rep.rank0_bytes_sent = st.bytes_sent;
  rep.spill_bytes = total[1];
  rep.spill_runs = total[2];
  rep.terms = total[3];
  rep.columns_stored = t.columns.size();
  rep.compressed_bytes = file_bytes;
  rep.read_seconds = maxs[0];
  rep.row_transform_seconds = maxs[1];
  rep.exchange_seconds = maxs[2];
  rep.buffer_seconds = maxs[3];
  rep.merge_seconds = maxs[4];
  rep.compress_seconds = maxs[5];
  rep.transpose_seconds = maxs[6];
  rep.raw_kept = !options.discard_raw;
  // ‖T − T̃‖_F / ‖T‖_F, T̃ what transport.prtc decodes to (exact, up to float rounding).
  rep.relative_frobenius_error =
      energy_all[0] > 0 ? std::sqrt(std::max(0.0, energy_all[1] + energy_all[2]) / energy_all[0])
                        : 0.0;
  if (options.measure_bandwidth) {
    rep.memory_bandwidth_mb_s = MeasureMemoryBandwidth(256u << 20);
    rep.disk_write_bandwidth_mb_s = MeasureDiskWriteBandwidth(folder.dir, 256u << 20);
  }
  rep.wall_seconds = FarmNow() - start;
  ctx.run_eta.StepFinished("compress");
  // RunFarm writes the report, then (the compressed file being durable) removes
  // transport.prtt if --discard-raw.
  rep.enabled = true;
  if (!options.quiet) {
    spdlog::info(
        "compression: {} in {}: {:.1f} MB raw -> {:.2f} MB ({:.3f}% of raw), relative "
        "Frobenius error {:.3f}%, {} terms in {} "
        "columns; transpose {:.0f} MB/s ({:.1f} MB moved between ranks, {:.1f} MB spilled "
        "in {} runs){}",
        prtc, Progress::FormatDuration(rep.wall_seconds), static_cast<double>(rep.raw_bytes) / 1e6,
        static_cast<double>(rep.compressed_bytes) / 1e6, 100 * rep.Ratio(),
        100 * rep.relative_frobenius_error, rep.terms, rep.columns_stored,
        rep.TransposeMbPerSecond(), static_cast<double>(rep.bytes_moved) / 1e6,
        static_cast<double>(rep.spill_bytes) / 1e6, rep.spill_runs,
        options.discard_raw ? "; transport.prtt removed (--discard-raw)" : "");
    if (options.measure_bandwidth)
      spdlog::info("compression: memcpy {:.0f} MB/s, disk write+fsync {:.0f} MB/s in {}",
                   rep.memory_bandwidth_mb_s, rep.disk_write_bandwidth_mb_s, folder.dir);
  }
}

// The phase (docs/farm-compression.md; Cheslack-Postava et al. 2008 §4.4 steps 2–5): set up on
// rank 0 and shared (step 1), then the CPCA scheme's own path (farm/cpca_phase.h), or rows → row
// transform → distributed transpose → column compression (steps 2–3) → the columns gathered on
// rank 0, written and reported (step 4). A failure after the setup is logged here with what to
// rerun and rethrown: RunFarm writes the failed report and aborts the job.
void Compress(FarmContext& ctx) {
  const FarmOptions& options = ctx.options;
  const int rank = ctx.rank;
  const int size = ctx.size;
  const double start = FarmNow();

  CompressionSetup s;
  if (rank == 0) SetUpOnRank0(ctx, s);
  ShareSetupOutcome(s.setup, ctx.collectives);
  if (s.setup[0] != kExitOk) throw CollectiveStop{static_cast<int>(s.setup[0])};

  CompressionFarmReport& rep = ctx.report.compression;
  try {
    ShareSetup(ctx, s);
    const CompressedTransportHeader& header = s.header;
    const uint64_t rows = header.sample_count;
    const uint32_t cols = header.column_count();
    StartReport(ctx, header);
    if (header.scheme == CompressionScheme::kCpca) {
      RunCpcaCompression(
          ctx, header, s.reader, [&] { return OpenComposedRows(ctx); }, start);
      return;
    }

    const TransposePlan plan = PlanTranspose(ctx, s);
    ProgressOptions po = FarmProgressOptions(ctx, "rows", false);
    if (rank == 0) ctx.run_eta.StepStarted("compress");
    Progress progress("transpose", rows, po);
    if (rank == 0 && !options.quiet)
      spdlog::info(
          "compression: {} rows x {} columns ({:.1f} MB), {} scheme, {} rank(s), "
          "{} rows per chunk, memory budget {:.1f} MB per rank",
          rows, cols, static_cast<double>(rep.raw_bytes) / 1e6, rep.scheme, size, plan.chunk,
          static_cast<double>(options.memory_budget_bytes) / 1e6);
    std::unique_ptr<RadianceNormAccumulator> norms = StartRadianceNorms(ctx, header);
    RankColumns columns = TransposeAndCompress(ctx, s, plan, norms.get(), progress, po);
    std::error_code ec;
    fs::remove_all(plan.spill_dir, ec);
    if (norms) {
      std::vector<double> all_norms = SumRadianceNorms(norms->Flat(), ctx.collectives);
      if (rank == 0) {
        EstimateLights& estimate = LoadEstimateLights(ctx);  // loaded above: kept as it is
        estimate.norms = std::move(all_norms);
        estimate.have_norms = true;
      }
    }

    // Gather the compressed columns on rank 0 as one encoded column block per rank.
    const double tw = FarmNow();
    const auto owned = OwnedColumns(cols, rank, size);
    std::vector<uint8_t> bytes;
    if (owned.second > owned.first) {
      CompressedColumnBlock block;
      block.first_column = owned.first;
      block.column_span = owned.second - owned.first;
      block.columns = std::move(columns.mine);
      bytes = EncodeColumnBlock(header, block);
    }
    const std::vector<uint64_t> sizes = GatherColumnBlockSizes(bytes.size(), ctx.collectives);
    const RankTotals totals = ReduceRankFigures(columns, ctx.collectives);
    const CompressedTransport t = CollectColumnsOnRank0(ctx, header, bytes, sizes);
    if (rank == 0) {
      const std::vector<uint8_t> file = EncodeCompressedTransport(t);
      WriteCompressedFile(ctx, file);
      FinishReport(ctx, t, file.size(), totals, columns.st, plan.reading, tw, start);
    }
  } catch (...) {
    std::string message;
    const int code = ExitCodeOf(std::current_exception(), message, "compression phase");
    spdlog::error(
        "rank {}: compression: {} (the transport is complete: rerun with --resume to "
        "redo only the compression)",
        rank, message);
    (void)code;
    throw;  // RunFarm writes the failed report and aborts the job
  }
}

class CompressionPhase final : public FarmPhase {
 public:
  const char* name() const override { return "compress"; }
  const char* stage() const override { return kStageCompression; }
  // ~100 MB/s of float32 rows per rank (the 2-core VM's prior; docs/farm-compression.md).
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    const double raw_bytes = static_cast<double>(ctx.params.rows) * 6.0 * ctx.params.cubemap_n *
                             ctx.params.cubemap_n * 4.0;
    steps.push_back({"compress", "compress", raw_bytes, 1.0 / (1e8 * std::max(1, ctx.size))});
  }
  void Run(FarmContext& ctx) override { Compress(ctx); }
};

}  // namespace

double MeasureMemoryBandwidth(std::size_t bytes) {
  std::vector<char> a(bytes, 1), b(bytes, 2);
  double best = 0;
  for (int pass = 0; pass < 4; ++pass) {
    const double t = FarmNow();
    std::memcpy(b.data(), a.data(), bytes);
    const double dt = FarmNow() - t;
    if (dt > 0) best = std::max(best, static_cast<double>(bytes) / dt / 1e6);
    a[static_cast<std::size_t>(pass) % bytes] = b[bytes / 2];  // keep the copies observable
  }
  return best;
}

double MeasureDiskWriteBandwidth(const std::string& dir, std::size_t bytes) {
  const std::string path = (fs::path(dir) / ".prt-farm-disk-bench.tmp").string();
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw FileIoError(path, std::strerror(errno));
  std::vector<char> buf(8u << 20);
  for (std::size_t i = 0; i < buf.size(); ++i) buf[i] = static_cast<char>(i * 2654435761u >> 24);
  const double t = FarmNow();
  std::size_t done = 0;
  bool failed = false;
  while (done < bytes && !failed) {
    const std::size_t n = std::min(buf.size(), bytes - done);
    const ssize_t w = ::write(fd, buf.data(), n);
    if (w <= 0)
      failed = true;
    else
      done += static_cast<std::size_t>(w);
  }
  if (!failed && ::fsync(fd) != 0) failed = true;
  const double dt = FarmNow() - t;
  const int err = errno;
  ::close(fd);
  std::error_code ec;
  fs::remove(path, ec);
  if (failed) throw FileIoError(path, std::strerror(err));
  return dt > 0 ? static_cast<double>(done) / dt / 1e6 : 0;
}

// transport.prtc, when the compression stage runs.
void AddCompressionPhase(const FarmContext& ctx, PhaseList& phases) {
  if (ctx.params.run_compression) phases.push_back(std::make_unique<CompressionPhase>());
}

}  // namespace prt
