#!/usr/bin/env bash
# The Swift bindings tested on Linux: builds libwaymark, checks that the Swift committed in
# ios/Sources/ is what uniffi-bindgen generates today, exports a simulated walk, and runs the
# XCTest suite in bindings/swift/ with Debian trixie's swiftlang inside a chroot.
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

# --- 4. The README's Swift quickstart and the Swift snippets of docs/ios.md and
# docs/surveying.md (every block between `<!-- snippet: NAME -->` and `<!-- /snippet -->`),
# compiled into the test target (not committed).
{
    python3 "$REPO/scripts/readme-snippet.py" swift-quickstart
    python3 - "$REPO/docs/ios.md" "$REPO/docs/surveying.md" <<'PY'
import re, sys
for path in sys.argv[1:]:
    guide = open(path).read()
    blocks = re.findall(r"<!-- snippet: [\w-]+ -->\n```swift\n(.*?)```\n<!-- /snippet -->", guide, re.S)
    if not blocks:
        sys.exit(f"test.sh: no Swift snippet in {path}")
    sys.stdout.write("".join(blocks))
PY
} > "$REPO/bindings/swift/Tests/WaymarkTests/ReadmeQuickstart.swift"

# --- 5. XCTest in the chroot. The checkout (and the target dir, if elsewhere) is bind-mounted
# at the same path inside, so every path resolves identically.
log "swift test (in $ROOT)"
MOUNTS=("$REPO")
[[ "$TARGET/" == "$REPO/"* ]] || MOUNTS+=("$TARGET")
# shellcheck disable=SC2016
unshare --mount --fork /bin/bash -euo pipefail -c '
    root="$1"; target="$2"; package="$3"; shift 3
    mount --make-rprivate /
    for d in "$@"; do mkdir -p "$root$d"; mount --bind "$d" "$root$d"; done
    mount -t proc proc "$root/proc"
    mount --rbind /dev "$root/dev"
    exec chroot "$root" /usr/bin/env -i PATH=/usr/bin:/bin HOME=/root LANG=C.UTF-8 \
        WAYMARK_SIM_DIR="$target/sim-export" WAYMARK_CLI="$target/release/waymark" LD_LIBRARY_PATH="$target/debug" \
        /usr/bin/swift test --disable-swift-testing \
            --package-path "$package" --scratch-path "$target/swift-build" \
            -Xlinker -L -Xlinker "$target/debug" -Xlinker -rpath -Xlinker "$target/debug"
' _ "$ROOT" "$TARGET" "$REPO/bindings/swift" "${MOUNTS[@]}" 2>&1
