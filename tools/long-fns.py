#!/usr/bin/env python3
"""Long functions: `python3 tools/long-fns.py [--over N] [--max M] [crates/NAME/src ...]`.

Counts the functions of the crates' sources (default: every `crates/*/src`) that span more than 80 and
more than 120 lines, from the line of `fn` to the line of the body's closing brace, and lists those
over `--over` lines (default 80), longest first. Test code is left out: an item under `#[cfg(test)]`
(or `#[cfg(all(test, ...))]`) and everything in a `tests/`, `benches/` or `examples/` folder (they are
not under `src`). Comments, strings and character literals are blanked first (their line breaks
kept), so a brace inside one does not count. A function inside another is counted on its own and
within its parent. With `--max M`, the exit status is 1 when a function spans more than M lines.
"""
import re
import sys
from pathlib import Path

LEXEMES = re.compile(
    r'/\*.*?\*/|//[^\n]*|r(#*)".*?"\1|b?"(?:\\.|[^"\\])*"|b?\'(?:\\.|[^\'\\])\'',
    re.DOTALL,
)
TEST_ATTR = re.compile(r"#\[cfg\((?:test|all\(\s*test\b[^\]]*)\)\]")
FN = re.compile(r"\bfn\s+([A-Za-z_][A-Za-z0-9_]*)")


def blank(text: str) -> str:
    """Comments and literals replaced by spaces, their line breaks kept."""
    return LEXEMES.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def item_end(code: str, i: int) -> int:
    """Index after the item starting at `i`: its `;` or its `{...}` body, whichever comes first."""
    semi, brace = code.find(";", i), code.find("{", i)
    if brace == -1 or (semi != -1 and semi < brace):
        return semi + 1 if semi != -1 else len(code)
    depth, end = 0, brace
    while end < len(code):
        depth += {"{": 1, "}": -1}.get(code[end], 0)
        end += 1
        if depth == 0:
            break
    return end


def without_tests(code: str) -> str:
    """Test-only items blanked (line breaks kept)."""
    while m := TEST_ATTR.search(code):
        end = item_end(code, m.end())
        code = code[: m.start()] + re.sub(r"[^\n]", " ", code[m.start() : end]) + code[end:]
    return code


def functions(path: Path) -> list:
    """(lines, name, first line) of every function with a body in the file."""
    code = without_tests(blank(path.read_text(encoding="utf-8")))
    found = []
    for m in FN.finditer(code):
        # a body starts at the first `{` not preceded by `;` (a trait method without a body ends at `;`)
        end = item_end(code, m.end())
        if code[end - 1] != "}":
            continue
        first = code.count("\n", 0, m.start()) + 1
        last = code.count("\n", 0, end - 1) + 1
        found.append((last - first + 1, m.group(1), first))
    return found


def main() -> int:
    args = sys.argv[1:]
    over, limit = 80, None
    if "--over" in args:
        k = args.index("--over")
        over = int(args[k + 1])
        del args[k : k + 2]
    if "--max" in args:
        k = args.index("--max")
        limit = int(args[k + 1])
        del args[k : k + 2]
    roots = [Path(a) for a in args] or sorted(Path("crates").glob("*/src"))
    rows = []
    for root in roots:
        for f in sorted(root.rglob("*.rs")):
            rows += [(n, name, f, line) for n, name, line in functions(f)]
    rows.sort(key=lambda r: (-r[0], str(r[2]), r[3]))
    for n, name, f, line in rows:
        if n > over:
            print(f"{n:5} {name} {f}:{line}")
    n80 = sum(1 for r in rows if r[0] > 80)
    n120 = sum(1 for r in rows if r[0] > 120)
    print(f"long-fns: {len(rows)} functions; {n80} over 80 lines, {n120} over 120 lines")
    if limit is not None and rows and rows[0][0] > limit:
        print(f"long-fns: {rows[0][1]} spans {rows[0][0]} lines, more than {limit}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
