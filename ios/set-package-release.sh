#!/usr/bin/env bash
# Points the root Package.swift's binary target at a published XCFramework zip: rewrites its
# `let release` line with the zip's URL and SwiftPM checksum. build-xcframework.sh calls it
# with --release-url; bindings/swift/test.sh checks it on a copy of the manifest.
#
#   ios/set-package-release.sh URL CHECKSUM [MANIFEST]   # MANIFEST: the root Package.swift
set -euo pipefail
url="${1:?usage: set-package-release.sh URL CHECKSUM [MANIFEST]}"
checksum="${2:?usage: set-package-release.sh URL CHECKSUM [MANIFEST]}"
manifest="${3:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/Package.swift}"

die() { echo "set-package-release.sh: $*" >&2; exit 1; }
[[ "$url" =~ ^https://[^\"[:space:]]+\.zip$ ]] || die "the URL must be https and end in .zip: $url"
[[ "$checksum" =~ ^[0-9a-f]{64}$ ]] || die "the checksum must be 64 hex digits (swift package compute-checksum): $checksum"
pattern='^let release: \(url: String, checksum: String\)\? = '
count="$(grep -cE "$pattern" "$manifest" || true)"
[[ "$count" == 1 ]] || die "$manifest has $count \`let release\` lines, expected 1"

# awk, not sed -i: the same on macOS and Linux; written back in place, keeping the file's mode.
tmp="$(mktemp)"
trap 'rm -f "$tmp"' EXIT
awk -v line="let release: (url: String, checksum: String)? = (url: \"$url\", checksum: \"$checksum\")" \
    -v pattern="$pattern" '$0 ~ pattern { print line; next } { print }' "$manifest" > "$tmp"
cat "$tmp" > "$manifest"
echo "== $manifest: WaymarkFFI from $url" >&2
