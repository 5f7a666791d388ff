# The source files of the libraries prt_runtime links (vocabulary core, formats, pack reader,
# runtime), named once for the two builds that compile them: the native one (vocabulary/,
# packager/ and the folder globs of prt_library in PrtWarnings.cmake) and the WebAssembly one
# (web/wasm/CMakeLists.txt, docs/web.md).

# prt_vocabulary_core, relative to vocabulary/. The mesh file importers are a separate list: the
# runtime never reads a mesh file, and the WebAssembly build leaves them out (Emscripten 3.1.6's
# libc++ has no floating-point std::from_chars).
set(PRT_VOCABULARY_CORE_SOURCES
    cubemap.cpp cubemap_resample.cpp durable_file.cpp envmap.cpp hash.cpp huge_pages.cpp mesh.cpp
    parallel.cpp scene_geometry.cpp wavelet_filter.cpp wavelet_synthesis_simd.cpp wavelets.cpp)
set(PRT_VOCABULARY_MESH_IMPORT_SOURCES
    mesh_formats.cpp mesh_io.cpp mesh_obj.cpp mesh_off.cpp mesh_ply.cpp mesh_stl.cpp)

# prt_pack_reader, relative to packager/.
set(PRT_PACK_READER_SOURCES prtpack_reader.cpp prtpack_c_api.cpp prtpack_checksum.cpp
                            prtpack_transport.cpp draco_mesh_codec.cpp)

# prt_folder_sources(out dir): a stage library's sources when it is the whole folder: every .cpp
# in `dir` that is neither a test (*_test.cpp), an entry point (*_main.cpp) nor a fuzz harness.
function(prt_folder_sources out dir)
  file(GLOB srcs CONFIGURE_DEPENDS ${dir}/*.cpp)
  list(FILTER srcs EXCLUDE REGEX "(_test|_main|_fuzz)\\.cpp$")
  set(${out} ${srcs} PARENT_SCOPE)
endfunction()
