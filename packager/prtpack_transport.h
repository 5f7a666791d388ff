// The compressed transport (formats/compressed_transport.h) in a .prtpack TRNS section:
// the encoded CompressedTransportHeader is the section's global parameters, and each block of
// `columns_per_block` columns is one EncodeColumnBlock byte string, zstd-compressed on its own,
// so that a runtime decodes only the blocks it needs (docs/prtpack-format.md, "TRNS").
#pragma once

#include <cstddef>
#include <cstdint>

#include "packager/prtpack_reader.h"
#include "packager/prtpack_writer.h"
#include "formats/compressed_transport.h"

namespace prt::pack {

// Splits `t` into blocks of `columns_per_block` (≥ 1) columns. Throws prt::InputError if the
// header or a column is invalid (the vocabulary encoders validate what they write).
TransportInput MakeTransportInput(const CompressedTransport& t, uint32_t columns_per_block = 256);

// The header stored in the TRNS parameters. Throws prt::InputError (naming the pack) if the pack
// has no TRNS section or the parameters do not decode, or if the header's sample (row), column
// or channel counts disagree with the section's.
CompressedTransportHeader ReadCompressedTransportHeader(const PackReader& reader,
                                                        const TransportIndex& index);
// Block `b` decoded (checksum, decompression and column-block validation). Throws
// prt::InputError if any fails or the block's columns differ from the index's.
CompressedColumnBlock ReadCompressedColumnBlock(const PackReader& reader,
                                                const TransportIndex& index,
                                                const CompressedTransportHeader& header,
                                                std::size_t b);
// Every block, as one CompressedTransport (columns sorted, all-zero columns absent).
CompressedTransport ReadCompressedTransport(const PackReader& reader);

}  // namespace prt::pack
