#!/usr/bin/env bash
# Fails if a tracked text file names an absolute path on a developer's machine (a home folder,
# /root, /work): data and tools are found relative to the checkout or through an environment
# variable, and committed benchmark output must say paths the same way.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! git rev-parse --git-dir >/dev/null 2>&1; then
    echo "check_machine_paths: not a git checkout; nothing to check"
    exit 0
fi
if git grep -nIE '(^|[^A-Za-z0-9_.~-])/(work|home|root)/' -- . ':!scripts/check_machine_paths.sh'; then
    echo "absolute machine paths above: name them relative to the checkout (or via an environment variable)" >&2
    exit 1
fi
