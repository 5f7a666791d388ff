// The farm's checkpoint journal (docs/farm.md, "Checkpoints"): run/checkpoints/journal.txt, one
// text line per finished job, appended and fsynced only after the job's rows are durable in
// transport.prtt.partial. A line carries the job's row range, the XXH64 of its rows (so resume
// can prove the rows on disk are the rows that were journaled) and its counters, and ends with
// the XXH64 of the line itself; a torn or damaged line (a kill mid-write) is ignored, which only
// loses that job.
//
//   prt-farm-journal 1 <run key, 16 hex>
//   job <first> <count> <rows xxh64> <rank> <rays> <texels traced> <texels below horizon>
//       <rays below horizon> <busy seconds> <line xxh64>          (one line)
//   sjob <phase> <first> <count> <result xxh64> <rank> <busy seconds> <k> <counter 1> …
//       <counter k> <line xxh64>        (a job of a sparse phase; first/count index the phase's
//                                        deterministic item list, docs/farm.md "Sparse method")
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "farm/job_planner.h"

namespace prt {

struct JournalEntry {
  RowRange rows;
  uint64_t rows_checksum = 0;
  int rank = 0;
  uint64_t rays_traced = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_below_horizon = 0;
  uint64_t rays_below_horizon = 0;
  double busy_seconds = 0;
  // Sparse method only: the phase ("dense-initial", "rank-1", …) and its counters
  // (SparseJobCounters, farm/sparse_jobs.h). Empty phase: a brute-force job line.
  std::string phase;
  std::vector<uint64_t> counters;
};

std::string FormatJournalLine(const JournalEntry& entry);
// False for a torn, damaged or foreign line.
bool ParseJournalLine(const std::string& line, JournalEntry& entry);

struct JournalContents {
  uint64_t run_key = 0;
  bool has_header = false;
  std::vector<JournalEntry> entries;
  int damaged_lines = 0;
};
// Reads a journal; a missing file gives an empty result. Throws InputError when unreadable.
JournalContents ReadJournal(const std::string& path);

class CheckpointJournal {
 public:
  // Writes the journal afresh (header + `entries`) durably, then opens it for appending.
  CheckpointJournal(const std::string& path, uint64_t run_key,
                    const std::vector<JournalEntry>& entries);
  ~CheckpointJournal();
  CheckpointJournal(const CheckpointJournal&) = delete;
  CheckpointJournal& operator=(const CheckpointJournal&) = delete;

  // Appends the lines and fsyncs; when this returns, the jobs count as done. FileIoError.
  void Append(const std::vector<JournalEntry>& entries);

 private:
  std::string path_;
  int fd_ = -1;
};

}  // namespace prt
