#!/usr/bin/env python3
"""Structure measures of the workspace's crates (core, coordinator, worker, proto, tools/sweep).

Run it from the repository root, with nothing to install (Python 3.8 or later):

    python3 tools/structure.py            # print the findings; exit status 0
    python3 tools/structure.py --check    # exit status 1 when there is any finding
    python3 tools/structure.py --why      # also print, under each import cycle, the lines that make its edges

It prints one line per finding and a final summary line. Only the crates' non-test code counts: `#[cfg(test)]`
items and the files of `#[cfg(test)] mod x;` are left out, and so are comments and the insides of string
literals. Measures:
- files of `*/src` with more than `--max-file-lines` (500) code lines (non-blank lines of that code);
- functions with more than `--max-fn-lines` (80) code lines between the lines of their braces;
- file-level import cycles inside each crate: an edge goes from a file to the file that each path in its code
  names (`use crate::a::b…`, `crate::a::b::…`, `use super::x`, `super::x::…`, `self::x::…`, `child::x` for a
  module the file declares, and names brought in by `use`), resolved to the file of the longest prefix of the
  path that is a module file (`a/b.rs` or `a/b/mod.rs`, then `a.rs` or `a/mod.rs`). A folder's `mod.rs` that
  only declares `pub mod child;` has no edge to the child; one that names the child's items (`pub use
  child::X`, `child::f()`) has. `core/tests/module_layers.rs` and `coordinator/tests/module_layers.rs` check
  the same graph;
- `#[allow(clippy::too_many_arguments)]` (or `expect`);
- tests of the method enum outside the file that defines it (`core/src/method.rs`): `matches!(…, Method::…)`,
  `== Method::…`, `!= Method::…` and `Method::… =>` match arms. The rest of the workspace asks `Method`'s own
  questions instead.
"""
import argparse
import functools
import os
import re
import sys
from collections import defaultdict

CRATES = ("core", "coordinator", "worker", "proto", "tools/sweep")
METHOD_FILE = os.path.join("core", "src", "method.rs")
SKIPPED_DIRS = ("tests", "benches", "examples")


# ---------------------------------------------------------------------------------------------------- lexing
def lex(text):
    """`text` with comments blanked (spaces), the insides of string and char literals replaced by `s` and the names
    of lifetimes by `l`; newlines are kept, so offsets and line numbers stay those of the file."""
    out, i, n = [], 0, len(text)

    def blank(s, fill):
        return "".join("\n" if c == "\n" else fill for c in s)

    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(blank(text[i:j], " "))
            i = j
        elif (m := re.compile(r'b?r(#*)"').match(text, i)) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            close = '"' + m.group(1)
            j = text.find(close, m.end())
            j = n if j < 0 else j
            out.append(text[i:m.end()] + blank(text[m.end():j], "s") + close)
            i = j + len(close)
        elif c == '"' or (c == "b" and text.startswith('b"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_"))):
            start = i + (2 if c == "b" else 1)
            j = start
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(text[i:start] + blank(text[start:j], "s") + '"')
            i = j + 1
        elif c == "'":
            m = re.compile(r"'(\\(x[0-9a-fA-F]{2}|u\{[0-9a-fA-F]{1,6}\}|.)|[^\\'\n])'").match(text, i)
            if m:  # a char literal
                out.append("'" + "s" * (m.end() - i - 2) + "'")
                i = m.end()
            else:  # a lifetime or a label: its name is no item's (`&'static T` defines no `T`)
                w = re.compile(r"\w*").match(text, i + 1)
                out.append("'" + "l" * (w.end() - i - 1))
                i = w.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching(code, open_at):
    """The offset just after the bracket that closes the one at `open_at` (brackets of any kind nest)."""
    depth, j = 0, open_at
    while j < len(code):
        ch = code[j]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
            if depth == 0:
                return j + 1
        j += 1
    return len(code)


def item_end(code, start):
    """The end of the item that begins at `start`: its `;` outside brackets, or the `}` closing its body."""
    j = start
    while j < len(code):
        ch = code[j]
        if ch == ";":
            return j + 1
        if ch in "([":
            j = matching(code, j)
            continue
        if ch == "{":
            j = matching(code, j)
            k = j
            while k < len(code) and code[k] in " \t\r\n":
                k += 1
            return k + 1 if k < len(code) and code[k] == ";" else j
        j += 1
    return len(code)


CFG_TEST = re.compile(r"#\[cfg\(test\)\]")
ATTRIBUTE = re.compile(r"\s*#\[")


def strip_tests(code):
    """(`code` with every `#[cfg(test)]` item blanked, the names of the `#[cfg(test)] mod name;` it declares)."""
    if re.search(r"#!\[cfg\(test\)\]", code):
        return re.sub(r"[^\n]", " ", code), set()
    test_mods, parts, i = set(), [], 0
    for m in CFG_TEST.finditer(code):
        if m.start() < i:
            continue
        j = m.end()
        while (a := ATTRIBUTE.match(code, j)):  # further attributes of the same item
            j = matching(code, a.end() - 1)
        end = item_end(code, j)
        d = re.match(r"\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", code[j:end])
        if d:
            test_mods.add(d.group(1))
        parts.append(code[i:m.start()])
        parts.append(re.sub(r"[^\n]", " ", code[m.start():end]))
        i = end
    parts.append(code[i:])
    return "".join(parts), test_mods


@functools.lru_cache(maxsize=None)
def read_code(path):
    """The lexed, test-free code of a file, and the test modules it declares."""
    with open(path, encoding="utf-8", errors="replace") as f:
        return strip_tests(lex(f.read()))


def line_of(text, offset):
    return text.count("\n", 0, offset) + 1


def code_lines(text):
    return sum(1 for line in text.splitlines() if line.strip())


# ---------------------------------------------------------------------------------------------------- files
def module_of(rel):
    """The module path of a file, from its path under `src`: `a/b.rs` and `a/b/mod.rs` are `a::b`."""
    parts = rel[:-3].split("/")
    if parts[-1] == "mod" or parts == ["lib"] or parts == ["main"]:
        parts = parts[:-1]
    return tuple(parts)


def crate_files(crate, binaries=False):
    """{module path: path under src} of the files of a crate's library (or binary, when it has no library; or of
    every target with `binaries`), less the files of test modules."""
    src = os.path.join(crate, "src")
    rels = []
    for base, dirs, files in os.walk(src):
        dirs.sort()
        for f in sorted(files):
            if f.endswith(".rs"):
                rels.append(os.path.relpath(os.path.join(base, f), src).replace(os.sep, "/"))
    has_lib = "lib.rs" in rels
    # A binary beside a library is a crate of its own that reaches the library by its name.
    if has_lib and binaries:
        rels = [r for r in rels if r == "main.rs" or r.startswith("bin/")]
        found = {}
        for root in rels:  # each binary is a crate of its own: its modules are relative to it
            base = root[:-3] if root.startswith("bin/") and root.count("/") == 1 else os.path.dirname(root)
            inner = [r for r in rels if r == root or (root != "main.rs" and r.startswith(base + "/"))]
            found.update({(root,) + m: r for m, r in without_tests(src, inner).items()})
        return {**found, **crate_files(crate)}
    rels = [r for r in rels if not (has_lib and (r == "main.rs" or r.startswith("bin/")))]
    return without_tests(src, rels)


def without_tests(src, rels):
    mods = {module_of(r): r for r in rels}
    tests = set()
    for m, r in mods.items():
        _, test_mods = read_code(os.path.join(src, r))
        tests |= {m + (t,) for t in test_mods}
    return {m: r for m, r in mods.items() if not any(m[: len(t)] == t for t in tests)}


# ---------------------------------------------------------------------------------------------------- paths
def use_trees(body):
    """The leaves of a `use` tree: [(segments, bound name or None for a glob)]."""
    toks = re.findall(r"::|[{},*]|\w+", body)
    leaves = []

    def tree(i, prefix):
        path = list(prefix)
        while i < len(toks):
            t = toks[i]
            if t == "::":
                i += 1
            elif t == "{":
                i += 1
                while i < len(toks) and toks[i] != "}":
                    i = tree(i, path)
                    if i < len(toks) and toks[i] == ",":
                        i += 1
                return i + 1
            elif t == "*":
                leaves.append((path, None))
                return i + 1
            elif t in (",", "}"):
                break
            else:
                path.append(t)
                i += 1
                if i + 1 < len(toks) and toks[i] == "as":
                    if path[-1] == "self":
                        path.pop()
                    leaves.append((path, toks[i + 1]))
                    return i + 2
                if i < len(toks) and toks[i] == "::":
                    continue
                if path[-1] == "self":
                    path.pop()
                leaves.append((path, path[-1] if path else None))
                return i
        return i

    tree(0, [])
    return [(p, name) for p, name in leaves if p]


INLINE_MOD = re.compile(r"\bmod\s+(\w+)\s*\{")
USE = re.compile(r"\buse\s+([^;]*);")
CODE_PATH = re.compile(r"(?<![\w:])(\w+)((?:\s*::\s*\w+)+)")
VISIBILITY = re.compile(r"\bpub\s*\(\s*in\s+[^)]*\)")


def absolute(segs, scope, mods, aliases):
    """The crate-absolute segments a path stands for, or None for a path outside the crate (`std::…`, `glam::…`)."""
    head = segs[0]
    if head == "crate":
        return list(segs[1:])
    if head in ("super", "self"):
        base = list(scope)
        k = 0
        while k < len(segs) and segs[k] in ("super", "self"):
            if segs[k] == "super":
                base = base[:-1]
            k += 1
        return base + list(segs[k:])
    if tuple(scope) + (head,) in mods:  # a module declared here
        return list(scope) + list(segs)
    if head in aliases:  # a name brought in by `use`
        return list(aliases[head]) + list(segs[1:])
    return None


def resolve(mods, target):
    """The longest prefix of `target` that is a module file (the crate root when none is)."""
    for k in range(len(target), -1, -1):
        if tuple(target[:k]) in mods:
            return tuple(target[:k])
    return None


def defines(code, name):
    """Whether `code` defines an item called `name` itself."""
    n = re.escape(name)
    return re.search(r"\b(?:fn|struct|enum|union|trait|type|const|static|mod)\s+" + n + r"\b|\bmacro_rules!\s*" + n + r"\b",
                     code) is not None


class Scan:
    """One file's paths: [(offset, path as written, crate-absolute target)], the names its `use`s bind, the modules
    it imports with a glob."""

    def __init__(self, m, code, mods):
        self.code = code = VISIBILITY.sub(lambda v: re.sub(r"[^\n]", " ", v.group(0)), code)
        inline = [(x.end() - 1, matching(code, x.end() - 1), x.group(1)) for x in INLINE_MOD.finditer(code)]

        def scope_at(offset):
            return m + tuple(name for a, b, name in inline if a < offset < b)

        self.refs, self.aliases, self.globs = [], {}, []
        for u in USE.finditer(code):
            for segs, name in use_trees(u.group(1)):
                target = absolute(segs, scope_at(u.start()), mods, self.aliases)
                if target is None:
                    continue
                if name is None:
                    self.globs.append(target)
                else:
                    self.aliases[name] = target
                self.refs.append((u.start(), "::".join(segs), target))
        rest = USE.sub(lambda u: re.sub(r"[^\n]", " ", u.group(0)), code)
        for p in CODE_PATH.finditer(rest):
            segs = [p.group(1)] + [x.strip() for x in p.group(2).split("::")[1:]]
            target = absolute(segs, scope_at(p.start()), mods, self.aliases)
            if target is not None:
                self.refs.append((p.start(), "::".join(segs), target))


def locate(mods, scans, target, seen=frozenset()):
    """The file that defines what `target` names: the longest prefix that is a module file, then, when that file
    does not define the next name itself but brings it in with a `use` (`pub use child::X`, `pub use types::*`),
    the file it comes from."""
    f = resolve(mods, target)
    if f is None or len(f) == len(target) or (f, target[len(f)]) in seen:
        return f
    name, rest, scan = target[len(f)], list(target[len(f) + 1:]), scans[f]
    if defines(scan.code, name):
        return f
    seen = seen | {(f, name)}
    if name in scan.aliases:
        return locate(mods, scans, list(scan.aliases[name]) + rest, seen)
    for g in scan.globs:
        g = tuple(g)
        if g in mods and (defines(scans[g].code, name) or name in scans[g].aliases):
            return locate(mods, scans, list(g) + [name] + rest, seen)
    return f


def file_edges(mods, src):
    """{file: {file it names: [(line, path as written)]}} over the files `mods` of a crate under `src`."""
    scans = {m: Scan(m, read_code(os.path.join(src, rel))[0], mods) for m, rel in mods.items()}
    edges = {r: defaultdict(list) for r in mods.values()}
    for m, rel in mods.items():
        for offset, written, target in scans[m].refs:
            dst = locate(mods, scans, target)
            if dst is not None and dst != m:
                edges[rel][mods[dst]].append((line_of(scans[m].code, offset), written))
    return edges


def cycles(edges, limit=200):
    """Every elementary cycle of the graph (up to `limit`), each as its list of nodes, first node repeated last."""
    nodes = sorted(edges)
    order = {v: k for k, v in enumerate(nodes)}
    found = []

    def walk(start, path, on_path):
        v = path[-1]
        for w in sorted(edges.get(v, ())):
            if len(found) >= limit:
                return
            if w == start:
                found.append(path + [start])
            elif order.get(w, -1) > order[start] and w not in on_path:
                on_path.add(w)
                walk(start, path + [w], on_path)
                on_path.discard(w)

    sys.setrecursionlimit(10000)
    for s in nodes:
        walk(s, [s], {s})
    return found


# ---------------------------------------------------------------------------------------------------- measures
FN = re.compile(r"\bfn\s+(\w+)")


def long_functions(code, limit):
    """[(code lines, line, name)] of the functions whose bodies have more than `limit` code lines."""
    found = []
    for f in FN.finditer(code):
        j = f.end()
        while j < len(code) and code[j] not in "{;":
            j = matching(code, j) if code[j] in "([" else j + 1
        if j >= len(code) or code[j] == ";":
            continue  # a declaration without a body
        end = matching(code, j)
        inner = code[j:end].split("\n")[1:-1]
        n = code_lines("\n".join(inner))
        if n > limit:
            found.append((n, line_of(code, f.start()), f.group(1)))
    return found


METHOD_PATH = r"(?:\w+::)*Method::\w+"
METHOD_COMPARED = re.compile(r"[!=]=\s*" + METHOD_PATH + r"|" + METHOD_PATH + r"\s*[!=]=")
METHOD_ARM = re.compile(METHOD_PATH + r"(?:\s*\|\s*" + METHOD_PATH + r")*\s*(?:if\b[^\n]*)?=>")
MATCHES = re.compile(r"\bmatches!\s*\(")


def method_tests(code):
    """Lines that test the method enum: `matches!(…, Method::…)`, `== Method::…`, `!= Method::…`, match arms."""
    lines = set()
    for m in MATCHES.finditer(code):
        inside = code[m.end() - 1:matching(code, m.end() - 1)]
        if re.search(r"\bMethod::\w+", inside):
            lines.add(line_of(code, m.start()))
    for m in METHOD_COMPARED.finditer(code):
        lines.add(line_of(code, m.start() + m.group(0).find("Method")))
    for m in METHOD_ARM.finditer(code):
        before = code[:m.start()].rstrip()
        before = before[:-1].rstrip() if before.endswith("|") else before
        if not before or before[-1] in "{,}":  # the pattern of an arm, not the end of an expression
            lines.add(line_of(code, m.start()))
    return sorted(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--max-file-lines", type=int, default=500, help="code lines a file may have (500)")
    ap.add_argument("--max-fn-lines", type=int, default=80, help="code lines a function may have (80)")
    ap.add_argument("--check", action="store_true", help="exit with status 1 when there is any finding")
    ap.add_argument("--why", action="store_true", help="print the lines behind each edge of an import cycle")
    args = ap.parse_args()
    if not os.path.isdir("core/src"):
        sys.exit("run tools/structure.py from the repository root")

    big, longf, allows, methods, cyc = [], [], [], [], []
    for crate in [c for c in CRATES if os.path.isdir(os.path.join(c, "src"))]:
        src = os.path.join(crate, "src")
        mods = crate_files(crate)
        for rel in sorted(set(crate_files(crate, binaries=True).values())):
            path = os.path.join(src, rel)
            if any(part in SKIPPED_DIRS for part in rel.split("/")[:-1]):
                continue
            code, _ = read_code(path)
            n = code_lines(code)
            if n > args.max_file_lines:
                big.append((n, path))
            longf += [(k, f"{path}:{line} {name}") for k, line, name in long_functions(code, args.max_fn_lines)]
            allows += [f"{path}:{line_of(code, a.start())}"
                       for a in re.finditer(r"#!?\[\s*(?:allow|expect)\s*\([^\]]*\btoo_many_arguments\b", code)]
            if path != METHOD_FILE:
                methods += [f"{path}:{line}" for line in method_tests(code)]
        edges = file_edges(mods, src)
        for c in cycles(edges):
            cyc.append((crate, c, edges))

    for n, p in sorted(big, reverse=True):
        print(f"file over {args.max_file_lines} code lines: {p} {n}")
    for n, f in sorted(longf, reverse=True):
        print(f"function over {args.max_fn_lines} code lines: {f} ({n})")
    for crate, c, edges in cyc:
        print("import cycle: " + " -> ".join(f"{crate}/src/{f}" for f in c))
        if args.why:
            for a, b in zip(c, c[1:]):
                line, written = edges[a][b][0]
                print(f"    {crate}/src/{a}:{line} names {written} ({b})")
    for a in allows:
        print(f"too_many_arguments: {a}")
    for t in methods:
        print(f"method tested outside {METHOD_FILE}: {t}")
    print(f"SUMMARY files>{args.max_file_lines}={len(big)} functions>{args.max_fn_lines}={len(longf)} "
          f"cycles={len(cyc)} too_many_arguments={len(allows)} method_tests_outside={len(methods)}")
    findings = len(big) + len(longf) + len(cyc) + len(allows) + len(methods)
    return 1 if args.check and findings else 0


if __name__ == "__main__":
    sys.exit(main())
