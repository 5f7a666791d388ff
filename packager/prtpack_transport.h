// The compressed transport (formats/compressed_transport.h) in a .prtpack TRNS section:
// the encoded CompressedTransportHeader is the section's global parameters, and each block of
// `columns_per_block` columns is one EncodeColumnBlock byte string, zstd-compressed on its own,
// so that a runtime decodes only the blocks it needs (docs/prtpack-format.md, "TRNS").
// A clustered-PCA transport (formats/cpca_transport.h) is the CPCA section instead (1.3).
#pragma once

#include <cstddef>
#include <cstdint>

#include "formats/compressed_transport.h"
#include "formats/cpca_transport.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_writer.h"

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

// The CPCA section's transport (PackReader::ReadCpcaTransport: checksum, zstd, the section's
// sizes, the header of scheme cpca agreeing with the section, DecodeCpcaBody). Throws
// prt::InputError naming the pack if it has no CPCA section (a TRNS pack) or any check fails.
CpcaTransport ReadCpcaTransport(const PackReader& reader);

}  // namespace prt::pack
