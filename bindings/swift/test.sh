#!/usr/bin/env bash
# The Swift bindings tested on Linux: builds libwaymark, checks that the Swift committed in
# ios/Sources/ is what uniffi-bindgen generates today, exports a simulated walk, checks that
# the root Package.swift resolves from a fresh copy of the repository (and that its Apple
# branch declares the binary target), and runs the XCTest suite in bindings/swift/, which
# builds the root package's own Waymark target, with Debian trixie's swiftlang in a chroot.
#
#   bash bindings/swift/test.sh        # from anywhere; needs root (debootstrap, unshare, chroot)
#
# The chroot ($TARGET/swift-root, ~2.6 GB) is made on the first run (~2 minutes) and reused;
# delete it to rebuild it. XCTest's closing line is the last line printed.
#
#   bash bindings/swift/test.sh --tools-only   # makes the chroot, then stops (scripts/test.sh
#                                              # runs it in the background during its demo step)
set -euo pipefail
tools_only=0
[[ "${1:-}" == --tools-only ]] && tools_only=1

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$REPO/target}"
mkdir -p "$CARGO_TARGET_DIR"
TARGET="$(cd "$CARGO_TARGET_DIR" && pwd)"
ROOT="$TARGET/swift-root"
GENERATED="$REPO/ios/Sources"
cd "$REPO"

log() { printf '== %s\n' "$*" >&2; }

# --- 1. A Debian trixie chroot with swiftlang (made once; it is rebuildable, so it lives in target/).
if [[ ! -e "$ROOT/.waymark-swift-ready" ]]; then
    if ! command -v debootstrap >/dev/null; then
        log "installing debootstrap"
        apt-get update -qq && apt-get install -y -qq debootstrap >/dev/null
    fi
    log "creating the trixie chroot in $ROOT (once, ~2 minutes)"
    rm -rf "$ROOT.partial"
    debootstrap --variant=minbase trixie "$ROOT.partial" http://deb.debian.org/debian >/dev/null
    cp /etc/resolv.conf "$ROOT.partial/etc/resolv.conf"
    unshare --mount --fork chroot "$ROOT.partial" /bin/sh -c \
        'export DEBIAN_FRONTEND=noninteractive; apt-get update -qq && apt-get install -y -qq --no-install-recommends swiftlang libc6-dev >/dev/null && apt-get clean'
    touch "$ROOT.partial/.waymark-swift-ready"
    rm -rf "$ROOT"
    mv "$ROOT.partial" "$ROOT"
fi
if (( tools_only )); then exit 0; fi

# --- 2. The library and the generator, exactly as the release does (bindgen never in the lib).
log "building"
cargo build --quiet -p uniffi-bindgen
# The simulated site and walk the XCTest replays, by the release CLI: the survey test builds a
# site with it, minutes in a debug build and seconds in release. A release build leaves
# target/debug, where the library below goes, alone.
cargo run --release --quiet -p waymark-cli -- sim-export --out "$TARGET/sim-export" >/dev/null
# The same site with its transmitter ids hashed, under a fixed test salt.
echo 5a1f00d0c0ffee00112233445566778899aabbccddeeff0123456789abcdef01 > "$TARGET/sim-export/salt.hex"
cargo run --release --quiet -p waymark-cli -- site hash --salt-file "$TARGET/sim-export/salt.hex" \
    "$TARGET/sim-export/site.json" "$TARGET/sim-export/site-hashed.json" >/dev/null
# The same site in the binary encoding an app ships.
cargo run --release --quiet -p waymark-cli -- site pack "$TARGET/sim-export/site.json" \
    "$TARGET/sim-export/site.wmsite" >/dev/null
# A test build: a scan at UInt64.max - 7 panics inside the engine (feature fault-injection).
cargo build --quiet -p waymark --lib --features fault-injection
LIB="$TARGET/debug/libwaymark.so"

# --- 3. Freshness: the committed Swift must be what the generator makes today.
FRESH="$(mktemp -d)"
trap 'rm -rf "$FRESH"' EXIT
"$TARGET/debug/uniffi-bindgen" generate --no-format --library "$LIB" --language swift --out-dir "$FRESH" >/dev/null
stale=0
for pair in "Waymark.swift:Waymark/Waymark.swift" \
            "WaymarkFFI.h:WaymarkFFI/include/WaymarkFFI.h" \
            "WaymarkFFI.modulemap:WaymarkFFI/include/module.modulemap"; do
    if ! diff -u "$GENERATED/${pair#*:}" "$FRESH/${pair%%:*}" >&2; then stale=1; fi
done
if (( stale )); then
    log "ios/Sources/ is stale; regenerate it with:"
    log "  $TARGET/debug/uniffi-bindgen generate --no-format --library $LIB --language swift --out-dir DIR"
    log "  and copy Waymark.swift, WaymarkFFI.h, WaymarkFFI.modulemap (as module.modulemap) into ios/Sources/"
    exit 1
fi

# --- 4. The README's Swift quickstart and the Swift snippets of docs/ios.md,
# docs/surveying.md and docs/your-building.md (every block between `<!-- snippet: NAME -->` and `<!-- /snippet -->`),
# compiled into the test target (not committed).
{
    python3 "$REPO/scripts/readme-snippet.py" swift-quickstart
    python3 - "$REPO/docs/ios.md" "$REPO/docs/surveying.md" "$REPO/docs/your-building.md" <<'PY'
import re, sys
for path in sys.argv[1:]:
    guide = open(path).read()
    blocks = re.findall(r"<!-- snippet: [\w-]+ -->\n```swift\n(.*?)```\n<!-- /snippet -->", guide, re.S)
    if not blocks:
        sys.exit(f"test.sh: no Swift snippet in {path}")
    sys.stdout.write("".join(blocks))
PY
} > "$REPO/bindings/swift/Tests/WaymarkTests/ReadmeQuickstart.swift"

# Runs a command in the chroot. The checkout (and the target dir, if elsewhere) is
# bind-mounted at the same path inside, so every path resolves identically.
MOUNTS=("$REPO")
[[ "$TARGET/" == "$REPO/"* ]] || MOUNTS+=("$TARGET")
in_chroot() {
    # shellcheck disable=SC2016
    unshare --mount --fork /bin/bash -euo pipefail -c '
        root="$1"; n="$2"; shift 2
        mount --make-rprivate /
        for ((i = 0; i < n; i++)); do mkdir -p "$root$1"; mount --bind "$1" "$root$1"; shift; done
        mount -t proc proc "$root/proc"
        mount --rbind /dev "$root/dev"
        exec chroot "$root" /usr/bin/env -i PATH=/usr/bin:/bin HOME=/root LANG=C.UTF-8 "$@"
    ' _ "$ROOT" "${#MOUNTS[@]}" "${MOUNTS[@]}" "$@"
}

# --- 5. The root package as SwiftPM sees it from the repository's git URL: a copy of the files a
# clone of this tree holds (tracked, or new and not ignored), with nothing built.
log "swift package describe (the root package, from a fresh copy)"
CLONE="$TARGET/swift-clone"
rm -rf "$CLONE" && mkdir -p "$CLONE"
git -C "$REPO" ls-files -z --cached --others --exclude-standard |
    while IFS= read -r -d '' f; do [[ -e "$REPO/$f" || -L "$REPO/$f" ]] && printf '%s\0' "$f"; done |
    (cd "$REPO" && xargs -0 cp -P --parents -t "$CLONE")
described="$(in_chroot /usr/bin/swift package describe --package-path "$CLONE" 2>&1)" ||
    { echo "$described" >&2; log "the root Package.swift does not resolve"; exit 1; }
for want in "Name: Waymark" "Path: ios/Sources/Waymark" "Path: ios/Sources/WaymarkFFI" \
            "PrivacyInfo.xcprivacy" "LocationClient.swift" "Background.swift" "Waymark.swift"; do
    grep -qF "$want" <<<"$described" || { echo "$described" >&2; log "describe lacks: $want"; exit 1; }
done
# The manifest's Apple branch (compiled only on a Mac) as SwiftPM reads it: with no release the
# binary target is the local XCFramework; after set-package-release.sh, the release's zip.
APPLE="$TARGET/swift-apple"
rm -rf "$APPLE" && mkdir -p "$APPLE"
sed 's/^#if os(Linux)$/#if false/' "$CLONE/Package.swift" > "$APPLE/Package.swift"
grep -q '^#if false$' "$APPLE/Package.swift" || { log "Package.swift has no #if os(Linux) branch"; exit 1; }
dumped="$(in_chroot /usr/bin/swift package dump-package --package-path "$APPLE" 2>&1)"
grep -q '"path" : "ios/WaymarkFFI.xcframework"' <<<"$dumped" || { echo "$dumped" >&2; log "no local binary target"; exit 1; }
zip_url="https://example.com/waymark/releases/download/0.1.0/WaymarkFFI.xcframework.zip"
zip_sum="$(printf '%s' "$zip_url" | sha256sum | cut -d' ' -f1)"
"$REPO/ios/set-package-release.sh" "$zip_url" "$zip_sum" "$APPLE/Package.swift" 2>/dev/null
dumped="$(in_chroot /usr/bin/swift package dump-package --package-path "$APPLE" 2>&1)"
grep -qF "\"url\" : \"$zip_url\"" <<<"$dumped" && grep -qF "\"checksum\" : \"$zip_sum\"" <<<"$dumped" ||
    { echo "$dumped" >&2; log "set-package-release.sh did not give the binary target its URL and checksum"; exit 1; }
# The iOS shell, which only Xcode compiles: at least it must parse as Swift.
sed 's/^#if os(iOS)$/#if true/' "$GENERATED/Waymark/AppleAdapter.swift" > "$APPLE/AppleAdapter.swift"
grep -q '^#if true$' "$APPLE/AppleAdapter.swift" || { log "AppleAdapter.swift has no #if os(iOS)"; exit 1; }
in_chroot /usr/bin/swiftc -parse "$APPLE/AppleAdapter.swift" || { log "AppleAdapter.swift does not parse"; exit 1; }
rm -rf "$CLONE" "$APPLE"

# --- 6. XCTest in the chroot: bindings/swift depends on the root package by path.
log "swift test (in $ROOT)"
in_chroot WAYMARK_SIM_DIR="$TARGET/sim-export" WAYMARK_CLI="$TARGET/release/waymark" LD_LIBRARY_PATH="$TARGET/debug" \
    /usr/bin/swift test --disable-swift-testing \
        --package-path "$REPO/bindings/swift" --scratch-path "$TARGET/swift-build" \
        -Xlinker -L -Xlinker "$TARGET/debug" -Xlinker -rpath -Xlinker "$TARGET/debug" 2>&1
