// The compression phase for scheme "cpca" (issue #24; docs/cpca.md): clustered PCA of the
// finished transport, computed by all ranks, written to run/transport.prtc. Called by the
// compression phase (farm/compression_phase.cpp) once rank 0 has broadcast the header.
//
//   rows     every rank holds the rows CpcaRowRange gives it (whole units of 1024 rows), read
//            by itself where it sees the run folder (or sent by rank 0), row-transformed (§4.1
//            of Cheslack-Postava 2008, the lighting's Haar basis)
//   cluster  worker/cpca.h ComputeCpca with MPI reductions: distances and per-cluster sums on
//            the ranks holding the rows, sums as fixed-point integers (MPI_Allreduce of
//            int64), so no rank holds the whole matrix and the bytes are the same for any
//            number of ranks; a sparse run (run/sparse/combination.bin) takes Huang §6's dense
//            pass and re-clustering
//   output   rank 0 gathers every row's cluster id and coefficients and writes the file
//            durably (EncodeCpcaTransport)
// Like the column schemes, the phase writes nothing a later run depends on until
// transport.prtc is durable; an interrupted run resumes with --resume from the finished rows.
#pragma once

#include <functional>
#include <memory>

#include "formats/compressed_transport.h"

namespace prt {

struct FarmContext;
class ComposedTransport;

// rank 0 passes its open reader; `open_reader` opens one on another rank (where every rank sees
// the run folder). `start` is the phase's start time (FarmNow()).
void RunCpcaCompression(FarmContext& ctx, const CompressedTransportHeader& header,
                        std::unique_ptr<ComposedTransport>& reader,
                        const std::function<std::unique_ptr<ComposedTransport>()>& open_reader,
                        double start);

}  // namespace prt
