// Compressed transport ↔ TRNS section (docs/prtpack-format.md, "TRNS"; the column blocks are
// those of Cheslack-Postava et al. 2008 §4 as encoded by formats/compressed_transport.h).
#include "packager/prtpack_transport.h"

#include <algorithm>
#include <string>

#include "packager/prtpack_format.h"
#include "vocabulary/errors.h"

namespace prt::pack {

TransportInput MakeTransportInput(const CompressedTransport& t, uint32_t columns_per_block) {
  if (columns_per_block == 0) throw InputError("transport", "columns_per_block must be ≥ 1");
  TransportInput in;
  in.params = EncodeHeader(t.header);
  // EncodeHeader writes its magic (8 bytes) then its format version (u32).
  in.encoding = in.params.size() >= 12 ? LoadAt<uint32_t>(in.params, 8) : 0;
  in.row_count = t.header.sample_count;
  in.channels = t.header.channels;
  const uint32_t ncol = t.header.column_count();
  std::size_t k = 0;
  for (uint32_t first = 0; first < ncol; first += columns_per_block) {
    CompressedColumnBlock block;
    block.first_column = first;
    block.column_span = std::min(columns_per_block, ncol - first);
    while (k < t.columns.size() && t.columns[k].column < first + block.column_span) {
      if (t.columns[k].column < first) throw InputError("transport", "columns not sorted");
      block.columns.push_back(t.columns[k++]);
    }
    in.blocks.push_back({block.column_span, EncodeColumnBlock(t.header, block)});
  }
  if (k != t.columns.size()) throw InputError("transport", "columns not sorted or out of range");
  return in;
}

CompressedTransportHeader ReadCompressedTransportHeader(const PackReader& reader,
                                                        const TransportIndex& index) {
  CompressedTransportHeader h = DecodeHeader(index.params, reader.name() + ": TRNS parameters");
  if (h.sample_count != index.row_count || h.column_count() != index.column_count) {
    throw InputError(reader.name(),
                     "TRNS parameters disagree with the section's row or column "
                     "count");
  }
  if (h.channels != index.channels) {
    throw InputError(reader.name(), "TRNS parameters have " + std::to_string(h.channels) +
                                        " colour channel(s), the section " +
                                        std::to_string(index.channels));
  }
  return h;
}

CompressedColumnBlock ReadCompressedColumnBlock(const PackReader& reader,
                                                const TransportIndex& index,
                                                const CompressedTransportHeader& header,
                                                std::size_t b) {
  const std::vector<uint8_t> bytes = reader.ReadTransportBlock(index, b);
  const std::string where = reader.name() + ": transport block " + std::to_string(b);
  CompressedColumnBlock block = DecodeColumnBlock(header, bytes, where);
  const TransportBlockInfo& info = index.blocks[b];
  if (block.first_column != info.first_column || block.column_span != info.column_count) {
    throw InputError(where, "columns differ from the block index");
  }
  return block;
}

CompressedTransport ReadCompressedTransport(const PackReader& reader) {
  const TransportIndex index = reader.ReadTransportIndex();
  CompressedTransport t;
  t.header = ReadCompressedTransportHeader(reader, index);
  for (std::size_t b = 0; b < index.blocks.size(); ++b) {
    CompressedColumnBlock block = ReadCompressedColumnBlock(reader, index, t.header, b);
    for (CompressedColumn& c : block.columns) t.columns.push_back(std::move(c));
  }
  return t;
}

CpcaTransport ReadCpcaTransport(const PackReader& reader) {
  return reader.ReadCpcaTransport();
}

}  // namespace prt::pack
