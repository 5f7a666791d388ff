// The sparse reconstruction's own error, by cross-validation (docs/farm.md, "Accuracy
// estimates"): dense vertices reconstructed from the other dense vertices exactly as a sparse
// vertex is (Huang & Ramamoorthi 2010 §5), compared with their traced rows
// (FarmSparseSteps::CrossValidate, farm/sparse_steps.h).
#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "farm/sparse_steps.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace fs = std::filesystem;

std::vector<char> CrossValidationRecords(std::size_t T, std::span<const uint8_t> outcomes,
                                         const float* rows,
                                         const std::function<void(std::size_t, float*)>& traced) {
  const uint8_t ok = static_cast<uint8_t>(SparseOutcome::kReconstructed);
  const std::size_t record = 4 + 4 * T;
  std::vector<char> bytes(outcomes.size() * record, 0);
  std::vector<float> row(T);
  std::size_t k = 0;
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    char* rec = bytes.data() + i * record;
    rec[0] = static_cast<char>(outcomes[i]);
    if (outcomes[i] != ok) continue;
    traced(i, row.data());
    float* diff = reinterpret_cast<float*>(rec + 4);
    for (std::size_t j = 0; j < T; ++j) diff[j] = rows[k * T + j] - row[j];
    ++k;
  }
  return bytes;
}

void FarmSparseSteps::CrossValidate(const NeighborIndex& index, std::span<const uint32_t> dense,
                                    std::span<const uint32_t> order,
                                    std::span<const uint8_t> outcome) {
  const uint8_t ok = static_cast<uint8_t>(SparseOutcome::kReconstructed);
  const std::vector<uint32_t> initial =
      InitialDenseSet(N_, SparseInitialDenseCount(N_, ctx_.plan), ctx_.plan.seed);
  std::vector<uint32_t> cv;
  const std::size_t K = std::min<std::size_t>(kSparseCrossValidated, initial.size());
  for (std::size_t i = 0; i < K; ++i) cv.push_back(initial[i * initial.size() / K]);
  const std::size_t record = 4 + 4 * T_;
  SideFile file((fs::path(ctx_.folder.sparse) / "cross_validation.bin").string());
  if (ctx_.rows_in_place) WriteStepLists(StepListsPath(ctx_.folder, step_number_), dense, cv);
  StepJobs p;
  p.name = "cross-validate";
  p.kind = SparseJobKind::kSparse;
  p.items = cv.size();
  p.cross_validation = true;
  p.reuse = [&](const JournalEntry& e) {
    std::vector<char> bytes(static_cast<std::size_t>(e.rows.count) * record);
    return file.Read(bytes.data(), bytes.size(), e.rows.first * record) &&
           Checksum64(bytes.data(), bytes.size()) == e.rows_checksum;
  };
  p.make_job = [&](SparseJobHeader& h, std::string prefix) {
    return MakeSparseJob(h, std::move(prefix), index, cv, true, "cross-validate");
  };
  p.accept = [&](const SparseJobResult& r, uint64_t& rows_written) {
    const std::size_t c = static_cast<std::size_t>(r.header.count);
    if (r.outcomes.size() != c) throw RankFailure("a cross-validation job came back incomplete");
    rows_written = 0;
    if (r.in_place) {  // the worker wrote the records itself
      if (!r.transport.empty() || !ctx_.rows_in_place)
        throw RankFailure("a cross-validation job came back with rows it was to write itself");
      return r.checksum;
    }
    const std::size_t k =
        static_cast<std::size_t>(std::count(r.outcomes.begin(), r.outcomes.end(), ok));
    if (k * T_ != r.transport.size())
      throw RankFailure("a cross-validation job came back with the wrong number of rows");
    const std::vector<char> bytes = CrossValidationRecords(
        T_, r.outcomes, r.transport.data(), [&](std::size_t i, float* traced) {
          RowsStage(ctx_).writer->ReadRows(cv[r.header.first + i], 1, traced);
        });
    file.Write(bytes.data(), bytes.size(), r.header.first * record);
    return Checksum64(bytes.data(), bytes.size());
  };
  p.sync = [&] { file.Sync(); };
  RunStep(p);
  // Which vertices, and how many vertices of each mesh the pipeline reconstructed.
  std::vector<uint64_t> reconstructed(ctx_.RowGroups().size(), 0);
  for (std::size_t i = 0; i < order.size(); ++i)
    if (outcome[i] == ok) ++reconstructed[ctx_.GroupOfRow(order[i])];
  const nlohmann::json summary = {{"texels", T_},
                                  {"record_bytes", record},
                                  {"vertices", cv},
                                  {"reconstructed_per_mesh", reconstructed}};
  WriteFileDurably((fs::path(ctx_.folder.sparse) / "cross_validation.json").string(),
                   summary.dump() + "\n");
}

}  // namespace prt
