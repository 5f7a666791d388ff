// Blocked transpose with sorted runs spilled to disk (Cheslack-Postava et al. 2008 §4.4 step 3).
#include "worker/block_spill.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "vocabulary/huge_pages.h"

namespace prt {
namespace {
std::atomic<uint64_t> g_transposer_id{0};
}

struct BlockTransposer::Impl {
  struct Entry {
    uint32_t block;
    uint64_t row;
    std::size_t offset;  // into pool
  };
  // A spilled run being merged: records (u32 block, u64 row, width floats), sorted.
  struct Run {
    std::string path;
    std::ifstream in;
    bool has = false;
    uint32_t block = 0;
    uint64_t row = 0;
    void Next() {
      has = false;
      if (in.read(reinterpret_cast<char*>(&block), 4) && in.read(reinterpret_cast<char*>(&row), 8))
        has = true;
    }
  };

  uint64_t rows;
  uint32_t begin, end;
  BlockSpillOptions opt;
  uint32_t nblocks;
  std::vector<float> pool;
  // Direct mode, when every owned row fits the budget at once: the rows are written straight
  // into their column blocks (blocks[b], column-major: [k·rows + r]) as they arrive, and
  // NextColumnBlock hands each block out without a copy. The same values as the buffered path
  // (pool, entries, merge), minus one copy and one first touch of the owned data.
  bool direct = false;
  std::vector<std::vector<float>> blocks;
  std::vector<Entry> entries;
  std::vector<uint8_t> seen;
  std::vector<std::unique_ptr<Run>> runs;
  uint64_t spilled_bytes = 0;
  uint64_t id;
  bool finished = false;
  uint32_t next_block = 0;
  std::size_t entry_cursor = 0;

  uint32_t Width(uint32_t b) const {
    return std::min(opt.columns_per_block, end - begin - b * opt.columns_per_block);
  }
  void SortEntries() {
    std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
      return a.block != b.block ? a.block < b.block : a.row < b.row;
    });
  }
  void Spill() {
    if (entries.empty()) return;
    SortEntries();
    auto run = std::make_unique<Run>();
    run->path = (std::filesystem::path(opt.spill_dir) /
                 ("prt-spill-" + std::to_string(::getpid()) + "-" + std::to_string(id) + "-" +
                  std::to_string(runs.size()) + ".run"))
                    .string();
    {
      std::ofstream out(run->path, std::ios::binary | std::ios::trunc);
      if (!out) throw std::runtime_error(run->path + ": cannot create spill run");
      for (const Entry& e : entries) {
        out.write(reinterpret_cast<const char*>(&e.block), 4);
        out.write(reinterpret_cast<const char*>(&e.row), 8);
        out.write(reinterpret_cast<const char*>(pool.data() + e.offset),
                  static_cast<std::streamsize>(Width(e.block) * sizeof(float)));
        spilled_bytes += 12 + Width(e.block) * sizeof(float);
      }
      out.flush();
      if (!out) throw std::runtime_error(run->path + ": write failed (disk full?)");
    }
    runs.push_back(std::move(run));
    entries.clear();
    pool.clear();
  }
};

BlockTransposer::BlockTransposer(uint64_t rows, uint32_t column_begin, uint32_t column_end,
                                 BlockSpillOptions options)
    : impl_(std::make_unique<Impl>()) {
  if (column_end <= column_begin || options.columns_per_block == 0)
    throw std::invalid_argument("BlockTransposer: empty column range or block width");
  Impl& m = *impl_;
  m.rows = rows;
  m.begin = column_begin;
  m.end = column_end;
  m.opt = std::move(options);
  m.nblocks = (column_end - column_begin + m.opt.columns_per_block - 1) / m.opt.columns_per_block;
  m.seen.assign(rows, 0);
  const uint64_t owned_bytes = rows * (column_end - column_begin) * sizeof(float);
  m.direct = owned_bytes <= m.opt.memory_budget_bytes;
  if (m.direct) {
    m.blocks.resize(m.nblocks);
    for (uint32_t b = 0; b < m.nblocks; ++b) {
      ReserveFreshHuge(m.blocks[b], static_cast<std::size_t>(m.Width(b)) * rows);
      m.blocks[b].resize(static_cast<std::size_t>(m.Width(b)) * rows);
    }
  } else {
    // Reserve the row buffer once (growing a budget-sized vector by doubling dominated the
    // in-memory transpose: reallocation copies and repeated page faults), in huge pages: its
    // first touch was most of AddRows' time (docs/farm-compression.md).
    ReserveFreshHuge(m.pool, static_cast<std::size_t>(m.opt.memory_budget_bytes / 4));
  }
  m.id = g_transposer_id++;
}

BlockTransposer::~BlockTransposer() {
  for (auto& r : impl_->runs) {
    r->in.close();
    std::error_code ec;
    std::filesystem::remove(r->path, ec);
  }
}

void BlockTransposer::AddRows(uint64_t first_row, uint64_t count, const float* data,
                              std::size_t stride) {
  Impl& m = *impl_;
  if (m.finished) throw std::invalid_argument("BlockTransposer: rows added after the merge began");
  if (first_row + count > m.rows || first_row + count < first_row)
    throw std::invalid_argument("BlockTransposer: row range out of bounds");
  const std::size_t width = m.end - m.begin;
  if (stride < width) throw std::invalid_argument("BlockTransposer: stride < owned columns");
  for (uint64_t r = first_row; r < first_row + count; ++r)
    if (m.seen[r]) throw std::invalid_argument("BlockTransposer: row added twice");
  for (uint64_t r = first_row; r < first_row + count; ++r) m.seen[r] = 1;
  if (m.direct) {
    for (uint32_t b = 0; b < m.nblocks; ++b) {
      const uint32_t w = m.Width(b);
      float* const dst = m.blocks[b].data() + first_row;
      const float* const src = data + static_cast<std::size_t>(b) * m.opt.columns_per_block;
      for (uint64_t r = 0; r < count; ++r) {
        const float* row = src + r * stride;
        for (uint32_t k = 0; k < w; ++k) dst[k * m.rows + r] = row[k];
      }
    }
    return;
  }
  for (uint64_t r = 0; r < count; ++r) {
    const float* row = data + r * stride;
    for (uint32_t b = 0; b < m.nblocks; ++b) {
      m.entries.push_back({b, first_row + r, m.pool.size()});
      const float* src = row + static_cast<std::size_t>(b) * m.opt.columns_per_block;
      m.pool.insert(m.pool.end(), src, src + m.Width(b));
    }
    if (m.pool.size() * sizeof(float) + m.entries.size() * sizeof(Impl::Entry) >
        m.opt.memory_budget_bytes)
      m.Spill();
  }
}

bool BlockTransposer::NextColumnBlock(uint32_t& first_column, uint32_t& count,
                                      std::vector<float>& columns) {
  Impl& m = *impl_;
  if (!m.finished) {
    if (std::find(m.seen.begin(), m.seen.end(), 0) != m.seen.end())
      throw std::invalid_argument("BlockTransposer: not every row was added");
    m.SortEntries();
    for (auto& r : m.runs) {
      r->in.open(r->path, std::ios::binary);
      if (!r->in) throw std::runtime_error(r->path + ": cannot reopen spill run");
      r->Next();
    }
    m.finished = true;
  }
  if (m.next_block >= m.nblocks) return false;
  const uint32_t b = m.next_block++;
  const uint32_t w = m.Width(b);
  first_column = m.begin + b * m.opt.columns_per_block;
  count = w;
  if (m.direct) {
    columns.swap(m.blocks[b]);
    std::vector<float>().swap(m.blocks[b]);
    return true;
  }
  // A consumer that keeps the blocks (the global budget's stash) hands back an empty vector:
  // each block is then fresh memory, advised for huge pages before its first touch.
  ReserveFreshHuge(columns, static_cast<std::size_t>(w) * m.rows);
  columns.assign(static_cast<std::size_t>(w) * m.rows, 0.0f);
  std::vector<float> rec(w);
  auto scatter = [&](uint64_t row, const float* v) {
    for (uint32_t k = 0; k < w; ++k) columns[k * m.rows + row] = v[k];
  };
  // Every source is sorted by (block, row): take this block's records from each in turn.
  for (auto& r : m.runs) {
    while (r->has && r->block == b) {
      if (!r->in.read(reinterpret_cast<char*>(rec.data()),
                      static_cast<std::streamsize>(w * sizeof(float))))
        throw std::runtime_error(r->path + ": spill run truncated");
      scatter(r->row, rec.data());
      r->Next();
    }
  }
  while (m.entry_cursor < m.entries.size() && m.entries[m.entry_cursor].block == b) {
    const auto& e = m.entries[m.entry_cursor++];
    scatter(e.row, m.pool.data() + e.offset);
  }
  return true;
}

uint64_t BlockTransposer::runs_spilled() const {
  return impl_->runs.size();
}
uint64_t BlockTransposer::bytes_spilled() const {
  return impl_->spilled_bytes;
}

}  // namespace prt
