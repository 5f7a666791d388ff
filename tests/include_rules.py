#!/usr/bin/env python3
"""The house rules of docs/architecture.md, checked on the source tree (ctest: include_rules).

1. A folder includes only its own floor and those below it (tests, *_test.cpp, *_main.cpp and the
   fuzz harness may reach higher: they are programs, not libraries).
2. <mpi.h> only under farm/ and in the MPI test programs of tests/.
3. No include cycle between modules (a module is x.h with its x.cpp: compressed_transport.cpp
   including a header that includes compressed_transport.h is a cycle the header split hides).
4. No library source starts another program (std::system, popen) outside the executables'
   files (*_main.cpp, bench/, viewer/rotation_plot.cpp).
5. The embeddable floor (runtime/, the pack reader, formats/, the core vocabulary) includes none
   of the heavier libraries' headers (TBB, OpenEXR, libpng, toml++, spdlog, Embree, MPI).
Prints every violation and exits 1 if there is any.
"""
import os, re, sys

ROOT = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FLOOR = {"vocabulary": 1, "formats": 2, "worker": 3, "packager": 3, "runtime": 3, "farm": 4, "viewer": 4,
         "bench": 5, "tests": 6}
INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]', re.M)

def sources():
    for folder in FLOOR:
        for dirpath, _, names in os.walk(os.path.join(ROOT, folder)):
            for n in names:
                if n.endswith((".h", ".cpp", ".c")):
                    yield os.path.relpath(os.path.join(dirpath, n), ROOT)

HEAVY = re.compile(r'^\s*#\s*include\s*<((?:tbb|OpenEXR|Imath|toml\+\+|spdlog|embree3)/[^>]*|png\.h|mpi\.h)>', re.M)
def kind_heavy(text):
    m = HEAVY.search(text)
    return m.group(1) if m else None

def is_program(path):
    n = os.path.basename(path)
    return (n.endswith(("_test.cpp", "_main.cpp", "_fuzz.cpp", "_test.c", "_check.cpp"))
            or path.startswith(("tests/", "bench/")) or n == "prtpack_test_util.h"
            or n == "window_test_support.h" or n == "grid_scene_test_support.h")

problems = []
graph = {}
for path in sources():
    text = open(os.path.join(ROOT, path), encoding="utf-8", errors="replace").read()
    folder = path.split("/")[0]
    graph[path] = []
    for kind, inc in INCLUDE.findall(text):
        if kind == "<" and inc == "mpi.h" and folder != "farm" and not path.startswith("tests/"):
            problems.append(f"{path}: includes <mpi.h> (MPI lives in farm/)")
        if kind != '"':
            continue
        top = inc.split("/")[0]
        if top not in FLOOR:
            continue
        graph[path].append(inc)
        if FLOOR[top] > FLOOR[folder] and not is_program(path):
            problems.append(f"{path}: includes {inc} from a floor above ({top} over {folder})")
    if (folder == "runtime" and not is_program(path)) and kind_heavy(text):
        problems.append(f"{path}: includes {kind_heavy(text)} (runtime/ links the embeddable reader's libraries only)")
    if re.search(r"std::system\s*\(|\bpopen\s*\(", text) and not (
            is_program(path) or path == "viewer/rotation_plot.cpp"):
        problems.append(f"{path}: starts another program (only executables may)")

# Module cycles (depth-first search over module → module edges; tests and programs excluded).
def module(path):
    return os.path.splitext(path)[0]
edges = {}
for path, deps in graph.items():
    if is_program(path):
        continue
    m = module(path)
    edges.setdefault(m, set()).update(module(d) for d in deps if module(d) != m)
state = {}
def visit(m, stack):
    state[m] = 1
    stack.append(m)
    for d in sorted(edges.get(m, ())):
        if state.get(d) == 1:
            problems.append("include cycle: " + " -> ".join(stack[stack.index(d):] + [d]))
        elif d in edges and not state.get(d):
            visit(d, stack)
    stack.pop()
    state[m] = 2
for m in sorted(edges):
    if not state.get(m):
        visit(m, [])

for p in problems:
    print(p)
print(f"include_rules: {len(graph)} files, {len(problems)} violation(s)")
sys.exit(1 if problems else 0)
