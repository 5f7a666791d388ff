#!/bin/sh
# runtime_c_link_test.sh CC CXX SOURCE_DIR WORK "ARCHIVES" PACK [LINK_FLAGS]
# Cuts the C example out of docs/runtime.md (the ```c block after "<!-- example -->"), compiles
# it as C99 with warnings as errors against runtime/prt_runtime.h, links it with the runtime's
# archives, Draco, zstd, xxHash and the C++ standard library alone, and runs it on PACK: an
# unresolved symbol from any other library (TBB, OpenEXR, libpng, toml++, spdlog, Embree, MPI)
# fails the link, and so this test.
set -eu
CC=$1 CXX=$2 SRC=$3 WORK=$4 ARCHIVES=$5 PACK=$6 FLAGS=${7:-}
mkdir -p "$WORK"
awk '/<!-- example -->/ { armed = 1; next }
     armed && /^```c$/ { inside = 1; next }
     inside && /^```$/ { exit }
     inside { print }' "$SRC/docs/runtime.md" > "$WORK/example.c"
test -s "$WORK/example.c" || { echo "no C example in docs/runtime.md"; exit 1; }
echo "example: $(wc -l < "$WORK/example.c") lines"
"$CC" -std=c99 -Wall -Wextra -Werror -pedantic -I"$SRC/runtime" -c "$WORK/example.c" -o "$WORK/example.o"
# shellcheck disable=SC2086 # ARCHIVES and FLAGS are lists
"$CXX" $FLAGS "$WORK/example.o" $ARCHIVES -ldraco -lzstd -lxxhash -lm -o "$WORK/example"
"$WORK/example" "$PACK"
