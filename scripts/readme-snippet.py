#!/usr/bin/env python3
"""Prints the code of one quickstart, the block between `<!-- snippet: NAME -->` and
`<!-- /snippet -->`, without its fences, so the binding tests compile what the docs show.
FILE is README.md unless given (a path from the repository root, e.g. docs/android.md).

    scripts/readme-snippet.py kotlin-quickstart > Quickstart.kt
    scripts/readme-snippet.py android-statuses docs/android.md > AndroidStatuses.kt
"""
import pathlib
import re
import sys

name = sys.argv[1]
relative = sys.argv[2] if len(sys.argv) > 2 else "README.md"
text = (pathlib.Path(__file__).resolve().parent.parent / relative).read_text()
match = re.search(r"<!-- snippet: %s -->\n```\w+\n(.*?)```\n<!-- /snippet -->" % re.escape(name), text, re.S)
if not match:
    sys.exit(f"readme-snippet.py: no snippet {name!r} in {relative}")
sys.stdout.write(match.group(1))
