#!/usr/bin/env python3
"""Prints the code of one README quickstart, the block between `<!-- snippet: NAME -->` and
`<!-- /snippet -->`, without its fences, so the binding tests compile what the README shows.

    scripts/readme-snippet.py kotlin-quickstart > Quickstart.kt
"""
import pathlib
import re
import sys

name = sys.argv[1]
readme = (pathlib.Path(__file__).resolve().parent.parent / "README.md").read_text()
match = re.search(r"<!-- snippet: %s -->\n```\w+\n(.*?)```\n<!-- /snippet -->" % re.escape(name), readme, re.S)
if not match:
    sys.exit(f"readme-snippet.py: no snippet {name!r} in README.md")
sys.stdout.write(match.group(1))
