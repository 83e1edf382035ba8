#!/usr/bin/env python3
"""Import circles between the files of a crate: `python3 tools/module-cycles.py crates/NAME/src ...`.

Each .rs file is a module (`a.rs` or `a/mod.rs` is `a`, `a/b.rs` is `a::b`). A file's code, without its
comments, string and character literals and test-only items (an item under `#[cfg(test)]` or
`#[cfg(all(test, ...))]`), names other modules through `crate::...`, `super::...` and `self::...` paths,
`use` trees with nested groups included, and through paths that start at one of its own child
modules by the bare name (`pub use builder::System`). A name a module re-exports (`pub use x::Name`,
any visibility) is followed to the module that defines it, so `use crate::Name` counts as an import of
that module. A module's reference to one of its ancestors is not counted (a child may use its
parent's own items: that is the module tree); every other reference is an edge, the parent's use of a
child's items (re-exports included) too, so a parent that uses its child while the child, through
other files, uses the parent is a circle. A circle of edges is printed with the files on it and the
exit status is 1; without one the script prints one line per crate and exits 0.
"""
import re
import sys
from pathlib import Path

# comments, raw strings, strings and character literals, in one pass so that each hides the others
LEXEMES = re.compile(
    r'/\*.*?\*/|//[^\n]*|r(#*)".*?"\1|b?"(?:\\.|[^"\\])*"|b?\'(?:\\.|[^\'\\])\'',
    re.DOTALL,
)
TEST_ATTR = re.compile(r"#\[cfg\((?:test|all\(\s*test\b[^\]]*)\)\]")
ROOT = re.compile(r"\b(crate|super|self)\s*::")
IDENT = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*|\*)")


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


def code_of(text: str) -> str:
    """The text without comments, literals and test-only items."""
    text = LEXEMES.sub(lambda m: " " if not m.group(0).startswith("//") else "", text)
    while True:
        m = TEST_ATTR.search(text)
        if not m:
            return text
        i = m.end()
        semi, brace = text.find(";", i), text.find("{", i)
        if brace == -1 or (semi != -1 and semi < brace):
            end = semi + 1 if semi != -1 else len(text)
        else:
            depth, end = 0, brace
            while end < len(text):
                depth += {"{": 1, "}": -1}.get(text[end], 0)
                end += 1
                if depth == 0:
                    break
        text = text[: m.start()] + text[end:]


def use_tree(code: str, i: int, prefix: list, out: list) -> int:
    """Parse a path tree at `i` (segments, `::`, `{...}` groups, `as` aliases); append each full path
    with its alias (or last segment) to `out`; return the index after it."""
    path = list(prefix)
    while True:
        if code.startswith("{", i := len(code) - len(code[i:].lstrip())):
            i += 1
            while True:
                i = len(code) - len(code[i:].lstrip())
                if code.startswith("}", i):
                    return i + 1
                i = use_tree(code, i, path, out)
                i = len(code) - len(code[i:].lstrip())
                if code.startswith(",", i):
                    i += 1
        m = IDENT.match(code, i)
        if not m:
            if path != prefix:
                out.append((path, path[-1]))
            return i
        path.append(m.group(1))
        i = m.end()
        rest = code[i:]
        stripped = rest.lstrip()
        if stripped.startswith("::"):
            i = len(code) - len(stripped) + 2
            continue
        alias = re.match(r"\s+as\s+([A-Za-z_][A-Za-z0-9_]*)", rest)
        if alias:
            i += alias.end()
        out.append((path, alias.group(1) if alias else path[-1]))
        return i


def paths(module: tuple, code: str, children: tuple = ()) -> list:
    """Every `crate::`/`super::`/`self::` path in the code, and every path that starts at one of the
    module's `children` by its bare name (`pub use builder::System`), as (absolute segments, exported
    name)."""
    found = []
    starts = [(m.start(), m.end(), m.group(1)) for m in ROOT.finditer(code)]
    for child in children:
        starts += [(m.start(), m.start() + len(child), "child") for m in re.finditer(rf"(?<![\w:]){child}\s*::", code)]
    for start, end, root in sorted(starts):
        base = [] if root == "crate" else list(module) if root in ("self", "child") else list(module[:-1])
        raw = []
        use_tree(code, start if root == "child" else end, [], raw)
        for segs, name in raw:
            b = list(base)
            while segs and segs[0] == "super":
                b, segs = b[:-1], segs[1:]
            if segs and segs[0] == "self":
                segs = segs[1:]
            found.append((b + segs, name))
    return found


def reexports(module: tuple, code: str, known: set) -> dict:
    """The names a module re-exports, with the absolute path they come from."""
    out = {}
    for m in re.finditer(r"\bpub(?:\s*\([^)]*\))?\s+use\s+", code):
        raw = []
        use_tree(code, m.end(), [], raw)
        for segs, name in raw:
            if not segs:
                continue
            if segs[0] == "crate":
                b, segs = [], segs[1:]
            elif segs[0] in ("self", "super"):
                b = list(module) if segs[0] == "self" else list(module[:-1])
                segs = segs[1:]
                while segs and segs[0] == "super":
                    b, segs = b[:-1], segs[1:]
            elif tuple(module) + (segs[0],) in known:
                b = list(module)
            else:
                continue  # another crate's item
            out[name] = b + segs
    return out


def resolve(path: list, known: set, exported: dict, depth: int = 0) -> tuple:
    """The module an absolute path lands in, following re-exports."""
    target = ()
    for s in path:
        if target + (s,) in known:
            target = target + (s,)
        elif s in exported.get(target, {}) and depth < 16:
            return resolve(exported[target][s], known, exported, depth + 1)
        else:
            break
    return target


def within(m: tuple, t: tuple) -> bool:
    """Whether `t` is `m` itself or one of its ancestors: the references a module makes to its own
    ancestors (the module tree) are not edges; those to its descendants are."""
    return t == m[: len(t)]


def cycles(src: Path) -> list:
    mods = modules(src)
    known = set(mods)
    codes = {m: code_of(f.read_text(encoding="utf-8")) for m, f in mods.items()}
    exported = {m: reexports(m, c, known) for m, c in codes.items()}
    edges = {}
    for m, code in codes.items():
        children = tuple(k[-1] for k in known if k[:-1] == m and len(k) == len(m) + 1)
        targets = {resolve(p, known, exported) for p, _ in paths(m, code, children)}
        edges[m] = sorted(t for t in targets if not within(m, t))
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
        if found:
            status = 1
            for c in found:
                print(f"module-cycles: {src}: " + " -> ".join("::".join(m) or "(root)" for m in c), file=sys.stderr)
        else:
            print(f"module-cycles: {src}: no import circle among its {len(modules(src))} files: ok")
    return status


if __name__ == "__main__":
    sys.exit(main())
