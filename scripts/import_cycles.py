#!/usr/bin/env python3
"""No two files of a crate depend on each other, directly or around a loop.

A file depends on the file that *defines* an item it names (through `crate::`, `super::`,
`self::` or a child module's path; a re-export is followed to where the item is defined, and a
name a module file re-exports counts only where that file also uses it). Test modules and
comments are left out. Prints each loop and exits 1 if there is one.

    python3 scripts/import_cycles.py [crates/sim/src ...]   (default: every crate's src/)
"""
import os
import re
import sys

ITEM = re.compile(r"\b(?:struct|enum|fn|trait|type|const|static|macro_rules!)\s+([A-Za-z_]\w*)")
PUB_USE = re.compile(
    r"pub use\s+((?:crate|self|super)?(?:::)?[A-Za-z_:]*?)(?:::)?(\{[^}]*\}|[A-Za-z_]\w*)\s*;"
)


def read_crate(root):
    files = {}
    for directory, _, names in os.walk(root):
        for name in names:
            if not name.endswith(".rs"):
                continue
            path = os.path.join(directory, name)
            parts = os.path.relpath(path, root)[:-3].split(os.sep)
            is_mod = parts[-1] in ("mod", "lib", "main")
            if is_mod:
                parts = parts[:-1]
            with open(path) as f:
                text = f.read()
            text = re.split(r"#\[cfg\(test\)\]\s*mod tests", text)[0]
            text = re.sub(r"//[^\n]*", "", text)
            files[tuple(parts)] = (text, is_mod)
    return files


def graph_of(files):
    defs = {m: set(ITEM.findall(text)) for m, (text, _) in files.items()}

    def here(mod, is_mod):
        return list(mod) if is_mod else list(mod[:-1])

    def absolute(mod, is_mod, kind, segs):
        if kind == "crate":
            return segs
        if kind == "super":
            return here(mod, is_mod)[:-1] + segs
        return here(mod, is_mod) + segs  # self:: or a child module's path

    reexports = {}
    for mod, (text, is_mod) in files.items():
        for m in PUB_USE.finditer(text):
            prefix = [x for x in m.group(1).split("::") if x]
            kind = prefix[0] if prefix and prefix[0] in ("crate", "self", "super") else "child"
            if kind != "child":
                prefix = prefix[1:]
            for item in m.group(2).strip("{}").split(","):
                item = item.strip()
                if not item:
                    continue
                path = [p.split(" as ")[0].strip() for p in item.split("::")]
                alias = item.split("::")[-1].split(" as ")[-1].strip()
                reexports[(mod, alias)] = absolute(mod, is_mod, kind, prefix + path)

    def locate(path, depth=0):
        for n in range(len(path), -1, -1):
            m = tuple(path[:n])
            if m not in files:
                continue
            rest = path[n:]
            if not rest or rest[0] in defs[m]:
                return m
            if (m, rest[0]) in reexports and depth < 10:
                return locate(reexports[(m, rest[0])] + rest[1:], depth + 1)
            return None  # an external crate's item, re-exported
        return None

    graph = {}
    for mod, (text, is_mod) in files.items():
        deps = set()
        body = re.sub(r"pub use[^;]*;", "", text)
        for (owner, alias), target in reexports.items():
            if owner == mod and re.search(r"(?<![\w:])" + re.escape(alias) + r"\b", body):
                deps.add(locate(target))
        kinds = r"crate|super|self" + (r"|[a-z_][a-z0-9_]*" if is_mod else "")
        pattern = r"(?<![\w:])(" + kinds + r")((?:::[A-Za-z_]\w*)*)(?:::\{([^}]*)\})?"
        for m in re.finditer(pattern, body):
            kind, rest, group = m.group(1), m.group(2), m.group(3)
            segs = [x for x in rest.split("::") if x]
            if kind not in ("crate", "super", "self"):
                if not rest and not group:
                    continue  # a bare name (`mod x;`, a variable), not a path
                if tuple(here(mod, is_mod) + [kind]) not in files:
                    continue
                segs, kind = [kind] + segs, "child"
            if not segs and not group:
                continue
            paths = [segs]
            if group:
                paths = [
                    segs + [g.strip().split(" as ")[0].split("::")[0].strip()]
                    for g in group.split(",")
                    if g.strip() and g.strip() != "self"
                ]
            for p in paths:
                deps.add(locate(absolute(mod, is_mod, kind, p)))
        deps.discard(None)
        deps.discard(mod)
        graph[mod] = deps
    return graph


def loops(graph):
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

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
                found.append(component)

    sys.setrecursionlimit(10000)
    for v in graph:
        if v not in index:
            visit(v)
    return found


def main():
    roots = sys.argv[1:] or sorted(
        os.path.join("crates", c, "src") for c in os.listdir("crates") if os.path.isdir(os.path.join("crates", c, "src"))
    )
    bad = 0
    for root in roots:
        graph = graph_of(read_crate(root))
        for component in loops(graph):
            bad += 1
            print(f"{root}: files that depend on each other:")
            for a in sorted(component):
                for b in sorted(graph[a] & set(component)):
                    print(f"    {'/'.join(a) or 'lib'} -> {'/'.join(b) or 'lib'}")
    if bad:
        sys.exit(1)
    print(f"import_cycles: no file depends on itself through others ({len(roots)} crates)")


if __name__ == "__main__":
    main()
