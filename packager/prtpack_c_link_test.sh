#!/bin/sh
# prtpack_c_link_test.sh CC CXX SOURCE_DIR WORK READER.a FORMATS.a CORE.a PACK [LINK_FLAGS]
# Builds packager/prtpack_c_test.c against packager/prtpack.h with the embeddable reader's link
# line alone (its three archives, Draco, zstd, xxHash, the C++ runtime) and runs it on PACK. An
# unresolved symbol from any other library (OpenEXR, libpng, toml++, spdlog, TBB, Embree, MPI)
# fails the link, and so this test. LINK_FLAGS: what the archives were built with that the link
# needs too (-fsanitize=... in a sanitizer build).
set -eu
CC=$1 CXX=$2 SRC=$3 WORK=$4 READER=$5 FORMATS=$6 CORE=$7 PACK=$8 FLAGS=${9:-}
mkdir -p "$WORK"
"$CC" -std=c99 -Wall -Werror -I"$SRC" -c "$SRC/packager/prtpack_c_test.c" -o "$WORK/prtpack_c_test.o"
# shellcheck disable=SC2086 # FLAGS is a list of flags
"$CXX" $FLAGS "$WORK/prtpack_c_test.o" "$READER" "$FORMATS" "$CORE" -ldraco -lzstd -lxxhash \
  -o "$WORK/prtpack_c_test_reader_only"
"$WORK/prtpack_c_test_reader_only" "$PACK"
