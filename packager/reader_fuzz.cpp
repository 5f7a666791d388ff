// libFuzzer harness for the .prtpack reader (docs/prtpack-format.md): every input is read twice,
// as is (the checksums stop almost every mutation at the header) and with its checksums
// recomputed (ResealChecksums), so that mutations reach the table rules, zstd, Draco, the TRNS
// index, the compressed-transport block decoders and the CPCA section's decoder. A prt::InputError
// is the expected outcome of a bad input; any other exception, crash, leak, hang or sanitizer
// report is a bug. Built only with clang (packager/CMakeLists.txt); run by CTest for a fixed number
// of runs on packager/fuzz_corpus/.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <vector>

#include "packager/prtpack_format.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_transport.h"
#include "packager/run_folder_pack.h"
#include "vocabulary/errors.h"

namespace {

void ReadAll(const std::vector<uint8_t>& bytes) {
  prt::pack::ReaderOptions options;
  options.max_section_bytes = 16 << 20;  // keep the fuzzer's memory bounded
  try {
    const prt::pack::PackReader r =
        prt::pack::PackReader::OpenMemory(bytes.data(), bytes.size(), "<fuzz>", options);
    (void)prt::pack::InspectPack(r);
    r.VerifyAll();
    for (std::size_t m = 0; m < r.mesh_count(); ++m) (void)r.ReadMesh(m);
    if (r.has_transport()) {
      const prt::pack::TransportIndex index = r.ReadTransportIndex();
      for (std::size_t b = 0; b < index.blocks.size(); ++b) (void)r.ReadTransportBlock(index, b);
      (void)prt::pack::VerifyPack(r);
    }
    if (r.has_cpca()) (void)prt::pack::ReadCpcaTransport(r);
  } catch (const prt::InputError&) {
    // A clear refusal: what the reader promises for bad input.
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reader_fuzz: not an InputError: %s\n", e.what());
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  std::vector<uint8_t> bytes(data, data + size);
  ReadAll(bytes);
  prt::pack::ResealChecksums(bytes);
  ReadAll(bytes);
  return 0;
}
