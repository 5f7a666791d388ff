// From the farm's run folder (formats/run_folder.h, formats/transport_file.h) to .prtpack inputs,
// and a readable summary of a pack: the library side of `prt-pack pack` and `prt-pack inspect`.
#pragma once

#include <cstdint>
#include <string>

#include "formats/run_folder.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_writer.h"

namespace prt::pack {

struct RunPackOptions {
  // Compressed transport file; empty means <run>/transport.prtc.
  std::string transport_file;
  // Pack geometry and metadata only when the run has no compressed transport.
  bool geometry_only = false;
  uint32_t columns_per_block = 256;
};

// Reads <run>/geometry.prtg (meshes, albedo, ground grid), <run>/scene.toml (stored in META as
// "scene", converted to JSON, and each mesh's glossy material as "materials"), <run>/report.json
// (as "report"), the compressed transport (its header's settings as "parameters", its columns
// as TRNS blocks; a transport of scheme cpca, formats/cpca_transport.h, as the CPCA section, its
// clusters and bases in "parameters" too) and the visibility maps <run>/visibility.prtv (one VISB
// section per mesh, a summary as META "visibility"). Throws prt::InputError naming the file on: a
// missing geometry file, a damaged file, neither compressed transport nor visibility (unless
// geometry_only), a transport or visibility whose sample count differs from the geometry's vertex
// count.
PackInput PackInputFromRunFolder(const std::string& run_dir, const RunPackOptions& options);

// prt-pack inspect: version, sections (raw vs stored sizes, compression ratios), meshes and the
// transport's shape. Reads META, MATL and the TRNS index (checking their checksums) but does
// not decode meshes or blocks; a CPCA section is decoded (its clusters, bases, terms and
// coefficients are counted). Throws prt::InputError like the reader.
std::string InspectPack(const PackReader& reader);

// prt-pack verify: every rule of docs/prtpack-format.md ("Verification"), and, when the TRNS
// parameters are a compressed-transport header, every column block decoded and validated (and a
// CPCA transport decoded and validated, as VerifyAll does).
// Returns a one-line summary; throws prt::InputError with the first failure.
std::string VerifyPack(const PackReader& reader);

}  // namespace prt::pack
