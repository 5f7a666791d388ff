// Jobs of the farm's sparse method (see sparse_jobs.h).
#include "farm/sparse_jobs.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <mutex>
#include <stdexcept>
#include <type_traits>

#include "formats/transport_variance.h"
#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/local_rank.h"

namespace prt {

namespace {

constexpr uint32_t kJobMagic = 0x4a535250u;     // "PRSJ"
constexpr uint32_t kResultMagic = 0x52535250u;  // "PRSR"

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Bytes PutVector writes for v.
template <typename T>
std::size_t VectorBytes(const std::vector<T>& v) {
  return sizeof(uint64_t) + v.size() * sizeof(T);
}

// A sparse job message's reader: a short message is a std::runtime_error (rank 0 turns it into a
// RankFailure naming the rank).
ByteReader MessageReader(std::string_view bytes) {
  return ByteReader(bytes, [](const char*, std::size_t) {
    throw std::runtime_error("truncated sparse job message");
  });
}

void PutHeader(ByteWriter& w, uint32_t magic, const SparseJobHeader& h) {
  w.Put(magic);
  w.Put(h);
}

SparseJobHeader GetHeader(ByteReader& r, uint32_t magic) {
  if (r.Get<uint32_t>("message") != magic) throw std::runtime_error("not a sparse job message");
  return r.Get<SparseJobHeader>("message");
}

// A neighbour list is well-formed: offsets start at 0, never decrease, end at neighbors.size(),
// and every neighbour index is inside the union.
void CheckLists(std::size_t items, const std::vector<uint32_t>& offsets,
                const std::vector<uint32_t>& neighbors, std::size_t union_rows) {
  if (offsets.size() != items + 1 || offsets.front() != 0 || offsets.back() != neighbors.size())
    throw std::runtime_error("malformed neighbour lists in a sparse job");
  for (std::size_t i = 0; i < items; ++i)
    if (offsets[i] > offsets[i + 1]) throw std::runtime_error("malformed neighbour offsets");
  for (uint32_t n : neighbors)
    if (n >= union_rows) throw std::runtime_error("neighbour index outside the job's rows");
}

void CheckFinite(const float* v, std::size_t count, const char* what, uint32_t sample) {
  for (std::size_t i = 0; i < count; ++i)
    if (!std::isfinite(v[i]))
      throw NumericalError(std::string("non-finite ") + what + " value for sample " +
                           std::to_string(sample));
}

// The combination records of a result, compactly (a record's used pairs come first and the
// unused ones are (kNoSample, 0): 40 pairs a vertex were 320 bytes, most of them unused): the
// pairs per record, the record count, then per record the number of pairs up to its last used
// one and those pairs. Decoding restores the records exactly.
void PutCombination(ByteWriter& w, const std::vector<uint32_t>& records, uint64_t slots) {
  w.Put(slots);
  const uint64_t count = slots == 0 ? 0 : records.size() / (2 * slots);
  w.Put(count);
  for (uint64_t i = 0; i < count; ++i) {
    const uint32_t* rec = records.data() + i * 2 * slots;
    uint32_t used = static_cast<uint32_t>(slots);
    while (used > 0 && rec[2 * (used - 1)] == kNoSample && rec[2 * (used - 1) + 1] == 0) --used;
    w.Put(used);
    w.PutBytes(rec, used * 2 * sizeof(uint32_t));
  }
}

std::vector<uint32_t> GetCombination(ByteReader& r) {
  const auto slots = r.Get<uint64_t>("message");
  const auto count = r.Get<uint64_t>("message");
  if (slots > 4096 || count > r.remaining() / sizeof(uint32_t))
    throw std::runtime_error("malformed combination records");
  std::vector<uint32_t> records(static_cast<std::size_t>(count * slots * 2), 0);
  for (uint64_t i = 0; i < count; ++i) {
    uint32_t* rec = records.data() + i * 2 * slots;
    for (uint64_t k = 0; k < slots; ++k) rec[2 * k] = kNoSample;
    const auto used = r.Get<uint32_t>("message");
    if (used > slots) throw std::runtime_error("malformed combination records");
    const std::string_view pairs = r.Take(used * 2 * sizeof(uint32_t), "message");
    std::memcpy(rec, pairs.data(), pairs.size());
  }
  return records;
}

}  // namespace

std::vector<uint64_t> SparseJobCounters::ToVector() const {
  return {rays_traced,           texels_traced,
          texels_below_horizon,  rays_below_horizon,
          texels_above_horizon,  grid_texels,
          feature_texels,        borrowed_texels,
          reconstructed,         fallback_too_few_neighbors,
          fallback_solve_failed, solved_lars,
          solved_admm,           zero_systems,
          features_traced,       fallback_poor_fit};
}

SparseJobCounters SparseJobCounters::FromVector(std::span<const uint64_t> v) {
  uint64_t a[kCount] = {};
  for (std::size_t i = 0; i < std::min(kCount, v.size()); ++i) a[i] = v[i];
  SparseJobCounters c;
  c.rays_traced = a[0];
  c.texels_traced = a[1];
  c.texels_below_horizon = a[2];
  c.rays_below_horizon = a[3];
  c.texels_above_horizon = a[4];
  c.grid_texels = a[5];
  c.feature_texels = a[6];
  c.borrowed_texels = a[7];
  c.reconstructed = a[8];
  c.fallback_too_few_neighbors = a[9];
  c.fallback_solve_failed = a[10];
  c.solved_lars = a[11];
  c.solved_admm = a[12];
  c.zero_systems = a[13];
  c.features_traced = a[14];
  c.fallback_poor_fit = a[15];
  return c;
}

SparseJobCounters& SparseJobCounters::operator+=(const SparseJobCounters& o) {
  const std::vector<uint64_t> a = ToVector(), b = o.ToVector();
  std::vector<uint64_t> s(kCount);
  for (std::size_t i = 0; i < kCount; ++i) s[i] = a[i] + b[i];
  *this = FromVector(s);
  return *this;
}

std::string EncodeDenseJob(const SparseJobHeader& h, const DenseJob& job, std::string prefix) {
  ByteWriter w(std::move(prefix));
  PutHeader(w, kJobMagic, h);
  w.PutVector(job.ids);
  w.Put(job.in_place);
  w.PutVector(std::vector<char>(job.step.begin(), job.step.end()));
  return std::move(w.bytes());
}

std::string EncodeRankJob(const SparseJobHeader& h, const RankJob& job, std::string prefix) {
  ByteWriter w(std::move(prefix));
  PutHeader(w, kJobMagic, h);
  w.Put(job.low_dim);
  w.PutVector(job.offsets);
  w.PutVector(job.neighbors);
  w.PutVector(job.low_rows);
  w.Put(job.in_place);
  w.PutVector(job.union_ids);
  return std::move(w.bytes());
}

std::string EncodeSparseJob(const SparseJobHeader& h, const SparseJob& job, std::string prefix) {
  ByteWriter w(std::move(prefix));
  w.Reserve(w.bytes().size() + sizeof(uint32_t) + sizeof h + sizeof job.texels +
            VectorBytes(job.vertices) + VectorBytes(job.offsets) + VectorBytes(job.neighbors) +
            VectorBytes(job.transport) + VectorBytes(job.visibility) + VectorBytes(job.feature) +
            VectorBytes(job.union_ids) + sizeof job.in_place + sizeof(uint64_t) + job.step.size());
  PutHeader(w, kJobMagic, h);
  w.Put(job.texels);
  w.PutVector(job.vertices);
  w.PutVector(job.offsets);
  w.PutVector(job.neighbors);
  w.PutVector(job.transport);
  w.PutVector(job.visibility);
  w.PutVector(job.feature);
  w.PutVector(job.union_ids);
  w.Put(job.in_place);
  w.PutVector(std::vector<char>(job.step.begin(), job.step.end()));
  return std::move(w.bytes());
}

SparseJobHeader PeekSparseJobHeader(std::string_view job_bytes) {
  ByteReader r = MessageReader(job_bytes);
  return GetHeader(r, kJobMagic);
}

std::string EncodeSparseJobResult(const SparseJobResult& res, std::string prefix) {
  ByteWriter w(std::move(prefix));
  const std::size_t start = w.bytes().size();  // the checksum covers this message only
  const std::vector<uint64_t> counters = res.counters.ToVector();
  w.Reserve(start + sizeof(uint32_t) + sizeof res.header + sizeof res.busy_seconds +
            VectorBytes(counters) + VectorBytes(res.transport) + VectorBytes(res.visibility) +
            VectorBytes(res.feature) + VectorBytes(res.weights) + VectorBytes(res.outcomes) +
            VectorBytes(res.combination) + sizeof res.in_place + sizeof res.checksum +
            sizeof(uint64_t));
  PutHeader(w, kResultMagic, res.header);
  w.Put(res.busy_seconds);
  w.PutVector(counters);
  w.PutVector(res.transport);
  w.PutVector(res.visibility);
  w.PutVector(res.feature);
  w.PutVector(res.weights);
  w.PutVector(res.outcomes);
  w.PutVector(std::vector<char>(res.variance.begin(), res.variance.end()));
  PutCombination(w, res.combination,
                 res.outcomes.empty() ? 0 : res.combination.size() / (2 * res.outcomes.size()));
  w.Put(res.in_place);
  w.Put(res.checksum);
  std::string& b = w.bytes();
  const uint64_t sum = Checksum64(b.data() + start, b.size() - start);
  b.append(reinterpret_cast<const char*>(&sum), sizeof sum);
  return std::move(b);
}

SparseJobResult DecodeSparseJobResult(std::string_view bytes) {
  if (bytes.size() < sizeof(uint64_t)) throw std::runtime_error("truncated sparse job result");
  const std::size_t body = bytes.size() - sizeof(uint64_t);
  uint64_t sum;
  std::memcpy(&sum, bytes.data() + body, sizeof sum);
  if (Checksum64(bytes.data(), body) != sum)
    throw std::runtime_error("sparse job result arrived damaged (checksum mismatch)");
  ByteReader r = MessageReader(bytes);
  SparseJobResult res;
  res.header = GetHeader(r, kResultMagic);
  res.busy_seconds = r.Get<double>("message");
  const std::vector<uint64_t> counters = r.GetVector<uint64_t>("message");
  res.counters = SparseJobCounters::FromVector(counters);
  res.transport = r.GetVector<float>("message");
  res.visibility = r.GetVector<float>("message");
  res.feature = r.GetVector<uint8_t>("message");
  res.weights = r.GetVector<int32_t>("message");
  res.outcomes = r.GetVector<uint8_t>("message");
  const std::vector<char> variance = r.GetVector<char>("message");
  res.variance.assign(variance.begin(), variance.end());
  res.combination = GetCombination(r);
  res.in_place = r.Get<uint32_t>("message");
  res.checksum = r.Get<uint64_t>("message");
  return res;
}

namespace {

// What a sparse job's computation shares across its kinds (ComputeSparseJob).
struct SparseJobWork {
  SparseJobWork(const TransportSampler& s, std::span<const SpatialSample> v, const SparsePlan& p,
                SparseRowFiles* f)
      : sampler(s), samples(v), plan(p), files(f) {}
  const TransportSampler& sampler;
  std::span<const SpatialSample> samples;
  const SparsePlan& plan;
  SparseRowFiles* files;
  bool with_variance = false;
  TransportVariance sums;  // the job's Monte-Carlo variance sums (with_variance)
  std::size_t T = 0;       // texels per row
  uint32_t in_place = 0;   // the job's in-place flags (kWriteRowsInPlace, …)
  std::string step;        // its step's name (dense and sparse jobs)
  std::mutex mutex;        // guards the totals the parallel loops add up

  // The job's in-place flags, checked against this rank having the run's files.
  uint32_t InPlaceOf(uint32_t flags) const {
    if (flags != 0 && files == nullptr)
      throw std::runtime_error("a sparse job asks for rows in place, and this rank has no files");
    return flags;
  }
};

// The traced-ray counters a dense and a sparse job report alike (AngularStats, SparseStats).
template <class Stats>
void CountTraced(const Stats& total, SparseJobCounters& c) {
  c.rays_traced = total.trace.rays_traced;
  c.texels_traced = total.trace.texels_traced;
  c.texels_below_horizon = total.trace.texels_below_horizon;
  c.rays_below_horizon = total.trace.rays_below_horizon;
  c.texels_above_horizon = total.texels_above_horizon;
}

std::string StepOf(ByteReader& r) {
  const std::vector<char> name = r.GetVector<char>("message");
  return std::string(name.begin(), name.end());
}

// A dense job: whole rows by adaptive angular sampling (Huang & Ramamoorthi 2010 §4.2), with
// their visibility and feature rows, written in place or returned.
void ComputeDenseJob(SparseJobWork& job, ByteReader& r, SparseJobResult& res) {
  const std::size_t T = job.T;
  std::mutex& mutex = job.mutex;
  const std::vector<uint32_t> ids = r.GetVector<uint32_t>("message");
  job.in_place = job.InPlaceOf(r.Get<uint32_t>("message"));
  job.step = StepOf(r);
  for (uint32_t s : ids)
    if (s >= job.samples.size()) throw std::runtime_error("dense job names a missing sample");
  res.transport.resize(ids.size() * T);
  res.visibility.resize(ids.size() * T);
  res.feature.resize(ids.size() * T);
  std::vector<float> variance(job.with_variance ? ids.size() * T : 0);
  AngularStats total;
  tbb::parallel_for(std::size_t{0}, ids.size(), [&](std::size_t i) {
    DenseRow row;
    const AngularStats st =
        SampleDenseRowAdaptive(job.sampler, job.samples[ids[i]], ids[i], job.plan.angular, row);
    if (job.with_variance)
      std::copy(row.variance.begin(), row.variance.end(), variance.begin() + i * T);
    std::copy(row.transport.begin(), row.transport.end(), res.transport.begin() + i * T);
    std::copy(row.visibility.begin(), row.visibility.end(), res.visibility.begin() + i * T);
    std::copy(row.feature.begin(), row.feature.end(), res.feature.begin() + i * T);
    std::lock_guard lock(mutex);
    total += st;
  });
  for (std::size_t i = 0; i < ids.size(); ++i) {
    CheckFinite(res.transport.data() + i * T, T, "transport", ids[i]);
    CheckFinite(res.visibility.data() + i * T, T, "visibility", ids[i]);
    if (job.with_variance) job.sums.AddRow(ids[i], variance.data() + i * T);
  }
  if (job.in_place & kWriteRowsInPlace) {
    // The rows go into the run's files here; the journal's checksum comes back instead.
    const int n = job.sampler.layout().n(), m = job.files->low_resolution();
    std::vector<float> low(static_cast<std::size_t>(6 * m * m));
    for (std::size_t i = 0; i < ids.size(); ++i) {
      DownsampleRow(res.transport.data() + i * T, n, m, low.data());
      job.files->WriteDense(ids[i], res.transport.data() + i * T, res.visibility.data() + i * T,
                            res.feature.data() + i * T, low.data());
    }
    res.checksum = DenseResultChecksum(ids.size(), T, res.transport.data(), res.visibility.data(),
                                       res.feature.data());
    res.in_place = 1;
    res.transport = {};
    res.visibility = {};
    res.feature = {};
  }
  SparseJobCounters& c = res.counters;
  CountTraced(total, c);
  c.grid_texels = total.grid_texels;
  c.feature_texels = total.feature_texels;
  c.borrowed_texels = total.borrowed_texels;
}

// A rank job: each candidate's local-rank weight from its dense neighbours' downsampled rows
// (§4.1).
void ComputeRankJob(SparseJobWork& job, ByteReader& r, SparseJobResult& res) {
  const auto low_dim = r.Get<uint32_t>("message");
  const std::vector<uint32_t> offsets = r.GetVector<uint32_t>("message");
  const std::vector<uint32_t> nb = r.GetVector<uint32_t>("message");
  std::vector<float> low = r.GetVector<float>("message");
  job.in_place = job.InPlaceOf(r.Get<uint32_t>("message"));
  const std::vector<uint32_t> union_ids = r.GetVector<uint32_t>("message");
  if (job.in_place & kReadRowsInPlace) {
    // The union's downsampled rows, from the run's files.
    const int m = job.files->low_resolution();
    if (low_dim != static_cast<uint32_t>(6 * m * m) || !low.empty())
      throw std::runtime_error("malformed rank job rows");
    low.resize(union_ids.size() * low_dim);
    for (std::size_t k = 0; k < union_ids.size(); ++k) {
      if (union_ids[k] >= job.samples.size())
        throw std::runtime_error("rank job names a missing sample");
      job.files->ReadLow(union_ids[k], low.data() + k * low_dim);
    }
    job.in_place = 0;  // nothing is written
  }
  if (low_dim == 0 || low.size() % low_dim != 0)
    throw std::runtime_error("malformed rank job rows");
  if (offsets.empty()) throw std::runtime_error("malformed rank job");
  const std::size_t count = offsets.size() - 1;
  CheckLists(count, offsets, nb, low.size() / low_dim);
  res.weights.resize(count);
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) {
    std::vector<const float*> rows;
    for (uint32_t k = offsets[i]; k < offsets[i + 1]; ++k)
      rows.push_back(low.data() + static_cast<std::size_t>(nb[k]) * low_dim);
    res.weights[i] = SparseCandidateWeight(rows, low_dim, job.plan);
  });
}

// A sparse job: each vertex's row reconstructed from its dense neighbours by the L1 fit of its
// feature texels (§5), with the combination the bounces reuse; written in place, kept for the
// cross-validation, or returned.
void ComputeSparseRows(SparseJobWork& job, ByteReader& r, SparseJobResult& res) {
  const std::size_t T = job.T;
  std::mutex& mutex = job.mutex;
  const auto texels = r.Get<uint32_t>("message");
  if (texels != T) throw std::runtime_error("sparse job for another cubemap resolution");
  const std::vector<uint32_t> vertices = r.GetVector<uint32_t>("message");
  const std::vector<uint32_t> offsets = r.GetVector<uint32_t>("message");
  const std::vector<uint32_t> nb = r.GetVector<uint32_t>("message");
  std::vector<float> tr = r.GetVector<float>("message");
  std::vector<float> vis = r.GetVector<float>("message");
  std::vector<uint8_t> feat = r.GetVector<uint8_t>("message");
  const std::vector<uint32_t> union_ids = r.GetVector<uint32_t>("message");
  job.in_place = job.InPlaceOf(r.Get<uint32_t>("message"));
  job.step = StepOf(r);
  if (job.in_place & kReadRowsInPlace) {
    // The dense neighbours' rows, from the run's files.
    if (!tr.empty() || !vis.empty() || !feat.empty())
      throw std::runtime_error("malformed sparse job rows");
    const std::size_t u = union_ids.size();
    tr.resize(u * T);
    vis.resize(u * T);
    feat.resize(u * T);
    for (std::size_t k = 0; k < u; ++k) {
      if (union_ids[k] >= job.samples.size())
        throw std::runtime_error("sparse job names a missing sample");
      job.files->ReadDense(union_ids[k], tr.data() + k * T, vis.data() + k * T,
                           feat.data() + k * T);
    }
  }
  const std::size_t rows = tr.size() / T;
  if (tr.size() != rows * T || vis.size() != rows * T || feat.size() != rows * T ||
      union_ids.size() != rows)
    throw std::runtime_error("malformed sparse job rows");
  for (uint32_t s : union_ids)
    if (s >= job.samples.size()) throw std::runtime_error("sparse job names a missing sample");
  CheckLists(vertices.size(), offsets, nb, rows);
  for (uint32_t s : vertices)
    if (s >= job.samples.size()) throw std::runtime_error("sparse job names a missing sample");
  std::vector<float> out(vertices.size() * T, 0.0f);
  std::vector<float> variance(job.with_variance ? vertices.size() * T : 0);
  res.outcomes.assign(vertices.size(), 0);
  tbb::enumerable_thread_specific<L1Solver> solvers([&] {
    L1Options o;
    o.lambda = job.plan.sparse.lambda;
    return L1Solver(o);
  });
  SparseStats total;
  const std::size_t slots = CombinationSlots(job.plan);
  res.combination.assign(vertices.size() * slots * 2, 0);
  for (std::size_t i = 0; i < vertices.size() * slots; ++i) res.combination[2 * i] = kNoSample;
  // Batches of consecutive vertices (the job's are in Morton order and share most of their
  // neighbours; ReconstructSparseRows reads the neighbours' rows once per batch). A vertex's row
  // does not depend on its batch.
  const std::size_t batches = (vertices.size() + kSparseRowBatch - 1) / kSparseRowBatch;
  tbb::parallel_for(std::size_t{0}, batches, [&](std::size_t bi) {
    const std::size_t first = bi * kSparseRowBatch;
    const std::size_t last = std::min(vertices.size(), first + kSparseRowBatch);
    std::vector<std::vector<DenseNeighbor>> nbs(last - first);
    std::vector<std::vector<NeighborWeight>> weights(last - first);
    std::vector<SparseRowTask> tasks;
    for (std::size_t i = first; i < last; ++i) {
      for (uint32_t k = offsets[i]; k < offsets[i + 1]; ++k) {
        const std::size_t u = nb[k];
        nbs[i - first].push_back({tr.data() + u * T, vis.data() + u * T, feat.data() + u * T,
                                  job.samples[union_ids[u]].normal});
      }
      tasks.push_back({&job.samples[vertices[i]], vertices[i], nbs[i - first], out.data() + i * T,
                       job.with_variance ? variance.data() + i * T : nullptr, &weights[i - first]});
    }
    SparseStats st;
    ReconstructSparseRows(job.sampler, tasks, job.plan.sparse, solvers.local(), st);
    for (std::size_t i = first; i < last; ++i) {
      const SparseOutcome o = tasks[i - first].outcome;
      res.outcomes[i] = static_cast<uint8_t>(o);
      if (o != SparseOutcome::kReconstructed) continue;
      const std::vector<NeighborWeight>& w = weights[i - first];
      uint32_t* rec = res.combination.data() + i * slots * 2;
      for (std::size_t x = 0; x < w.size() && x < slots; ++x) {
        rec[2 * x] = union_ids[nb[offsets[i] + w[x].neighbor]];
        rec[2 * x + 1] = std::bit_cast<uint32_t>(w[x].alpha);
      }
    }
    std::lock_guard lock(mutex);
    total += st;
  });
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    if (res.outcomes[i] != static_cast<uint8_t>(SparseOutcome::kReconstructed)) continue;
    CheckFinite(out.data() + i * T, T, "transport", vertices[i]);
    if (job.with_variance) job.sums.AddRow(vertices[i], variance.data() + i * T);
    res.transport.insert(res.transport.end(), out.begin() + static_cast<std::ptrdiff_t>(i * T),
                         out.begin() + static_cast<std::ptrdiff_t>((i + 1) * T));
    if (job.in_place & kWriteRowsInPlace) job.files->WriteRow(vertices[i], out.data() + i * T);
  }
  if (job.in_place & kWriteRowsInPlace) {
    res.checksum = SparseResultChecksum(res.outcomes, res.transport, res.combination);
    res.in_place = 1;
    res.transport = {};
  } else if (job.in_place & kCrossValidateInPlace) {
    res.checksum = job.files->WriteCrossValidation(res.header.first, vertices, res.outcomes,
                                                   res.transport.data());
    res.in_place = 1;
    res.transport = {};
    res.combination = {};
  }
  SparseJobCounters& c = res.counters;
  CountTraced(total, c);
  c.reconstructed = total.reconstructed;
  c.fallback_too_few_neighbors = total.fallback_too_few_neighbors;
  c.fallback_solve_failed = total.fallback_solve_failed;
  c.fallback_poor_fit = total.fallback_poor_fit;
  c.solved_lars = total.solved_lars;
  c.solved_admm = total.solved_admm;
  c.zero_systems = total.zero_systems;
  c.features_traced = total.features_traced;
}

}  // namespace

std::string ComputeSparseJob(const TransportSampler& sampler,
                             std::span<const SpatialSample> samples, const SparsePlan& plan,
                             std::string_view job_bytes, std::string prefix,
                             const TransportVariance* variance_shape, SparseRowFiles* files) {
  ByteReader r = MessageReader(job_bytes);
  SparseJobWork job(sampler, samples, plan, files);
  job.with_variance = variance_shape != nullptr;
  if (job.with_variance) job.sums = *variance_shape;
  SparseJobResult res;
  res.header = GetHeader(r, kJobMagic);
  const double t0 = Now();
  job.T = sampler.layout().texel_count();
  switch (static_cast<SparseJobKind>(res.header.kind)) {
    case SparseJobKind::kDense:
      ComputeDenseJob(job, r, res);
      break;
    case SparseJobKind::kRank:
      ComputeRankJob(job, r, res);
      break;
    case SparseJobKind::kSparse:
      ComputeSparseRows(job, r, res);
      break;
    default:
      throw std::runtime_error("unknown sparse job kind " + std::to_string(res.header.kind));
  }
  // A cross-validation's rays are not T's: its sums are never recorded (rank 0 ignores them).
  if (job.with_variance && res.header.kind != static_cast<uint32_t>(SparseJobKind::kRank) &&
      !(job.in_place & kCrossValidateInPlace)) {
    if (res.in_place) {
      files->RecordVariance(job.step, res.header.first, res.header.count,
                            EncodeTransportVariance(job.sums));
    } else {
      res.variance = EncodeTransportVariance(job.sums);
    }
  }
  // Rows and variance record durable before the result that lets rank 0 journal them.
  if (res.in_place) files->Sync();
  res.busy_seconds = Now() - t0;
  return EncodeSparseJobResult(res, std::move(prefix));
}

uint64_t DenseResultChecksum(std::size_t rows, std::size_t texels, const float* transport,
                             const float* visibility, const uint8_t* feature) {
  std::string buf;
  buf.reserve(rows * texels * 9);
  for (std::size_t i = 0; i < rows; ++i) {
    buf.append(reinterpret_cast<const char*>(transport + i * texels), texels * sizeof(float));
    buf.append(reinterpret_cast<const char*>(visibility + i * texels), texels * sizeof(float));
    buf.append(reinterpret_cast<const char*>(feature + i * texels), texels);
  }
  return Checksum64(buf.data(), buf.size());
}

uint64_t SparseResultChecksum(std::span<const uint8_t> outcomes, std::span<const float> rows,
                              std::span<const uint32_t> combination) {
  std::string buf(reinterpret_cast<const char*>(outcomes.data()), outcomes.size());
  buf.append(reinterpret_cast<const char*>(rows.data()), rows.size() * sizeof(float));
  buf.append(reinterpret_cast<const char*>(combination.data()),
             combination.size() * sizeof(uint32_t));
  return Checksum64(buf.data(), buf.size());
}

namespace {
constexpr char kCombinationMagic[8] = {'P', 'R', 'T', 'C', 'M', 'B', '1', '\0'};
}  // namespace

std::string EncodeCombinationFile(uint64_t samples, uint64_t slots,
                                  std::span<const uint32_t> pairs) {
  std::string b(kCombinationMagic, sizeof kCombinationMagic);
  b.append(reinterpret_cast<const char*>(&samples), sizeof samples);
  b.append(reinterpret_cast<const char*>(&slots), sizeof slots);
  b.append(reinterpret_cast<const char*>(pairs.data()), pairs.size() * sizeof(uint32_t));
  const uint64_t sum = Checksum64(b.data(), b.size());
  b.append(reinterpret_cast<const char*>(&sum), sizeof sum);
  return b;
}

std::vector<uint32_t> ReadCombinationFile(const std::string& path, uint64_t samples,
                                          uint64_t& slots) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot be opened (the sparse phase writes it)");
  const std::string b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  constexpr std::size_t kHead = sizeof kCombinationMagic + 2 * sizeof(uint64_t);
  if (b.size() < kHead + sizeof(uint64_t) ||
      std::memcmp(b.data(), kCombinationMagic, sizeof kCombinationMagic) != 0)
    throw InputError(path, "is not a combination file (bad magic or too short)");
  uint64_t n = 0, sum = 0;
  std::memcpy(&n, b.data() + 8, sizeof n);
  std::memcpy(&slots, b.data() + 16, sizeof slots);
  std::memcpy(&sum, b.data() + b.size() - sizeof sum, sizeof sum);
  if (Checksum64(b.data(), b.size() - sizeof sum) != sum)
    throw InputError(path, "is damaged (checksum mismatch)");
  if (n != samples)
    throw InputError(
        path, "holds " + std::to_string(n) + " samples, the run has " + std::to_string(samples));
  if (slots == 0 || slots > 4096 || (b.size() - kHead - sizeof sum) != n * slots * 8)
    throw InputError(
        path, "has a size that does not match its " + std::to_string(slots) + " slots per sample");
  std::vector<uint32_t> pairs(n * slots * 2);
  std::memcpy(pairs.data(), b.data() + kHead, pairs.size() * sizeof(uint32_t));
  for (std::size_t i = 0; i < n * slots; ++i) {
    if (pairs[2 * i] == kNoSample) continue;
    const float a = std::bit_cast<float>(pairs[2 * i + 1]);
    if (pairs[2 * i] >= n || !std::isfinite(a))
      throw InputError(path, "pair " + std::to_string(i) + " names sample " +
                                 std::to_string(pairs[2 * i]) + " or a non-finite weight");
  }
  return pairs;
}

uint32_t MortonKey(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  auto q = [](double v, double a, double b) -> uint32_t {
    const double t = b > a ? (v - a) / (b - a) : 0.0;
    return static_cast<uint32_t>(std::clamp(t, 0.0, 1.0) * 1023.0);
  };
  auto spread = [](uint32_t x) {
    x &= 0x3ffu;
    x = (x | (x << 16)) & 0x030000ffu;
    x = (x | (x << 8)) & 0x0300f00fu;
    x = (x | (x << 4)) & 0x030c30c3u;
    x = (x | (x << 2)) & 0x09249249u;
    return x;
  };
  return spread(q(p.x, lo.x, hi.x)) | (spread(q(p.y, lo.y, hi.y)) << 1) |
         (spread(q(p.z, lo.z, hi.z)) << 2);
}

}  // namespace prt
