#!/usr/bin/env python3
"""Figures of the workspace's shape: largest files, longest lines, CLI lines, and the module
import graph of each crate outside unit tests (import circles, and the files in them). Standard
library only.

Run from the repository root: python3 tools/house_metrics.py
"""
import os
import re
import sys

ROOT = os.getcwd()
SKIP = {"target", ".git", "fixtures"}


def rust_files(top):
    for d, subdirs, files in os.walk(top):
        subdirs[:] = [s for s in subdirs if s not in SKIP]
        for f in files:
            if f.endswith(".rs"):
                yield os.path.join(d, f)


def crates():
    """(name, src dir) of every crate: the root package and each workspace member with a src/."""
    found = [("vkdiff", os.path.join(ROOT, "src"))]
    for entry in sorted(os.listdir(ROOT)):
        src = os.path.join(ROOT, entry, "src")
        if os.path.isfile(os.path.join(ROOT, entry, "Cargo.toml")) and os.path.isdir(src):
            found.append((entry, src))
    return found


def module_of(src, path):
    rel = os.path.relpath(path, src)[:-3].split(os.sep)
    if rel[-1] in ("mod", "lib", "main"):
        rel = rel[:-1]
    return tuple(rel)


PATH = re.compile(r"\b(crate|super|self)((?:::\w+)+)")
USE_STMT = re.compile(r"\buse\s+((?:crate|super|self)::[^;]*);")
REEXPORT = re.compile(r"\bpub(?:\([\w:]+\))?\s+use\s+(\w+)::([^;]*);")


def expand(tree):
    """`a::{b, c::{d}}` → ["a::b", "a::c::d"]."""
    tree = re.sub(r"\s+", "", tree)
    if "{" not in tree:
        return [tree]
    head, rest = tree.split("{", 1)
    inner = rest[: rest.rindex("}")]
    parts, depth, cur = [], 0, ""
    for ch in inner:
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        depth += ch == "{"
        depth -= ch == "}"
        cur += ch
    parts.append(cur)
    return [p for part in parts if part for p in expand(head + part)]


def edges(src, files):
    modules = {module_of(src, f): f for f in files}
    # Unit tests (`#[cfg(test)]`, at the end of a file) may use any module: not part of the graph.
    texts = {
        m: re.sub(r"//[^\n]*", "", open(p, encoding="utf-8").read()).split("#[cfg(test)]")[0]
        for m, p in modules.items()
    }
    # Names a directory module re-exports from its children: (module, name) → child.
    reexports = {}
    for m, text in texts.items():
        for child, items in REEXPORT.findall(text):
            for item in expand(items):
                name = item.split("::")[-1].split(" as ")[-1]
                if m + (child,) in modules:
                    reexports[(m, name)] = m + (child,)
    graph = {m: set() for m in modules}
    for module, path in modules.items():
        is_dir_module = os.path.basename(path) in ("mod.rs", "lib.rs", "main.rs")
        text = texts[module]
        paths = [p for tree in USE_STMT.findall(text) for p in expand(tree)]
        paths += [h + t for h, t in PATH.findall(USE_STMT.sub("", text))]
        for full in paths:
            head, *parts = full.split("::")
            if head == "crate":
                base = ()
            else:
                base = module if is_dir_module else module[:-1]
                if head == "super":
                    base = base[:-1]
            target, rest = base, list(parts)
            while rest and target + (rest[0],) in modules:
                target += (rest.pop(0),)
            while rest and (target, rest[0]) in reexports:
                target = reexports[(target, rest.pop(0))]
            if target != module and target in modules:
                graph[module].add(target)
    return graph


def cycles(graph):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    sys.setrecursionlimit(10000)
    for v in graph:
        if v not in index:
            visit(v)
    return out


def main():
    all_files = list(rust_files(ROOT))
    sizes = sorted(((sum(1 for _ in open(f, encoding="utf-8")), f) for f in all_files), reverse=True)
    print("largest files (lines):")
    for n, f in sizes[:5]:
        print(f"  {n:5d} {os.path.relpath(f, ROOT)}")
    longest = max((len(line.rstrip("\n")), f) for f in all_files for line in open(f, encoding="utf-8"))
    print(f"longest line: {longest[0]} characters ({os.path.relpath(longest[1], ROOT)})")
    cli = [f for f in rust_files(os.path.join(ROOT, "src"))]
    print(f"CLI (src/): {len(cli)} files, {sum(sum(1 for _ in open(f)) for f in cli)} lines")
    total_circles = 0
    for name, src in crates():
        files = list(rust_files(src))
        circles = cycles(edges(src, files))
        total_circles += len(circles)
        print(f"{name}: {len(files)} files, {len(circles)} import circles")
        for c in circles:
            print("    " + " <-> ".join("::".join(m) or "(root)" for m in c))
    print(f"import circles in all crates: {total_circles}")


main()
