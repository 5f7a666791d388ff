#!/usr/bin/env python3
"""Line counts of C++ functions (and, with --classes, of classes), longest first.

    scripts/function-lengths.py farm/              # the 10 longest functions under farm/
    scripts/function-lengths.py -n 20 farm/*.cpp   # the 20 longest in these files
    scripts/function-lengths.py --classes farm/    # classes and structs too

A function's length is the number of lines from the line of its name to the line of its closing
brace, both included (its body's lambdas and local classes count as its own lines). A brace
matcher, not a parser: comments, string and character literals and preprocessor lines are blanked
first, then every '{' outside a function is classified by the text before it (since the last
';', '{' or '}'): "namespace"/"class"/"struct"/"union" open a scope whose functions are named
Scope::name, a ')' followed only by qualifiers (const, override, noexcept, a trailing return type,
a constructor's initialiser list) opens a function, anything else (enum bodies, brace
initialisers) is skipped. Good enough for this repository's style (clang-formatted), which is
what it is for: the numbers issue 37 asks for before and after a split.
"""
import argparse
import os
import re
import signal
import sys


def blank(text):
    """Comments, literals and preprocessor lines replaced by spaces (newlines kept)."""
    out = []
    i, n = 0, len(text)
    line_start = True
    while i < n:
        c = text[i]
        if line_start and c == "#":
            # A preprocessor line, with its continuations.
            while i < n and text[i] != "\n":
                if text[i] == "\\" and i + 1 < n and text[i + 1] == "\n":
                    out.append(" \n")
                    i += 2
                    continue
                out.append(" ")
                i += 1
            continue
        if c == "/" and text.startswith("//", i):
            while i < n and text[i] != "\n":
                out.append(" ")
                i += 1
            continue
        if c == "/" and text.startswith("/*", i):
            end = text.find("*/", i + 2)
            end = n if end < 0 else end + 2
            out.append(re.sub(r"[^\n]", " ", text[i:end]))
            i = end
            continue
        m = re.match(r'(?:u8|u|U|L)?R"([^(\s]*)\(', text[i:i + 40]) if c in 'uULR' else None
        if m and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            close = ")" + m.group(1) + '"'
            end = text.find(close, i + m.end())
            end = n if end < 0 else end + len(close)
            out.append('""' + re.sub(r"[^\n]", " ", text[i + 2:end]))
            i = end
            continue
        if c in "\"'":
            # A literal; a ' between digits is a digit separator (1'000), not a quote.
            if c == "'" and i > 0 and text[i - 1].isalnum() and i + 1 < n and text[i + 1].isalnum():
                out.append(" ")
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            out.append(c + " " * (min(j, n - 1) - i - 1) + c)
            i = j + 1
            continue
        out.append(c)
        line_start = c == "\n" or (line_start and c in " \t")
        i += 1
    return "".join(out)


QUALIFIERS = re.compile(
    r"\)\s*(?:(?:const|override|final|noexcept(?:\([^()]*\))?|mutable|volatile|&&?|"
    r"->\s*[\w:<>,\s*&]+)\s*)*$")
CONTAINER = re.compile(r"\b(namespace|class|struct|union)\b\s*([\w:]*)")
NAME = re.compile(r"((?:[\w~]+\s*(?:<[^()]*?>)?::)*(?:operator\s*(?:\(\)|[^\s(]+)|~?\w+))\s*\(")
ACCESS = re.compile(r"^\s*(?:(?:public|private|protected)\s*:)?\s*")


def is_function(header):
    h = header.strip()
    if not h or re.match(r"(?:if|for|while|switch|catch|do|else|return)\b", h):
        return False
    if re.search(r"\)\s*:\s*[\w:]+\s*[({]", h) and not CONTAINER.match(h):
        return True  # a constructor with an initialiser list
    return bool(QUALIFIERS.search(h)) and "(" in h and not re.search(r"=\s*\[", h)


def function_name(header):
    h = " ".join(header.split())
    m = re.match(r"([A-Z][A-Z0-9_]+)\s*\((.*)\)\s*$", h)  # TEST(Suite, Name) and friends
    if m:
        return m.group(1) + "(" + m.group(2) + ")"
    m = NAME.search(h)
    return re.sub(r"\s+", "", m.group(1)) if m else h[:60]


def measure(path):
    """[(kind, name, first line, last line)] of the functions (and classes) in `path`."""
    with open(path, encoding="utf-8", errors="replace") as f:
        text = blank(f.read())
    found = []
    # Each open scope: (kind, name, start line); kind: "scope" (namespace/class), "function",
    # "block" (inside a function, or an initialiser/enum body).
    stack = []
    header_start = 0
    line = 1
    for i, c in enumerate(text):
        if c == "\n":
            line += 1
        if c not in "{};":
            continue
        in_function = any(k == "function" for k, _, _ in stack)
        if c == ";":
            if not in_function:
                header_start = i + 1
            continue
        if c == "}":
            if stack:
                kind, name, start = stack.pop()
                if kind == "function" or (kind == "class"):
                    found.append((kind, name, start, line))
            if not any(k == "function" for k, _, _ in stack):
                header_start = i + 1
            continue
        # '{'
        if in_function:
            stack.append(("block", "", line))
            continue
        header = ACCESS.sub("", text[header_start:i])
        header_line = line - text[header_start + (len(text[header_start:i]) - len(header)):i].count("\n")
        # The header's first non-blank line.
        lead = len(header) - len(header.lstrip())
        header_line += header[:lead].count("\n")
        scope = "::".join(n for k, n, _ in stack if k == "class")
        cm = CONTAINER.match(header.strip())
        if cm and "(" not in header:
            kind = "class" if cm.group(1) in ("class", "struct", "union") else "scope"
            name = cm.group(2).split("::")[-1] if cm.group(1) == "namespace" else cm.group(2)
            if kind == "class" and scope:
                name = scope + "::" + name
            stack.append((kind, name if kind == "class" else (name or ""), header_line))
        elif is_function(header):
            name = function_name(header)
            cls = [n for k, n, _ in stack if k == "class"]
            if cls and "::" not in name:
                name = cls[-1] + "::" + name
            stack.append(("function", name, header_line))
        else:
            stack.append(("block", "", line))
        header_start = i + 1
    return found


def main():
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # quiet under `| head`
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("paths", nargs="+", help="files or folders (*.cpp, *.h, *.hpp)")
    ap.add_argument("-n", type=int, default=10, help="how many to list (0: all)")
    ap.add_argument("--classes", action="store_true", help="list classes and structs too")
    ap.add_argument("--files", action="store_true", help="also list the files' line counts")
    args = ap.parse_args()
    files = []
    for p in args.paths:
        if os.path.isdir(p):
            for root, _, names in os.walk(p):
                files += [os.path.join(root, n) for n in names
                          if n.endswith((".cpp", ".cc", ".h", ".hpp"))]
        elif os.path.isfile(p):
            files.append(p)
        else:
            ap.error(f"{p}: no such file or folder")
    rows = []
    for path in sorted(files):
        for kind, name, first, last in measure(path):
            if kind == "class" and not args.classes:
                continue
            rows.append((last - first + 1, kind, name, path, first))
    rows.sort(key=lambda r: (-r[0], r[3], r[4]))
    if args.files:
        for path in sorted(files, key=lambda p: -sum(1 for _ in open(p, errors="replace"))):
            with open(path, errors="replace") as f:
                print(f"{sum(1 for _ in f):6d}  {path}")
        print()
    for length, kind, name, path, first in rows[:args.n or None]:
        tag = "" if kind == "function" else f" ({kind})"
        print(f"{length:6d}  {name}{tag}  {path}:{first}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
