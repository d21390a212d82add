#!/usr/bin/env python3
"""Checks that the docs read as a reference and that their links hold.

    python3 scripts/check-docs.py

1. docs/ says what is true now: no dates (2026-11-26), no commit hashes (7 to 40 hex digits
   in backticks or in a link) and no links to patches. How a figure came to be lives in
   research/ or in git history.
2. Every section a file cites resolves: `docs/X.md#anchor` anywhere in the repository's text
   (code comments included), and every relative Markdown link `[..](X.md#anchor)` in docs/,
   research/, README.md and ARCHITECTURE.md, against the headings of X, with GitHub's anchors
   (lowercase, spaces to '-', punctuation dropped, a repeated heading gets -1, -2...).
3. Nothing shipped names research/: it is notes beside the project, not part of it.

Exits 1, listing every problem as path:line: what, when a check fails.
"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
# Where code and docs live; research/ is read for its links only.
SHIPPED = ["src", "crates", "tests", "bindings", "android", "ios", "fuzz", "scripts", "docs",
           "README.md", "ARCHITECTURE.md", "CHANGELOG.md", "Cargo.toml", "cbindgen.toml",
           "uniffi.toml"]
TEXT = {".rs", ".md", ".kt", ".kts", ".swift", ".h", ".c", ".sh", ".py", ".toml", ".gradle",
        ".json", ".html", ".js", ".yml", ".yaml", ".txt"}
SKIP = {"target", "build", ".gradle", "node_modules", ".git"}

DATE = re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b")
HEX = r"[0-9a-f]{7,40}"
HASH_CODE = re.compile(r"`(" + HEX + r")`")
HASH_LINK = re.compile(r"\]\([^)]*\b(" + HEX + r")\b[^)]*\)")
PATCH_LINK = re.compile(r"\]\([^)]*\.(patch|diff)\)|/commit/|/compare/")
CITED = re.compile(r"\bdocs/([A-Za-z0-9_-]+\.md)#([a-z0-9-]+)")
MD_LINK = re.compile(r"\]\(([^)\s#]*\.md)?#([^)\s]+)\)")
RESEARCH = re.compile(r"(^|[^A-Za-z0-9_-])research/")


def files(paths):
    for name in paths:
        p = ROOT / name
        if p.is_file():
            yield p
        elif p.is_dir():
            for f in sorted(p.rglob("*")):
                if f.is_file() and f.suffix in TEXT and not SKIP & set(f.relative_to(ROOT).parts):
                    yield f


def anchors(path, cache={}):
    """GitHub's anchors of a Markdown file's headings (outside code blocks)."""
    if path not in cache:
        seen, out, fence = {}, set(), False
        for line in path.read_text(errors="replace").splitlines():
            if line.lstrip().startswith("```"):
                fence = not fence
            m = None if fence else re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
            if m:
                slug = re.sub(r"[^\w\- ]", "", m.group(1).lower().replace("`", "")).replace(" ", "-")
                n = seen.get(slug, 0)
                seen[slug] = n + 1
                out.add(slug if n == 0 else f"{slug}-{n}")
        cache[path] = out
    return cache[path]


def hexish(s):
    # A hash has digits and letters; a word like `deadbeef` or a number alone is not one.
    return re.search(r"[0-9]", s) and re.search(r"[a-f]", s)


def main():
    problems = []
    here = lambda f, i: f"{f.relative_to(ROOT)}:{i}"
    for f in files(["docs"]):
        if f.suffix != ".md":
            continue
        for i, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
            if DATE.search(line):
                problems.append(f"{here(f, i)}: a date ({DATE.search(line).group(0)})")
            for m in list(HASH_CODE.finditer(line)) + list(HASH_LINK.finditer(line)):
                if hexish(m.group(1)):
                    problems.append(f"{here(f, i)}: a commit hash ({m.group(1)})")
            if PATCH_LINK.search(line):
                problems.append(f"{here(f, i)}: a link to a patch or commit")
    for f in files(SHIPPED + ["research"]):
        text = f.read_text(errors="replace")
        if f.name == "check-docs.py":
            continue
        shipped = not f.relative_to(ROOT).parts[0] == "research"
        for i, line in enumerate(text.splitlines(), 1):
            if shipped and RESEARCH.search(line):
                problems.append(f"{here(f, i)}: names research/, which nothing shipped links into")
            for m in CITED.finditer(line):
                target = ROOT / "docs" / m.group(1)
                if not target.is_file():
                    problems.append(f"{here(f, i)}: cites docs/{m.group(1)}, which does not exist")
                elif m.group(2) not in anchors(target):
                    problems.append(f"{here(f, i)}: cites docs/{m.group(1)}#{m.group(2)}, no such section")
            if f.suffix != ".md":
                continue
            for m in MD_LINK.finditer(line):
                target = (f.parent / m.group(1)).resolve() if m.group(1) else f
                if not target.is_file():
                    problems.append(f"{here(f, i)}: links to {m.group(1)}, which does not exist")
                elif m.group(2) not in anchors(target):
                    problems.append(f"{here(f, i)}: links to {m.group(1) or ''}#{m.group(2)}, no such section")
    for p in problems:
        print(p)
    if problems:
        print(f"check-docs: {len(problems)} problems (above)", file=sys.stderr)
        return 1
    print("check-docs: docs carry no dates, hashes or patch links; every cited section resolves")
    return 0


if __name__ == "__main__":
    sys.exit(main())
