// report.json (see farm_report.h).
#include "farm/farm_report.h"

#include <algorithm>
#include <nlohmann/json.hpp>

namespace prt {

double FarmReport::LoadImbalance() const {
  double max = 0, sum = 0;
  int n = 0;
  for (const RankReport& r : rank_reports) {
    if (!r.computes) continue;
    max = std::max(max, r.busy_seconds);
    sum += r.busy_seconds;
    ++n;
  }
  return (n == 0 || sum <= 0) ? 0.0 : max / (sum / n);
}

double SparseFarmReport::SampledFraction() const {
  return counters.texels_above_horizon == 0
             ? 0.0
             : static_cast<double>(counters.texels_traced) /
                   static_cast<double>(counters.texels_above_horizon);
}

void FarmReport::SetSection(const std::string& key, std::string json_text) {
  for (auto& [k, text] : sections)
    if (k == key) {
      text = std::move(json_text);
      return;
    }
  sections.emplace_back(key, std::move(json_text));
}

std::string FarmReport::Section(const std::string& key) const {
  for (const auto& [k, text] : sections)
    if (k == key) return text;
  return "";
}

namespace {

using Json = nlohmann::ordered_json;

// report.json "rank_details": every rank's jobs, rows, rays and time.
Json RanksJson(const std::vector<RankReport>& rank_reports) {
  Json ranks_json = Json::array();
  for (const RankReport& r : rank_reports) {
    ranks_json.push_back(
        {{"rank", r.rank},
         {"host", r.host},
         {"threads", r.threads},
         {"computes", r.computes},
         {"jobs", r.jobs},
         {"rows", r.rows},
         {"rays_traced", r.rays_traced},
         {"busy_seconds", r.busy_seconds},
         {"peak_rss_bytes", r.peak_rss_bytes},
         {"rays_per_second",
          r.busy_seconds > 0 ? static_cast<double>(r.rays_traced) / r.busy_seconds : 0.0}});
  }
  return ranks_json;
}

// report.json "coordinator": rank 0's traffic per batch of jobs.
Json CoordinatorJson(const std::vector<CoordinatorReport>& coordinator, bool rows_in_place) {
  Json batches = Json::array();
  for (const CoordinatorReport& c : coordinator) {
    const double items = static_cast<double>(std::max<uint64_t>(1, c.items));
    batches.push_back(
        {{"batch", c.batch},
         {"items", c.items},
         {"jobs", c.jobs},
         {"bytes_in", c.bytes_in},
         {"bytes_out", c.bytes_out},
         {"bytes_per_item", static_cast<double>(c.bytes_in + c.bytes_out) / items},
         {"cpu_seconds", c.cpu_seconds},
         {"cpu_ms_per_job", c.jobs > 0 ? 1e3 * c.cpu_seconds / static_cast<double>(c.jobs) : 0.0},
         {"wall_seconds", c.wall_seconds}});
  }
  return {{"rows_in_place", rows_in_place}, {"batches", batches}};
}

// report.json "sparse": the sparse method's steps and counters.
Json SparseJson(const SparseFarmReport& sparse) {
  Json sp = Json::array();
  for (const SparsePhaseReport& p : sparse.phases) {
    sp.push_back({{"name", p.name},
                  {"wall_seconds", p.wall_seconds},
                  {"items", p.items},
                  {"jobs_reused", p.jobs_reused}});
  }
  const SparseJobCounters& c = sparse.counters;
  return {
      {"phases", sp},
      {"dense_initial", sparse.dense_initial},
      {"dense_by_rank", sparse.dense_by_rank},
      {"dense_fallback", sparse.dense_fallback},
      {"dense_total", sparse.dense_initial + sparse.dense_by_rank + sparse.dense_fallback},
      {"sparse", c.reconstructed},
      {"candidates_ranked", sparse.candidates_ranked},
      {"sampled_fraction", sparse.SampledFraction()},
      {"texels_traced", c.texels_traced},
      {"texels_above_horizon", c.texels_above_horizon},
      {"dense_texels",
       {{"grid", c.grid_texels}, {"feature", c.feature_texels}, {"borrowed", c.borrowed_texels}}},
      {"features_traced", c.features_traced},
      {"fallbacks",
       {{"too_few_neighbors", c.fallback_too_few_neighbors},
        {"solve_failed", c.fallback_solve_failed},
        {"poor_fit", c.fallback_poor_fit}}},
      {"l1_solver", {{"lars", c.solved_lars}, {"admm", c.solved_admm}, {"zero", c.zero_systems}}},
      {"dense_rows_shipped", sparse.dense_rows_shipped},
      {"cross_validation",
       {{"reconstructed", sparse.cross_validation.reconstructed},
        {"fallbacks", sparse.cross_validation.fallback_too_few_neighbors +
                          sparse.cross_validation.fallback_solve_failed +
                          sparse.cross_validation.fallback_poor_fit},
        {"rays_traced", sparse.cross_validation.rays_traced}}},
      {"index_seconds", sparse.index_seconds},
  };
}

// report.json "visibility": the visibility job's maps and blocks.
Json VisibilityJson(const VisibilityFarmReport& visibility) {
  const VisibilityFarmReport& v = visibility;
  return {
      {"n", v.n},
      {"supersample", v.supersample},
      {"bits", v.bits},
      {"vertices", v.vertices},
      {"raw_bytes", v.raw_bytes},
      {"encoded_bytes", v.encoded_bytes},
      {"encoded_bytes_per_vertex", v.vertices ? double(v.encoded_bytes) / double(v.vertices) : 0.0},
      {"blocks", {{"zero", v.blocks_zero}, {"one", v.blocks_one}, {"mixed", v.blocks_mixed}}},
      {"changes", v.changes},
  };
}

// report.json "compression": the compression phase's figures (docs/farm-compression.md).
Json CompressionJson(const CompressionFarmReport& compression) {
  const CompressionFarmReport& r = compression;
  Json c;
  c["wall_seconds"] = r.wall_seconds;
  c["ranks"] = r.ranks;
  c["scheme"] = r.scheme;
  c["row_wavelet"] = r.row_wavelet;
  c["column_wavelet"] = r.column_wavelet;
  c["bits"] = r.bits;
  c["keep_fraction"] = r.keep_fraction;
  c["memory_budget_bytes"] = r.memory_budget_bytes;
  c["raw_bytes"] = r.raw_bytes;
  c["bytes_moved"] = r.bytes_moved;
  c["every_rank_reads"] = r.every_rank_reads;
  c["rank0_bytes_read"] = r.rank0_bytes_read;
  c["rank0_bytes_sent"] = r.rank0_bytes_sent;
  c["spill_bytes"] = r.spill_bytes;
  c["spill_runs"] = r.spill_runs;
  c["transpose_seconds"] = r.transpose_seconds;
  c["transpose_mb_per_second"] = r.TransposeMbPerSecond();
  c["phase_mb_per_second"] = r.PhaseMbPerSecond();
  c["stage_seconds"] = {
      {"read", r.read_seconds},         {"row_transform", r.row_transform_seconds},
      {"exchange", r.exchange_seconds}, {"buffer", r.buffer_seconds},
      {"merge", r.merge_seconds},       {"compress", r.compress_seconds},
      {"write", r.write_seconds}};
  c["compressed_bytes"] = r.compressed_bytes;
  c["terms"] = r.terms;
  c["columns_stored"] = r.columns_stored;
  c["ratio_to_raw"] = r.Ratio();
  c["raw_kept"] = r.raw_kept;
  c["relative_frobenius_error"] = r.relative_frobenius_error;
  if (r.memory_bandwidth_mb_s > 0) c["memory_bandwidth_mb_per_second"] = r.memory_bandwidth_mb_s;
  if (r.disk_write_bandwidth_mb_s > 0)
    c["disk_write_bandwidth_mb_per_second"] = r.disk_write_bandwidth_mb_s;
  if (r.cpca.enabled) {
    Json p;
    p["clusters"] = r.cpca.clusters;
    p["bases"] = r.cpca.bases;
    p["method"] = r.cpca.method;
    p["rows_dense_pass"] = r.cpca.rows_dense_pass;
    p["lbg_iterations"] = r.cpca.lbg_iterations;
    p["distance_evaluations"] = r.cpca.distance_evaluations;
    p["empty_clusters"] = r.cpca.empty_clusters;
    p["seconds_dense_pass"] = r.cpca.seconds_dense;
    p["seconds_recluster"] = r.cpca.seconds_recluster;
    p["basis_terms"] = r.cpca.basis_terms;
    c["cpca"] = p;
  }
  return c;
}

// report.json "job_times": how long the jobs took against their targets (farm/job_loop.h).
Json JobTimesJson(const JobTimesReport& job_times) {
  const JobTimesReport& t = job_times;
  return {{"target_seconds", t.target_seconds},
          {"jobs", t.jobs},
          {"over_4x_target", t.over_4x_target},
          {"over_4x_planned", t.over_4x_planned},
          {"longest",
           {{"seconds", t.longest_seconds},
            {"planned_seconds", t.longest_planned_seconds},
            {"batch", t.longest_batch},
            {"rank", t.longest_rank},
            {"first", t.longest_first},
            {"count", t.longest_count}}},
          {"longest_seconds_by_rank", t.longest_by_rank},
          {"longest_silence_seconds", t.longest_silence_seconds}};
}

}  // namespace

std::string FarmReport::ToJsonText() const {
  Json phases_json = Json::array();
  for (const PhaseReport& p : phases) {
    phases_json.push_back({{"name", p.name}, {"wall_seconds", p.wall_seconds}});
  }
  Json stages_json = Json::array();
  for (const StageReport& st : stages) {
    stages_json.push_back({{"name", st.name},
                           {"status", st.status},
                           {"reason", st.reason},
                           {"wall_seconds", st.wall_seconds}});
  }
  Json eta_json = Json::array();
  for (const EtaReport& e : eta) {
    eta_json.push_back({{"elapsed_seconds", e.elapsed_seconds},
                        {"step", e.step},
                        {"predicted_total_seconds", e.predicted_total_seconds}});
  }
  Json j = {
      {"tool", "prt-farm"},
      {"version", version},
      {"status", status},
      {"exit_code", exit_code},
      {"error", error},
      {"scene", scene},
      {"scene_name", scene_name},
      {"method", method},
      {"ranks", ranks},
      {"cubemap_n", cubemap_n},
      {"rays_per_texel", rays_per_texel},
      {"seed", seed},
      {"rows", rows},
      {"cols", cols},
      {"rows_per_block", rows_per_block},
      {"transport_bytes", transport_bytes},
      {"wall_seconds", wall_seconds},
      {"stages", stages_json},
      {"eta", eta_json},
      {"phases", phases_json},
      {"rays_traced", rays_traced},
      {"rays_per_second",
       sampling_seconds > 0 ? static_cast<double>(rays_traced) / sampling_seconds : 0.0},
      {"texels_traced", texels_traced},
      {"texels_skipped_below_horizon", texels_below_horizon},
      {"rays_skipped_below_horizon", rays_below_horizon},
      {"rays_traced_including_reused", rays_traced_all},
      {"texels_skipped_below_horizon_including_reused", texels_below_horizon_all},
      {"jobs",
       {{"total", jobs_total},
        {"done", jobs_done},
        {"reused_from_checkpoints", jobs_reused},
        {"rows_done", rows_done},
        {"rows_reused", rows_reused},
        {"damaged_journal_lines", damaged_journal_lines},
        {"checkpoints_rejected", checkpoints_rejected}}},
      {"load_imbalance", LoadImbalance()},
      {"rank_details", RanksJson(rank_reports)},
  };
  j["coordinator"] = CoordinatorJson(coordinator, rows_in_place);
  if (sparse.enabled) j["sparse"] = SparseJson(sparse);
  if (visibility.enabled) j["visibility"] = VisibilityJson(visibility);
  if (compression.enabled) j["compression"] = CompressionJson(compression);
  if (!carried_json.empty()) {
    const Json carried = Json::parse(carried_json, nullptr, false);
    if (carried.is_object()) {
      for (auto it = carried.begin(); it != carried.end(); ++it) {
        if (!j.contains(it.key())) j[it.key()] = it.value();
      }
    }
  }
  for (const auto& [key, text] : sections) {
    const Json section = Json::parse(text, nullptr, false);
    if (!section.is_discarded()) j[key] = section;
  }
  if (!accuracy_json.empty()) {
    const Json accuracy = Json::parse(accuracy_json, nullptr, false);
    if (!accuracy.is_discarded()) j["accuracy"] = accuracy;
  }
  if (job_times.jobs > 0) j["job_times"] = JobTimesJson(job_times);
  return j.dump(2) + "\n";
}

double CompressionFarmReport::TransposeMbPerSecond() const {
  return transpose_seconds > 0 ? static_cast<double>(raw_bytes) / transpose_seconds / 1e6 : 0;
}
double CompressionFarmReport::PhaseMbPerSecond() const {
  return wall_seconds > 0 ? static_cast<double>(raw_bytes) / wall_seconds / 1e6 : 0;
}
double CompressionFarmReport::Ratio() const {
  return raw_bytes > 0 ? static_cast<double>(compressed_bytes) / static_cast<double>(raw_bytes) : 0;
}

}  // namespace prt
