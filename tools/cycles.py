#!/usr/bin/env python3
"""Circles of imports between the modules of a crate; exits 1 if there is one.

Usage: tools/cycles.py SRC_DIR...   (e.g. src guiding/src lab/src)

A module uses another when its code (tests and comments aside) names a path through it:
`crate::a::b`, `super::b`, `crate::a::{b, c}`. Two kinds of edge count: between top-level
modules (`scene` -> `tracking`) and between sibling files of one directory
(`guided::distance` -> `guided::plain_flight`). A module naming its parent or its own children
is not an edge: that is how a module and its parts are written in Rust.
"""
import os
import re
import sys


def module_of(root, path):
    parts = os.path.relpath(path, root)[:-3].split(os.sep)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return tuple(parts)


def code_of(text):
    """The text without comments and without a trailing `#[cfg(test)] mod tests`."""
    m = re.search(r"#\[cfg\(test\)\]\s*(pub(\(\w+\))?\s+)?mod \w+\s*(;|\{)", text)
    if m:
        text = text[: m.start()]
    return re.sub(r"//[^\n]*", "", text)


def paths(module, is_dir_module, code):
    """The module paths `code` names, absolute from the crate root."""
    # `super` from `a/b.rs` (module a::b) or `a/b/mod.rs` (also a::b) is `a`.
    parent = list(module[:-1])
    for m in re.finditer(r"\b(crate|super)((?:::\w+)+)(::\{([^}]*)\})?", code):
        base = [] if m.group(1) == "crate" else parent
        prefix = base + m.group(2).split("::")[1:]
        if m.group(4) is None:
            yield prefix
            continue
        for item in m.group(4).split(","):
            name = item.strip().split("::")[0].split(" ")[0]
            if name and name != "self":
                yield prefix + [name]
            else:
                yield prefix


def edges(root):
    files = []
    for d, _, names in os.walk(root):
        files += [os.path.join(d, n) for n in names if n.endswith(".rs")]
    modules = {module_of(root, f): f for f in files}
    out = {}
    for module, f in modules.items():
        if module and module[-1] in ("tests", "testutil"):
            continue
        code = code_of(open(f, encoding="utf-8").read())
        for p in paths(module, f.endswith("mod.rs"), code):
            target = next((tuple(p[:k]) for k in range(len(p), 0, -1) if tuple(p[:k]) in modules), None)
            if target is None or target == module:
                continue
            if module and target[0] != module[0]:
                out.setdefault((module[0],), set()).add((target[0],))
            depth = len(module)
            if depth and len(target) >= depth and target[: depth - 1] == module[:-1]:
                sibling = target[:depth]
                if sibling != module and sibling in modules:
                    out.setdefault(module, set()).add(sibling)
    return out


def circles(graph):
    found = set()

    def walk(start, node, path):
        for nxt in graph.get(node, ()):
            if nxt == start:
                i = path.index(min(path))
                found.add(tuple(path[i:] + path[:i]))
            elif nxt not in path and nxt > start:
                walk(start, nxt, path + [nxt])

    for start in sorted(graph):
        walk(start, start, [start])
    return sorted(found)


def main(roots):
    bad = 0
    for root in roots:
        for c in circles(edges(root)):
            print(f"{root}: " + " -> ".join("::".join(m) for m in c + (c[0],)))
            bad = 1
    return bad


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1:]))
