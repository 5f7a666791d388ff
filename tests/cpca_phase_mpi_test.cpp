// The compression phase with scheme cpca under mpirun (farm/cpca_phase.h, docs/cpca.md): on a
// scene of three 1024-row units, run/transport.prtc is byte-identical for 1, 2 and 3 ranks and
// with the rows sent by rank 0, and equal to the in-process CompressCpca on the farmed rows; the
// reported error is the decoded file's; a sparse run takes Huang §6's dense pass and
// re-clustering at about the error of standard CPCA on the same rows; a run killed while writing
// resumes to the same bytes without tracing.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "formats/cpca_transport.h"
#include "formats/transport_file.h"
#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"
#include "worker/cpca.h"
#include "worker/transport_compressor.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kScene = std::string(PRT_TESTS_DATA_DIR) + "/cpca_tiny.toml";
const std::string kArgs = " --rows-per-block 64 --quiet --force";

using testing::RunResult;

RunResult Farm(int ranks, const std::string& args) {
  testing::ApplyMpiTestEnvironment();
  return testing::RunPrtFarm(ranks, args);
}

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / ("cpca_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

nlohmann::json Report(const std::string& run) {
  return nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
}

CpcaTransport Decode(const std::string& bytes) {
  return DecodeCpcaTransport(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
      "transport.prtc");
}

// The farmed rows in the row-wavelet basis.
std::vector<float> RowsHat(const std::string& run, const CompressedTransportHeader& h) {
  TransportFileReader reader(run + "/transport.prtt");
  std::vector<float> T(reader.info().rows * reader.info().cols());
  reader.ReadRows(0, reader.info().rows, T.data());
  CompressionOptions o;
  PrepareRows(h, o, T.data(), reader.info().rows);
  return T;
}

double DecodedError(const CpcaTransport& t, const std::vector<float>& X) {
  return CpcaDecodedRelativeError(t, X.data());
}

TEST(CpcaPhase, ByteIdenticalForAnyRanksAndEqualToInProcess) {
  const std::string first = WorkDir("np2");
  const RunResult r = Farm(2, kScene + " --out " + first + kArgs);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string bytes = ReadWholeFile(first + "/transport.prtc");
  const CpcaTransport t = Decode(bytes);
  EXPECT_EQ(t.header.cpca_clusters, 24u);
  EXPECT_EQ(t.header.cpca_bases, 6u);
  EXPECT_EQ(t.header.cpca_method, CpcaMethod::kStandard);
  const std::vector<float> X = RowsHat(first, t.header);
  const std::vector<uint8_t> in_process =
      EncodeCpcaTransport(CompressCpca(X.data(), t.header, CpcaOptionsFrom(t.header)));
  EXPECT_TRUE(bytes == std::string(in_process.begin(), in_process.end()))
      << "transport.prtc differs from the in-process CompressCpca";
  const nlohmann::json c = Report(first)["compression"];
  EXPECT_EQ(c["scheme"], "cpca");
  EXPECT_EQ(c["compressed_bytes"], bytes.size());
  EXPECT_EQ(c["cpca"]["method"], "standard");
  EXPECT_EQ(c["cpca"]["rows_dense_pass"], 2312u);
  const double reported = c["relative_frobenius_error"].get<double>();
  EXPECT_GT(reported, 0.0);
  EXPECT_LT(reported, 0.5);
  EXPECT_NEAR(reported, DecodedError(t, X), 1e-5 * reported);
  for (const auto& [ranks, extra] :
       std::vector<std::pair<int, std::string>>{{1, ""}, {3, ""}, {2, " --rows-via-rank0"}}) {
    SCOPED_TRACE(std::to_string(ranks) + " rank(s)" + extra);
    const std::string run = WorkDir("np" + std::to_string(ranks) + (extra.empty() ? "" : "_r0"));
    const RunResult o = Farm(ranks, kScene + " --out " + run + kArgs + extra);
    ASSERT_EQ(o.exit_code, 0) << o.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == bytes);
  }
}

// A sparse run: the dense pass on the dense rows, every sparse row joins a dense neighbour's
// cluster, one re-clustering iteration (Huang §6). Its error is close to standard CPCA's on the
// same rows, with far fewer projection distances; 1 and 2 ranks give the same bytes.
TEST(CpcaPhase, SparseRunTakesTheDensePassAndReclustering) {
  const std::string run = WorkDir("sparse");
  const RunResult r = Farm(2, kScene + " --out " + run + kArgs + " --method sparse");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string bytes = ReadWholeFile(run + "/transport.prtc");
  const CpcaTransport t = Decode(bytes);
  EXPECT_EQ(t.header.cpca_method, CpcaMethod::kDenseRecluster);
  const nlohmann::json c = Report(run)["compression"];
  EXPECT_EQ(c["cpca"]["method"], "dense-recluster");
  const uint64_t dense_rows = c["cpca"]["rows_dense_pass"].get<uint64_t>();
  EXPECT_GT(dense_rows, 0u);
  EXPECT_LT(dense_rows, 2312u / 2);
  const std::vector<float> X = RowsHat(run, t.header);
  const double huang = c["relative_frobenius_error"].get<double>();
  EXPECT_NEAR(huang, DecodedError(t, X), 1e-5 * huang);
  CompressedTransportHeader h = t.header;
  h.cpca_method = CpcaMethod::kStandard;
  CpcaStats standard;
  CompressCpca(X.data(), h, CpcaOptionsFrom(h), nullptr, &standard);
  EXPECT_LT(huang, 1.5 * standard.relative_error) << "standard " << standard.relative_error;
  EXPECT_LT(c["cpca"]["distance_evaluations"].get<uint64_t>(), standard.distance_evaluations);
  const std::string one = WorkDir("sparse_np1");
  ASSERT_EQ(Farm(1, kScene + " --out " + one + kArgs + " --method sparse").exit_code, 0);
  EXPECT_TRUE(ReadWholeFile(one + "/transport.prtc") == bytes);
}

// Killed halfway through writing transport.prtc: --resume traces nothing and writes the bytes
// of an uninterrupted run.
TEST(CpcaPhase, KilledWhileWritingResumesToTheSameBytes) {
  const std::string reference = WorkDir("kill_reference");
  ASSERT_EQ(Farm(2, kScene + " --out " + reference + kArgs).exit_code, 0);
  const std::string run = WorkDir("kill_write");
  const RunResult killed =
      Farm(2, kScene + " --out " + run + kArgs + " --fail-in write --fail-rank 0");
  EXPECT_EQ(killed.exit_code, 4) << killed.output;
  EXPECT_FALSE(fs::exists(run + "/transport.prtc"));
  const RunResult resumed =
      Farm(2, kScene + " --out " + run + " --rows-per-block 64 --quiet --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_EQ(Report(run)["rays_traced"], 0);
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") ==
              ReadWholeFile(reference + "/transport.prtc"));
  EXPECT_FALSE(fs::exists(run + "/transport.prtc.tmp"));
}

}  // namespace
}  // namespace prt
