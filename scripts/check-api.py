#!/usr/bin/env python3
"""docs/api.md: the engine crate's public items, each with who uses it.

The list comes from rustdoc's item index of `waymark-engine` (target/doc/waymark_engine/all.html,
written by `cargo doc -p waymark-engine --no-deps`), so it is exactly what the crate exports and
at the path a user reaches it by. "Used by" is every place outside the engine's own source that
depends on the engine and names the item: the SDK library (`src/`), a tool crate, a test, a
bench or the README's Rust example. An item nobody outside uses has no reason to be public.

    python3 scripts/check-api.py --write   # regenerate docs/api.md
    python3 scripts/check-api.py --check   # fail if docs/api.md is stale or an item is unused

Run `cargo doc -p waymark-engine --no-deps` first (the test command does).
"""

import html
import os
import re
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(REPO, "target")), "doc", "waymark_engine")
API_MD = os.path.join(REPO, "docs", "api.md")

KINDS = {
    "struct": "struct",
    "enum": "enum",
    "trait": "trait",
    "fn": "fn",
    "type": "type",
    "constant": "const",
    "macro": "macro",
    "static": "static",
}


SIGNATURES = re.compile(
    r'<pre class="rust item-decl">.*?</pre>|<h4 class="code-header">.*?</h4>'
    r'|<span id="(?:structfield|variant)\.[^"]*"[^>]*>.*?</span>', re.S)


def signature_links(href):
    """Pages of the items `href`'s declaration, fields, variants and method signatures name."""
    page = open(os.path.join(DOC, href), encoding="utf-8").read()
    here = os.path.dirname(href)
    out = set()
    for code in SIGNATURES.findall(page):
        for link in re.findall(r'href="([^"#]+\.html)', code):
            out.add(os.path.normpath(os.path.join(here, link)))
    return out


def items():
    """(href, module path, name, kind, summary) for every public item, in rustdoc's order."""
    index = open(os.path.join(DOC, "all.html"), encoding="utf-8").read()
    out = []
    for href in dict.fromkeys(re.findall(r'<li><a href="([^"]+\.html)">', index)):
        parts = href.split("/")
        kind, name = parts[-1][: -len(".html")].split(".", 1)
        if kind not in KINDS:
            continue
        page = open(os.path.join(DOC, href), encoding="utf-8").read()
        m = re.search(r'<meta name="description" content="([^"]*)"', page)
        summary = html.unescape(m.group(1)) if m else ""
        # The first sentence: the page has the rest.
        summary = re.split(r"(?<=[a-z0-9)`])\. (?=[A-Z`(])", summary, maxsplit=1)[0].rstrip(".") + "."
        out.append((href, "::".join(parts[:-1]), name, KINDS[kind], summary))
    return out


def user_files():
    """{group: [file text]} for every file outside the engine's source that uses the engine."""
    groups = {}

    def add(group, path):
        text = open(path, encoding="utf-8", errors="replace").read()
        if "waymark_engine" in text or path.startswith(os.path.join(REPO, "crates", "engine", "tests")):
            groups.setdefault(group, []).append(text)

    for top, group in [("src", "sdk"), ("tests", "tests"), ("fuzz", "tests")]:
        for root, _, files in os.walk(os.path.join(REPO, top)):
            for f in files:
                if f.endswith(".rs"):
                    add(group, os.path.join(root, f))
    crates = os.path.join(REPO, "crates")
    for crate in sorted(os.listdir(crates)):
        for root, _, files in os.walk(os.path.join(crates, crate)):
            rel = os.path.relpath(root, crates)
            if rel.startswith(os.path.join("engine", "src")):
                continue
            sub = rel.split(os.sep)[1] if os.sep in rel else "src"
            group = "tests" if sub in ("tests", "benches", "examples") else crate
            for f in files:
                if f.endswith(".rs"):
                    add(group, os.path.join(root, f))
    readme = open(os.path.join(REPO, "README.md"), encoding="utf-8").read()
    groups["readme"] = [readme + "\nwaymark_engine"]
    return groups


def render():
    groups = user_files()
    listed = items()
    users = {}
    for href, _, name, _, _ in listed:
        word = re.compile(r"\b" + re.escape(name) + r"\b")
        users[href] = [g for g in sorted(groups) if any(word.search(t) for t in groups[g])]
    # An item no one names is still used when a used item's signature, field or variant holds
    # it: the type of a config field an app sets, the error a used function returns.
    names = {href: name for href, _, name, _, _ in listed}
    changed = True
    while changed:
        changed = False
        for href in [h for h in users if users[h]]:
            for link in signature_links(href):
                if link in users and not users[link] and link != href:
                    users[link] = [f"via `{names[href]}`"]
                    changed = True
    rows, unused = {}, []
    for href, module, name, kind, summary in listed:
        path = "::".join(["waymark_engine"] + ([module] if module else []))
        if not users[href]:
            unused.append(f"{path}::{name}")
        summary = summary.replace("|", "\\|")
        by = ", ".join(users[href]) or "—"
        rows.setdefault(path, []).append(f"| `{name}` | {kind} | {summary} | {by} |")
    lines = [
        "# The engine's Rust API",
        "",
        "Every public item of the `waymark-engine` crate, at the path a user reaches it by, and",
        "who uses it: `sdk` is the mobile SDK library (`src/`), `cli`, `eval`, `sim`, `survey`",
        "and `experiments` are the tool crates, `tests` the test suites and benches, `readme` the",
        "README's Rust example. Methods are documented on their types (`cargo doc -p",
        "waymark-engine --open`). Apps on Android, iOS or C use the SDK's bindings instead",
        "(docs/android.md, docs/ios.md, docs/c.md).",
        "",
        "This page is generated: `cargo doc -p waymark-engine --no-deps && python3",
        "scripts/check-api.py --write`. The test command fails when it is stale or when an item",
        "has no user outside the engine.",
        "",
    ]
    for path in sorted(rows, key=lambda p: (p.count("::"), p)):
        lines += [f"## `{path}`", "", "| item | kind | what | used by |", "|---|---|---|---|"]
        lines += rows[path] + [""]
    return "\n".join(lines), unused


def main():
    mode = sys.argv[1] if len(sys.argv) > 1 else "--check"
    if not os.path.exists(os.path.join(DOC, "all.html")):
        sys.exit(f"check-api: {DOC}/all.html is missing: run cargo doc -p waymark-engine --no-deps")
    text, unused = render()
    if mode == "--write":
        open(API_MD, "w", encoding="utf-8").write(text)
    elif mode == "--unused":
        print("\n".join(unused))
        return
    elif open(API_MD, encoding="utf-8").read() != text:
        sys.exit("check-api: docs/api.md is stale: run cargo doc -p waymark-engine --no-deps "
                 "&& python3 scripts/check-api.py --write")
    if unused:
        sys.exit("check-api: public items no one outside the engine uses:\n  " + "\n  ".join(unused))
    print(f"check-api: docs/api.md lists {text.count(chr(10) + '| `')} public items, each with a user")


if __name__ == "__main__":
    main()
