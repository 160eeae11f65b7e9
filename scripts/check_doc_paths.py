#!/usr/bin/env python3
"""Checks that every file or folder of the checkout the docs name in `backticks` exists.

A path is a backticked word that starts with one of the checkout's top-level folders (or is a
top-level file such as README.md) and has no spaces, wildcards or placeholders. Usage:
check_doc_paths.py CHECKOUT; prints each missing path with where it is named; exit 1 if any.
"""
import pathlib
import re
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
top = {p.name for p in root.iterdir() if not p.name.startswith(".") and not p.name.startswith("build")}
docs = [root / "README.md", root / "BENCHMARKS.md", *sorted((root / "docs").glob("*.md"))]
missing = []
for doc in docs:
    for lineno, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
        if "in git at" in line:  # a file of the past, named with the commit that has it
            continue
        for word in re.findall(r"`([^`\s]+)`", line):
            word = word.rstrip(".,:;)")
            if any(c in word for c in "*?<>{}$|") or "NNN" in word or "..." in word:
                continue
            path = word.split(":")[0].split("#")[0]
            first = path.split("/")[0]
            if first not in top or ("/" not in path and "." not in path):
                continue
            if not (root / path).exists():
                missing.append(f"{doc.relative_to(root)}:{lineno}: `{word}` does not exist")
for m in missing:
    print(m)
sys.exit(1 if missing else 0)
