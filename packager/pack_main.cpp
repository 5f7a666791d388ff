// prt-pack: packs a farm run folder into one .prtpack asset, inspects and verifies packs
// (docs/prtpack-format.md).
//
//   prt-pack pack RUN_DIR --out scene.prtpack     (also: prt-pack RUN_DIR --out scene.prtpack)
//   prt-pack pack --mesh a.off [--mesh b.obj ...] [--metadata m.json] --out x.prtpack
//   prt-pack inspect FILE
//   prt-pack verify FILE
//
// Exit status: 0 success; 1 the input could not be read or packed, or the pack failed
// verification (the reason on stderr); 2 usage error (bad or missing arguments).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "packager/prtpack_format.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_writer.h"
#include "packager/run_folder_pack.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/mesh.h"
#include "vocabulary/mesh_io.h"

#ifndef PRT_VERSION
#define PRT_VERSION "0"
#endif

namespace {

constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

int Pack(const std::string& run_dir, const std::vector<std::string>& meshes,
         const std::string& metadata, const std::string& out,
         const prt::pack::RunPackOptions& run_options, const prt::pack::WriterOptions& options) {
  prt::pack::PackInput input;
  if (!run_dir.empty()) {
    if (!meshes.empty() || !metadata.empty()) {
      std::fprintf(stderr, "prt-pack: give either a run folder or --mesh/--metadata, not both\n");
      return kExitUsage;
    }
    input = prt::pack::PackInputFromRunFolder(run_dir, run_options);
  } else {
    if (meshes.empty()) {
      std::fprintf(stderr, "prt-pack: pack needs a run folder or at least one --mesh\n");
      return kExitUsage;
    }
    for (const std::string& m : meshes) {
      input.meshes.push_back({std::filesystem::path(m).stem().string(),
                              prt::LoadMesh(m),
                              {0.8f, 0.8f, 0.8f},
                              false,
                              0});
    }
    if (!metadata.empty()) input.metadata_json = prt::ReadWholeFile(metadata);
  }
  prt::pack::WritePackFile(out, input, options);
  const prt::pack::PackReader reader = prt::pack::PackReader::OpenFile(out);
  // One line: what was written and that it reads back (`prt-pack inspect` for the details).
  std::cout << "wrote " << out << " (" << reader.file_size()
            << " bytes): " << prt::pack::VerifyPack(reader) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // `prt-pack run/ --out x` is `prt-pack pack run/ --out x`.
  std::vector<std::string> args(argv, argv + argc);
  if (args.size() > 1 && args[1] != "pack" && args[1] != "inspect" && args[1] != "verify" &&
      !args[1].empty() && args[1][0] != '-') {
    args.insert(args.begin() + 1, "pack");
  }
  std::vector<char*> arg_ptrs;
  for (std::string& a : args) arg_ptrs.push_back(a.data());

  CLI::App app{
      "prt-pack: builds, inspects and verifies .prtpack assets (docs/prtpack-format.md)."
      "\nExit status: 0 success, 1 unreadable input or failed verification, 2 usage "
      "error."};
  app.set_version_flag("--version", std::string("prt-pack ") + PRT_VERSION + " (.prtpack " +
                                        std::to_string(prt::pack::kVersionMajor) + "." +
                                        std::to_string(prt::pack::kVersionMinor) + ")");
  app.require_subcommand(1);

  std::string run_dir, out, metadata;
  std::vector<std::string> meshes;
  prt::pack::RunPackOptions run_options;
  prt::pack::WriterOptions options;
  CLI::App* pack = app.add_subcommand("pack", "Pack a farm run folder (or meshes) into a .prtpack");
  pack->add_option("run", run_dir, "Run folder written by prt-farm")->check(CLI::ExistingDirectory);
  pack->add_option("--out,-o", out, "Output .prtpack file")->required();
  pack->add_option("--mesh", meshes, "Mesh file (PLY/OBJ/OFF/STL) to pack without a run folder")
      ->check(CLI::ExistingFile);
  pack->add_option("--metadata", metadata, "JSON object stored in META (with --mesh)")
      ->check(CLI::ExistingFile);
  pack->add_option("--transport", run_options.transport_file,
                   "Compressed transport file (default: RUN/transport.prtc)")
      ->check(CLI::ExistingFile);
  pack->add_flag("--geometry-only", run_options.geometry_only,
                 "Pack a run folder that has no compressed transport yet");
  pack->add_option("--columns-per-block", run_options.columns_per_block,
                   "Transport columns per independently compressed block")
      ->check(CLI::Range(1u, 1u << 24))
      ->capture_default_str();
  pack->add_option("--position-bits", options.position_bits, "Draco position quantisation bits")
      ->check(CLI::Range(8, 30))
      ->capture_default_str();
  pack->add_option("--normal-bits", options.normal_bits, "Draco normal quantisation bits")
      ->check(CLI::Range(6, 30))
      ->capture_default_str();
  pack->add_option("--zstd-level", options.zstd_level, "zstd level for META and transport")
      ->check(CLI::Range(1, 22))
      ->capture_default_str();
  pack->add_option("--alignment", options.alignment, "Section alignment (64 or 4096 for mmap)")
      ->check(CLI::IsMember(
          {64u, 128u, 256u, 512u, 1024u, 2048u, 4096u, 8192u, 16384u, 32768u, 65536u}))
      ->capture_default_str();

  std::string file;
  CLI::App* inspect = app.add_subcommand("inspect", "Print sections, sizes and a scene summary");
  inspect->add_option("file", file, ".prtpack file")->required();
  bool meta = false;
  inspect->add_flag("--meta", meta, "Print the META section's JSON as well (the run's report)");
  CLI::App* verify = app.add_subcommand("verify", "Check every checksum and structural rule");
  verify->add_option("file", file, ".prtpack file")->required();

  try {
    app.parse(static_cast<int>(arg_ptrs.size()), arg_ptrs.data());
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitUsage;
  }
  try {
    if (*pack) return Pack(run_dir, meshes, metadata, out, run_options, options);
    const prt::pack::PackReader reader = prt::pack::PackReader::OpenFile(file);
    if (*inspect) std::cout << prt::pack::InspectPack(reader);
    if (*inspect && meta) std::cout << "META: " << reader.ReadMetadata() << "\n";
    if (*verify) std::cout << prt::pack::VerifyPack(reader) << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-pack: %s\n", e.what());
    return kExitFailure;
  }
}
