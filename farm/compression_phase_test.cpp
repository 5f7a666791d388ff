// The MPI-free parts of the compression phase (farm/compression_phase.h): column ownership and
// chunk shares partition exactly, chunk sizes follow the budget in whole file blocks, the report
// report carries the phase's figures last, and the bandwidth probes return positive rates.
// The distributed transpose itself runs under mpirun in tests/ (distributed_transpose_mpi_check,
// compression_phase_mpi_tests).
#include "farm/compression_phase.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "farm/distributed_transpose.h"
#include "farm/farm_report.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

TEST(CompressionPhase, OwnedColumnsAndChunkSharesPartitionExactly) {
  for (uint32_t cols : {1u, 7u, 384u, 6144u})
    for (int ranks = 1; ranks <= 9; ++ranks) {
      uint32_t next = 0;
      for (int r = 0; r < ranks; ++r) {
        const auto [a, b] = OwnedColumns(cols, r, ranks);
        EXPECT_EQ(a, next);
        EXPECT_LE(b - a, cols / ranks + 1);
        EXPECT_GE(b - a, cols / ranks);
        next = b;
      }
      EXPECT_EQ(next, cols);
      uint64_t row = 100;
      for (int r = 0; r < ranks; ++r) {
        const auto [f, c] = ChunkShare(100, cols, r, ranks);
        EXPECT_EQ(f, row);
        row += c;
      }
      EXPECT_EQ(row, 100u + cols);
    }
}

TEST(CompressionPhase, ChunkRowsAreWholeBlocksWithinAQuarterOfTheBudget) {
  const uint64_t row = 24576;                                   // n = 32
  EXPECT_EQ(ChunkRows(row, 256, 1024, 100000), 256u);           // at least one block
  EXPECT_EQ(ChunkRows(row, 256, 1ull << 30, 100000), 2560u);    // 64 MiB cap: 10 blocks
  EXPECT_EQ(ChunkRows(row, 256, 200ull << 20, 100000), 2048u);  // 50 MiB: 8 blocks
  EXPECT_EQ(ChunkRows(row, 256, 1ull << 30, 300), 300u);        // never past the end
  EXPECT_EQ(ChunkRows(1536, 16, 4096, 72), 16u);
}

TEST(CompressionPhase, ReportCarriesThePhaseLastAndOnlyWhenItRan) {
  FarmReport rep;
  rep.status = "ok";
  rep.wall_seconds = 12.5;
  rep.phases = {{"setup", 0.5}, {"compress", 2}};
  EXPECT_FALSE(nlohmann::json::parse(rep.ToJsonText()).contains("compression"));
  CompressionFarmReport& r = rep.compression;
  r.enabled = true;
  r.wall_seconds = 2;
  r.raw_bytes = 8000000;
  r.compressed_bytes = 400000;
  r.transpose_seconds = 0.5;
  r.bytes_moved = 4000000;
  r.spill_bytes = 123;
  r.terms = 99;
  EXPECT_DOUBLE_EQ(r.TransposeMbPerSecond(), 16.0);
  EXPECT_DOUBLE_EQ(r.PhaseMbPerSecond(), 4.0);
  EXPECT_DOUBLE_EQ(r.Ratio(), 0.05);
  const nlohmann::ordered_json j = nlohmann::ordered_json::parse(rep.ToJsonText());
  EXPECT_EQ(j["status"], "ok");
  EXPECT_DOUBLE_EQ(j["wall_seconds"].get<double>(), 12.5);
  ASSERT_EQ(j["phases"].size(), 2u);
  EXPECT_EQ(j["phases"][1]["name"], "compress");
  EXPECT_EQ(j.back(), j["compression"]);  // the last key, where readers of older reports found it
  EXPECT_EQ(j["compression"]["spill_bytes"], 123);
  EXPECT_EQ(j["compression"]["terms"], 99);
  EXPECT_DOUBLE_EQ(j["compression"]["ratio_to_raw"].get<double>(), 0.05);
  EXPECT_DOUBLE_EQ(j["compression"]["transpose_mb_per_second"].get<double>(), 16.0);
  EXPECT_FALSE(j["compression"].contains("memory_bandwidth_mb_per_second"));
}

TEST(CompressionPhase, BandwidthProbesArePositive) {
  EXPECT_GT(MeasureMemoryBandwidth(4u << 20), 0.0);
  const std::string dir = std::filesystem::temp_directory_path().string();
  EXPECT_GT(MeasureDiskWriteBandwidth(dir, 1u << 20), 0.0);
  EXPECT_THROW(MeasureDiskWriteBandwidth("/nonexistent-prt-dir", 1024), FileIoError);
}

}  // namespace
}  // namespace prt
