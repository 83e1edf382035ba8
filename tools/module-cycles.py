#!/usr/bin/env python3
"""Import circles between the files of a crate: `python3 tools/module-cycles.py crates/NAME/src ...`.

Each .rs file is a module (`a.rs` or `a/mod.rs` is `a`, `a/b.rs` is `a::b`). A file's non-test code
(everything before its first `#[cfg(test)]`, comments left out: a doc link is no import) names other
modules through `crate::...`, `super::...` and `self::...` paths, `use` groups included. A reference between a module and one of its ancestors is the
module tree itself (a parent declares and re-exports its children; a child may use its parent's items)
and is not counted; every other reference is an edge. A circle of edges is printed with the files on it
and the exit status is 1; without one the script prints one line per crate and exits 0.
"""
import re
import sys
from pathlib import Path

PATH = re.compile(r"\b(crate|super|self)((?:::(?:super|[A-Za-z_][A-Za-z0-9_]*))*)(::\{)?")


def modules(src: Path) -> dict:
    """Module path (tuple) of every .rs file under `src`."""
    found = {}
    for f in sorted(src.rglob("*.rs")):
        parts = list(f.relative_to(src).with_suffix("").parts)
        if parts in (["lib"], ["main"]):
            parts = []
        elif parts[-1] == "mod":
            parts = parts[:-1]
        found[tuple(parts)] = f
    return found


def group_heads(text: str, start: int) -> list:
    """The first path segment of each item in the `{...}` group opening at `start`, nested groups skipped."""
    depth, item, heads = 1, "", []
    i = start
    while i < len(text) and depth:
        c = text[i]
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
        if depth == 1 and c == ",":
            heads.append(item)
            item = ""
        elif depth == 1 and c not in "{}":
            item += c
        i += 1
    heads.append(item)
    return [h.strip().split("::")[0].split(" ")[0] for h in heads if h.strip()]


def references(module: tuple, text: str, known: set) -> set:
    """The modules `module`'s code names."""
    code = text.split("#[cfg(test)]")[0]
    # comments (doc links included) name modules without importing them
    code = "\n".join(line.split("//")[0] for line in code.splitlines())
    targets = set()
    for m in PATH.finditer(code):
        root, rest, group = m.group(1), m.group(2), m.group(3)
        segments = [s for s in rest.split("::") if s]
        if root == "crate":
            base = []
        elif root == "self":
            base = list(module)
        else:
            base = list(module[:-1])
        while segments and segments[0] == "super":
            base = base[:-1]
            segments = segments[1:]
        heads = [segments] if not group else [segments + [h] for h in group_heads(code, m.end())]
        for path in heads:
            target = tuple(base)
            for s in path:
                if target + (s,) in known:
                    target = target + (s,)
                else:
                    break
            targets.add(target)
    return targets


def ancestor(a: tuple, b: tuple) -> bool:
    return a == b[: len(a)] or b == a[: len(b)]


def cycles(src: Path) -> list:
    mods = modules(src)
    known = set(mods)
    edges = {
        m: sorted(t for t in references(m, f.read_text(encoding="utf-8"), known) if t in known and not ancestor(m, t))
        for m, f in mods.items()
    }
    found, state, stack = [], {}, []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in edges[m]:
            if state.get(t) == 1:
                found.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(mods):
        if m not in state:
            visit(m)
    return found


def main() -> int:
    status = 0
    for arg in sys.argv[1:]:
        src = Path(arg)
        found = cycles(src)
        name = "::".join
        if found:
            status = 1
            for c in found:
                print(f"module-cycles: {src}: " + " -> ".join(name(m) or "(root)" for m in c), file=sys.stderr)
        else:
            print(f"module-cycles: {src}: no import circle among its {len(modules(src))} files: ok")
    return status


if __name__ == "__main__":
    sys.exit(main())
