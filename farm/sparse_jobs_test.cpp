// The sparse method's job messages and kernel (farm/sparse_jobs.h) without MPI: a job computed
// through ComputeSparseJob gives exactly the rows, weights and outcomes of the worker kernels
// called directly; results survive encoding and damage is detected; sparse journal lines round
// trip; Morton keys follow space.
#include "farm/sparse_jobs.h"

#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>

#include "farm/checkpoint_journal.h"
#include "vocabulary/errors.h"
#include "worker/embree_scene.h"
#include "worker/local_rank.h"

namespace prt {
namespace {

// A 6×6 ground grid under a floating square: part of the ground is shadowed.
SceneGeometry GroundUnderSquare() {
  SceneGeometry g;
  SceneMesh square;
  square.name = "square";
  square.mesh.positions = {{-0.5, 0.6, -0.5}, {0.5, 0.6, -0.5}, {0.5, 0.6, 0.5}, {-0.5, 0.6, 0.5}};
  square.mesh.normals.assign(4, Vec3{0, -1, 0});
  square.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  g.meshes.push_back(square);
  GroundPlane gp;
  gp.enabled = true;
  gp.size = 2;
  gp.resolution = 6;
  SceneMesh ground;
  ground.name = "ground";
  ground.is_ground = true;
  ground.grid_resolution = 6;
  ground.mesh = MakeGroundGrid(gp);
  g.meshes.push_back(ground);
  g.bounds_min = {-1, 0, -1};
  g.bounds_max = {1, 0.6, 1};
  return g;
}

class SparseJobsTest : public ::testing::Test {
 protected:
  SparseJobsTest()
      : geometry_(GroundUnderSquare()),
        samples_(SpatialSamplesOf(geometry_)),
        embree_(geometry_),
        sampler_(embree_, 8, TransportSamplerOptions{}) {
    plan_.max_neighbors = 6;
  }
  std::size_t T() const { return sampler_.layout().texel_count(); }

  SceneGeometry geometry_;
  std::vector<SpatialSample> samples_;
  EmbreeScene embree_;
  TransportSampler sampler_;
  SparsePlan plan_;
};

TEST_F(SparseJobsTest, DenseJobEqualsTheAdaptiveSamplerAndSurvivesEncoding) {
  SparseJobHeader h{static_cast<uint32_t>(SparseJobKind::kDense), 3, 10, 3};
  const DenseJob job{{5, 17, 30}, 0, ""};
  const SparseJobResult r =
      DecodeSparseJobResult(ComputeSparseJob(sampler_, samples_, plan_, EncodeDenseJob(h, job)));
  EXPECT_EQ(r.header.phase, 3u);
  EXPECT_EQ(r.header.first, 10u);
  EXPECT_EQ(r.header.count, 3u);
  ASSERT_EQ(r.transport.size(), 3 * T());
  AngularStats total;
  for (std::size_t i = 0; i < 3; ++i) {
    DenseRow row;
    total += SampleDenseRowAdaptive(sampler_, samples_[job.ids[i]], job.ids[i], plan_.angular, row);
    EXPECT_EQ(std::memcmp(row.transport.data(), r.transport.data() + i * T(), T() * 4), 0);
    EXPECT_EQ(std::memcmp(row.visibility.data(), r.visibility.data() + i * T(), T() * 4), 0);
    EXPECT_EQ(std::memcmp(row.feature.data(), r.feature.data() + i * T(), T()), 0);
  }
  EXPECT_EQ(r.counters.rays_traced, total.trace.rays_traced);
  EXPECT_EQ(r.counters.texels_above_horizon, total.texels_above_horizon);
  EXPECT_EQ(r.counters.borrowed_texels, total.borrowed_texels);
  EXPECT_GT(r.counters.rays_traced, 0u);
}

TEST_F(SparseJobsTest, RankAndSparseJobsEqualTheKernelsCalledDirectly) {
  // The job mechanics with the paper's fallbacks only (the poor-fit fallback, which turns one
  // of this tiny grid's vertices dense, is tested in worker/sparse_precomputation_test.cpp;
  // its counter is checked against the kernel below).
  plan_.sparse.max_residual = 0;
  // Dense rows of every other ground vertex, computed directly.
  const std::vector<uint32_t> dense = {4, 6, 8, 16, 18, 20, 28, 30, 32};
  std::vector<DenseRow> rows(dense.size());
  for (std::size_t k = 0; k < dense.size(); ++k)
    SampleDenseRowAdaptive(sampler_, samples_[dense[k]], dense[k], plan_.angular, rows[k]);
  const int m = SparseRankResolution(plan_, 8);
  const std::size_t low_dim = 6u * m * m;
  std::vector<float> low(dense.size() * low_dim);
  for (std::size_t k = 0; k < dense.size(); ++k)
    DownsampleRow(rows[k].transport.data(), 8, m, low.data() + k * low_dim);

  // Two candidates with neighbours {0, 1, 3, 4}, {4, 5, 7, 8, 2}, one with none.
  const std::vector<std::vector<uint32_t>> lists = {{0, 1, 3, 4}, {4, 5, 7, 8, 2}, {}};
  RankJob rj;
  rj.low_dim = static_cast<uint32_t>(low_dim);
  rj.low_rows = low;
  rj.offsets = {0};
  for (const auto& l : lists) {
    rj.neighbors.insert(rj.neighbors.end(), l.begin(), l.end());
    rj.offsets.push_back(static_cast<uint32_t>(rj.neighbors.size()));
  }
  const SparseJobResult rr = DecodeSparseJobResult(
      ComputeSparseJob(sampler_, samples_, plan_,
                       EncodeRankJob({static_cast<uint32_t>(SparseJobKind::kRank), 0, 0, 3}, rj)));
  ASSERT_EQ(rr.weights.size(), 3u);
  for (std::size_t c = 0; c < 2; ++c) {
    std::vector<const float*> p;
    for (uint32_t k : lists[c]) p.push_back(low.data() + k * low_dim);
    EXPECT_EQ(rr.weights[c], std::max(1, LocalRank(p, low_dim, plan_.rank_threshold)));
  }
  EXPECT_EQ(rr.weights[2], plan_.max_neighbors);  // nothing known there

  // Sparse vertices 5 and 17 from neighbours {0, 1, 3, 4} and {3, 4, 6, 7}; 25 from two
  // (too few: falls back).
  const std::vector<uint32_t> vertices = {5, 17, 25};
  const std::vector<std::vector<uint32_t>> nbl = {{0, 1, 3, 4}, {3, 4, 6, 7}, {7, 8}};
  SparseJob sj;
  sj.texels = static_cast<uint32_t>(T());
  sj.vertices = vertices;
  sj.offsets = {0};
  for (const auto& l : nbl) {
    sj.neighbors.insert(sj.neighbors.end(), l.begin(), l.end());
    sj.offsets.push_back(static_cast<uint32_t>(sj.neighbors.size()));
  }
  for (const DenseRow& d : rows) {
    sj.transport.insert(sj.transport.end(), d.transport.begin(), d.transport.end());
    sj.visibility.insert(sj.visibility.end(), d.visibility.begin(), d.visibility.end());
    sj.feature.insert(sj.feature.end(), d.feature.begin(), d.feature.end());
  }
  sj.union_ids = dense;
  const SparseJobResult sr = DecodeSparseJobResult(ComputeSparseJob(
      sampler_, samples_, plan_,
      EncodeSparseJob({static_cast<uint32_t>(SparseJobKind::kSparse), 7, 20, 3}, sj)));
  ASSERT_EQ(sr.outcomes.size(), 3u);
  std::size_t at = 0;
  L1Options lo;
  lo.lambda = plan_.sparse.lambda;
  L1Solver solver(lo);
  for (std::size_t i = 0; i < 3; ++i) {
    std::vector<DenseNeighbor> nbs;
    for (uint32_t k : nbl[i])
      nbs.push_back({rows[k].transport.data(), rows[k].visibility.data(), rows[k].feature.data(),
                     samples_[dense[k]].normal});
    std::vector<float> row(T(), 0.0f);
    SparseStats st;
    const SparseOutcome o = ReconstructSparseRow(sampler_, samples_[vertices[i]], vertices[i], nbs,
                                                 plan_.sparse, solver, row.data(), st);
    EXPECT_EQ(sr.outcomes[i], static_cast<uint8_t>(o));
    if (o != SparseOutcome::kReconstructed) continue;
    ASSERT_LE((at + 1) * T(), sr.transport.size());
    EXPECT_EQ(std::memcmp(row.data(), sr.transport.data() + at * T(), T() * 4), 0);
    ++at;
  }
  EXPECT_EQ(at, 2u);  // both well-surrounded vertices are reconstructed
  EXPECT_EQ(at * T(), sr.transport.size());
  EXPECT_EQ(sr.outcomes[2], static_cast<uint8_t>(SparseOutcome::kTooFewNeighbors));
  EXPECT_EQ(sr.counters.fallback_too_few_neighbors, 1u);
  EXPECT_EQ(sr.counters.fallback_poor_fit, 0u);
  EXPECT_EQ(sr.counters.reconstructed, at);
  EXPECT_EQ(sr.counters.solved_lars + sr.counters.solved_admm + sr.counters.zero_systems, at);

  // Neighbours facing away (normals at more than acos(min_normal_cos) from the vertex's) are not
  // used: with all four turned over, vertex 5 has none left and falls back.
  SparseOptions opt = plan_.sparse;
  opt.min_normal_cos = 0.0;
  std::vector<DenseNeighbor> flipped;
  for (uint32_t k : nbl[0])
    flipped.push_back({rows[k].transport.data(), rows[k].visibility.data(), rows[k].feature.data(),
                       -samples_[dense[k]].normal});
  flipped[1].normal = samples_[dense[nbl[0][1]]].normal;  // one still faces the same way
  std::vector<float> row(T(), 0.0f);
  SparseStats st;
  EXPECT_EQ(ReconstructSparseRow(sampler_, samples_[5], 5, flipped, opt, solver, row.data(), st),
            SparseOutcome::kTooFewNeighbors);
  EXPECT_EQ(st.neighbors_dropped_by_normal, 3u);
  EXPECT_EQ(st.fallback_too_few_neighbors, 1u);
}

// The run's files in memory (farm/sparse_phase.cpp keeps them in the run folder).
class MemoryRowFiles final : public SparseRowFiles {
 public:
  MemoryRowFiles(std::size_t texels, int m) : T_(texels), m_(m) {}
  void ReadDense(uint32_t s, float* t, float* v, uint8_t* f) override {
    const Dense& d = dense.at(s);
    std::copy(d.t.begin(), d.t.end(), t);
    std::copy(d.v.begin(), d.v.end(), v);
    std::copy(d.f.begin(), d.f.end(), f);
  }
  void ReadLow(uint32_t s, float* low) override {
    std::copy(dense.at(s).low.begin(), dense.at(s).low.end(), low);
  }
  void WriteDense(uint32_t s, const float* t, const float* v, const uint8_t* f,
                  const float* low) override {
    dense[s] = {{t, t + T_}, {v, v + T_}, {f, f + T_}, {low, low + 6 * m_ * m_}};
  }
  void WriteRow(uint32_t s, const float* t) override { rows[s].assign(t, t + T_); }
  void RecordVariance(const std::string& step, uint64_t, uint64_t,
                      const std::string& sums) override {
    variance_steps.push_back(step);
    EXPECT_FALSE(sums.empty());
  }
  uint64_t WriteCrossValidation(uint64_t first, std::span<const uint32_t>,
                                std::span<const uint8_t> outcomes, const float*) override {
    cross_validated.push_back(first);
    return outcomes.size();
  }
  void Sync() override { ++syncs; }
  int low_resolution() const override { return m_; }

  struct Dense {
    std::vector<float> t, v;
    std::vector<uint8_t> f;
    std::vector<float> low;
  };
  std::map<uint32_t, Dense> dense;
  std::map<uint32_t, std::vector<float>> rows;
  std::vector<std::string> variance_steps;
  std::vector<uint64_t> cross_validated;
  int syncs = 0;

 private:
  std::size_t T_;
  int m_;
};

// Rows in place (docs/farm.md, "Where the rows go"): a dense job writes its rows and their
// downsampled rows into the files and returns the checksum of what it wrote; a rank job reads the
// downsampled rows, a sparse job its neighbours' rows from the files, and writes its
// reconstructed rows there: every value and checksum as when the rows travel in the messages.
TEST_F(SparseJobsTest, JobsWithRowsInPlaceEqualJobsWithRowsInTheMessages) {
  plan_.sparse.max_residual = 0;
  const int m = SparseRankResolution(plan_, 8);
  MemoryRowFiles files(T(), m);
  const TransportVariance mesh_rows =
      MakeTransportVariance(static_cast<uint32_t>(sampler_.layout().n()),
                            static_cast<uint32_t>(sampler_.options().rays_per_texel), {4, 36});
  const std::vector<uint32_t> dense = {4, 6, 8, 16, 18, 20, 28, 30, 32};
  const SparseJobHeader dh{static_cast<uint32_t>(SparseJobKind::kDense), 1, 0, dense.size()};
  const SparseJobResult plain = DecodeSparseJobResult(
      ComputeSparseJob(sampler_, samples_, plan_,
                       EncodeDenseJob(dh, DenseJob{dense, 0, "dense-initial"}), {}, &mesh_rows));
  EXPECT_THROW(ComputeSparseJob(sampler_, samples_, plan_,
                                EncodeDenseJob(dh, DenseJob{dense, kWriteRowsInPlace, "d"})),
               std::runtime_error);  // no files to write to
  const SparseJobResult kept = DecodeSparseJobResult(
      ComputeSparseJob(sampler_, samples_, plan_,
                       EncodeDenseJob(dh, DenseJob{dense, kWriteRowsInPlace, "dense-initial"}), {},
                       &mesh_rows, &files));
  EXPECT_EQ(kept.in_place, 1u);
  EXPECT_TRUE(kept.transport.empty() && kept.visibility.empty() && kept.variance.empty());
  EXPECT_FALSE(plain.variance.empty());
  EXPECT_EQ(kept.checksum, DenseResultChecksum(dense.size(), T(), plain.transport.data(),
                                               plain.visibility.data(), plain.feature.data()));
  EXPECT_EQ(kept.counters.ToVector(), plain.counters.ToVector());
  EXPECT_EQ(files.variance_steps, std::vector<std::string>{"dense-initial"});
  EXPECT_GE(files.syncs, 1);
  const std::size_t low_dim = 6u * m * m;
  std::vector<float> low(dense.size() * low_dim);
  for (std::size_t k = 0; k < dense.size(); ++k) {
    const MemoryRowFiles::Dense& d = files.dense.at(dense[k]);
    EXPECT_EQ(std::memcmp(d.t.data(), plain.transport.data() + k * T(), T() * 4), 0);
    EXPECT_EQ(std::memcmp(d.v.data(), plain.visibility.data() + k * T(), T() * 4), 0);
    EXPECT_EQ(std::memcmp(d.f.data(), plain.feature.data() + k * T(), T()), 0);
    DownsampleRow(plain.transport.data() + k * T(), 8, m, low.data() + k * low_dim);
    EXPECT_EQ(std::memcmp(d.low.data(), low.data() + k * low_dim, low_dim * 4), 0);
  }

  // A rank job: the same weights from the files' downsampled rows.
  RankJob rj;
  rj.low_dim = static_cast<uint32_t>(low_dim);
  rj.offsets = {0, 4, 9};
  rj.neighbors = {0, 1, 3, 4, 4, 5, 7, 8, 2};
  RankJob rk = rj;
  rj.low_rows = low;
  rk.in_place = kReadRowsInPlace;
  rk.union_ids = dense;
  const SparseJobHeader rh{static_cast<uint32_t>(SparseJobKind::kRank), 2, 0, 2};
  EXPECT_EQ(
      DecodeSparseJobResult(
          ComputeSparseJob(sampler_, samples_, plan_, EncodeRankJob(rh, rk), {}, nullptr, &files))
          .weights,
      DecodeSparseJobResult(ComputeSparseJob(sampler_, samples_, plan_, EncodeRankJob(rh, rj)))
          .weights);

  // A sparse job: the same outcomes, combinations and rows, the rows in the files.
  SparseJob sj;
  sj.texels = static_cast<uint32_t>(T());
  sj.vertices = {5, 17, 25};
  sj.offsets = {0, 4, 8, 10};
  sj.neighbors = {0, 1, 3, 4, 3, 4, 6, 7, 7, 8};
  sj.union_ids = dense;
  sj.step = "sparse-reconstruct";
  SparseJob sk = sj;
  sj.transport = plain.transport;
  sj.visibility = plain.visibility;
  sj.feature = plain.feature;
  sk.in_place = kReadRowsInPlace | kWriteRowsInPlace;
  const SparseJobHeader sh{static_cast<uint32_t>(SparseJobKind::kSparse), 3, 0, 3};
  const SparseJobResult a = DecodeSparseJobResult(
      ComputeSparseJob(sampler_, samples_, plan_, EncodeSparseJob(sh, sj), {}, &mesh_rows));
  const SparseJobResult b = DecodeSparseJobResult(
      ComputeSparseJob(sampler_, samples_, plan_, EncodeSparseJob(sh, sk), {}, &mesh_rows, &files));
  EXPECT_EQ(b.in_place, 1u);
  EXPECT_TRUE(b.transport.empty());
  EXPECT_EQ(a.outcomes, b.outcomes);
  EXPECT_EQ(a.combination, b.combination);  // the compact records decode to the same pairs
  ASSERT_EQ(a.combination.size(), 3u * 2 * plan_.max_neighbors);
  EXPECT_NE(a.combination[0], kNoSample);
  EXPECT_EQ(b.checksum, SparseResultChecksum(a.outcomes, a.transport, a.combination));
  std::size_t k = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    if (a.outcomes[i] != static_cast<uint8_t>(SparseOutcome::kReconstructed)) {
      EXPECT_EQ(files.rows.count(sj.vertices[i]), 0u);
      continue;
    }
    ASSERT_EQ(files.rows.count(sj.vertices[i]), 1u);
    EXPECT_EQ(std::memcmp(files.rows[sj.vertices[i]].data(), a.transport.data() + k * T(), T() * 4),
              0);
    ++k;
  }
  EXPECT_EQ(k, 2u);
  EXPECT_EQ(files.variance_steps.back(), "sparse-reconstruct");
}

TEST_F(SparseJobsTest, DamagedOrMalformedMessagesAreRejected) {
  const std::string ok =
      ComputeSparseJob(sampler_, samples_, plan_,
                       EncodeDenseJob({static_cast<uint32_t>(SparseJobKind::kDense), 0, 0, 1},
                                      DenseJob{{3}, 0, ""}));
  std::string damaged = ok;
  damaged[damaged.size() / 2] ^= 0x10;
  EXPECT_THROW(DecodeSparseJobResult(damaged), std::runtime_error);
  EXPECT_THROW(DecodeSparseJobResult(ok.substr(0, 20)), std::runtime_error);
  // A neighbour index outside the job's rows, and a sample that does not exist.
  RankJob bad;
  bad.low_dim = 4;
  bad.low_rows.assign(8, 1.0f);
  bad.offsets = {0, 1};
  bad.neighbors = {2};
  EXPECT_THROW(
      ComputeSparseJob(sampler_, samples_, plan_,
                       EncodeRankJob({static_cast<uint32_t>(SparseJobKind::kRank), 0, 0, 1}, bad)),
      std::runtime_error);
  EXPECT_THROW(
      ComputeSparseJob(sampler_, samples_, plan_,
                       EncodeDenseJob({static_cast<uint32_t>(SparseJobKind::kDense), 0, 0, 1},
                                      DenseJob{{9999}, 0, ""})),
      std::runtime_error);
}

TEST(SparseJobCountersTest, VectorRoundTripAndSum) {
  SparseJobCounters a;
  std::vector<uint64_t> v(SparseJobCounters::kCount);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = 3 * i + 1;
  a = SparseJobCounters::FromVector(v);
  EXPECT_EQ(a.ToVector(), v);
  SparseJobCounters b = a;
  b += a;
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(b.ToVector()[i], 2 * v[i]);
  // Older lines with fewer counters read the missing ones as 0.
  const std::vector<uint64_t> shorter(v.begin(), v.begin() + 4);
  EXPECT_EQ(SparseJobCounters::FromVector(shorter).texels_above_horizon, 0u);
  EXPECT_EQ(SparseJobCounters::FromVector(shorter).rays_below_horizon, v[3]);
}

TEST(SparseJournalTest, SparseLinesRoundTripAndDetectDamage) {
  JournalEntry e;
  e.phase = "dense-rank-2";
  e.rows = {35, 7};
  e.rows_checksum = 0xfedcba9876543210ULL;
  e.rank = 2;
  e.busy_seconds = 0.5;
  e.counters = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
  const std::string line = FormatJournalLine(e);
  EXPECT_EQ(line.rfind("sjob dense-rank-2 35 7 fedcba9876543210 2 0.500000 15 1 2 3", 0), 0u)
      << line;
  JournalEntry back;
  ASSERT_TRUE(ParseJournalLine(line, back));
  EXPECT_EQ(back.phase, e.phase);
  EXPECT_EQ(back.rows, e.rows);
  EXPECT_EQ(back.rows_checksum, e.rows_checksum);
  EXPECT_EQ(back.rank, 2);
  EXPECT_EQ(back.counters, e.counters);
  std::string damaged = line;
  damaged[6] = 'x';
  EXPECT_FALSE(ParseJournalLine(damaged, back));
  EXPECT_FALSE(ParseJournalLine(line.substr(0, line.size() - 3), back));
}

TEST(MortonKeyTest, FollowsSpaceAndClampsToTheBox) {
  const Vec3 lo{0, 0, 0}, hi{1, 1, 1};
  EXPECT_EQ(MortonKey({0, 0, 0}, lo, hi), 0u);
  EXPECT_EQ(MortonKey({1, 1, 1}, lo, hi), (1u << 30) - 1);
  EXPECT_EQ(MortonKey({2, -1, 5}, lo, hi), MortonKey({1, 0, 1}, lo, hi));
  // x is the lowest bit of each triple: the far corner of the first octant sorts before the
  // near corner of the next octant in x.
  EXPECT_LT(MortonKey({0.49, 0.49, 0.49}, lo, hi), MortonKey({0.51, 0.0, 0.0}, lo, hi));
  EXPECT_EQ(MortonKey({0.5, 0.5, 0.5}, {1, 1, 1}, {1, 1, 1}), 0u);  // a flat box
}

// run/sparse/combination.bin (the bounce phases' input) round-trips, and a damaged, truncated,
// foreign or inconsistent file is an InputError naming it, never a crash or a wrong read.
TEST(CombinationFileTest, RoundTripsAndRejectsHostileFiles) {
  const std::string path = ::testing::TempDir() + "/combination.bin";
  const uint64_t N = 5, slots = 2;
  std::vector<uint32_t> pairs(N * slots * 2, 0);
  for (uint64_t i = 0; i < N * slots; ++i) pairs[2 * i] = kNoSample;
  pairs[(3 * slots) * 2] = 1;  // sample 3 = 0.75 · row 1 + 0.25 · row 4
  pairs[(3 * slots) * 2 + 1] = std::bit_cast<uint32_t>(0.75f);
  pairs[(3 * slots + 1) * 2] = 4;
  pairs[(3 * slots + 1) * 2 + 1] = std::bit_cast<uint32_t>(0.25f);
  auto write = [&](const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; };
  auto read = [&](uint64_t n) {
    uint64_t s = 0;
    return ReadCombinationFile(path, n, s);
  };
  const std::string good = EncodeCombinationFile(N, slots, pairs);
  write(good);
  uint64_t s = 0;
  EXPECT_EQ(ReadCombinationFile(path, N, s), pairs);
  EXPECT_EQ(s, slots);
  EXPECT_THROW(read(N + 1), InputError);  // another run's
  std::string bad = good;
  bad[30] ^= 1;  // damaged
  write(bad);
  EXPECT_THROW(read(N), InputError);
  write(good.substr(0, good.size() - 9));  // truncated
  EXPECT_THROW(read(N), InputError);
  write("PRTCMB2" + good.substr(7));  // foreign magic
  EXPECT_THROW(read(N), InputError);
  std::vector<uint32_t> out_of_range = pairs;
  out_of_range[0] = static_cast<uint32_t>(N);  // names a sample the run lacks
  write(EncodeCombinationFile(N, slots, out_of_range));
  EXPECT_THROW(read(N), InputError);
  std::vector<uint32_t> nan = pairs;
  nan[(3 * slots) * 2 + 1] = std::bit_cast<uint32_t>(std::numeric_limits<float>::quiet_NaN());
  write(EncodeCombinationFile(N, slots, nan));
  EXPECT_THROW(read(N), InputError);
  write(EncodeCombinationFile(N, 3, pairs));  // slots that do not match the size
  EXPECT_THROW(read(N), InputError);
  std::filesystem::remove(path);
  EXPECT_THROW(read(N), InputError);  // missing
}

}  // namespace
}  // namespace prt
