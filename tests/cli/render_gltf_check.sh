#!/usr/bin/env bash
# `previs render` on glTF files a new user might try (issue 11, "Real-world glTF files"):
#   1. a scene with no light source and no --env renders, with one warning naming the fix;
#   2. --env studio (the bundled environment, no file) lights it: no warning, a non-black image;
#   3. tinygltf's tests/issue-416.gltf (its whole text; MIT) is refused in one line naming the
#      file and the problem, not with "std::bad_alloc".
# Usage: render_gltf_check.sh PREVIS UNLIT_PLANE.gltf
set -euo pipefail
previs=$1
unlit=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

"$previs" render "$unlit" --width 8 --height 8 --spp 1 --out "$tmp/dark.exr" 2>"$tmp/err1" ||
    fail "render without light exited $?: $(cat "$tmp/err1")"
warnings=$(grep -c "no light source" "$tmp/err1" || true)
[[ $warnings == 1 ]] || fail "expected one no-light warning, got $warnings: $(cat "$tmp/err1")"
grep "no light source" "$tmp/err1" | grep -q -- "--env studio" || fail "the warning names no fix"

"$previs" render "$unlit" --env studio --width 8 --height 8 --spp 1 --out "$tmp/studio.exr" \
    2>"$tmp/err2" || fail "render with --env studio failed: $(cat "$tmp/err2")"
! grep -q "no light source" "$tmp/err2" || fail "warning despite --env studio"
read -r _ _ _ _ _ mean _ < <("$previs" compare "$tmp/studio.exr" "$tmp/dark.exr")
awk -v m="$mean" 'BEGIN { exit !(m > 0.1) }' || fail "studio render mean $mean: black?"

printf '%s' '{"images":[{"uri":"%!QAAAQAAA5"}],"asset":{"version":""}}' >"$tmp/issue-416.gltf"
rc=0
"$previs" render "$tmp/issue-416.gltf" --width 8 --height 8 --spp 1 --out "$tmp/x.exr" \
    2>"$tmp/err3" || rc=$?
[[ $rc == 2 ]] || fail "issue-416.gltf: exit code $rc, not 2 (bad input)"
[[ $(wc -l <"$tmp/err3") == 1 ]] || fail "not one line: $(cat "$tmp/err3")"
grep -q "issue-416.gltf.*asset.version" "$tmp/err3" || fail "does not name file and problem: $(cat "$tmp/err3")"
! grep -q "bad_alloc" "$tmp/err3" || fail "still bad_alloc"
echo "ok: $(cat "$tmp/err1") | $(cat "$tmp/err3")"
