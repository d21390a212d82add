#!/usr/bin/env bash
# The page test of `waymark view` (docs/view.md#the-test): builds the CLI, writes three pages —
# the simulated office with its walk (`waymark view --demo`), a two-floor site (the office's
# site file with a copy of its floor above it, joined by a stair edge), and that site
# geo-referenced with a survey coverage file (`--coverage`, 5 points on one floor, 3 on the
# other, each of which the page must say it drew) — and loads
# every floor of each (`#floor=N`) in headless Chromium. A floor passes when the page says it
# drew that floor (body[data-rendered], data-floor, its states), recorded no error
# (window.onerror, console.error: body[data-errors], #errors), and its screenshot's map area
# is not blank (enough pixels unlike the background). Two control pages, one logging an error
# and one with the map hidden, must fail the same checks. Installs Debian's chromium when
# missing. Last line: exactly "N passed, N failed".
# Usage: bash scripts/view-test.sh        (from anywhere; honours CARGO_TARGET_DIR)
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"
target=${CARGO_TARGET_DIR:-$repo/target}
mkdir -p "$target"
target=$(cd "$target" && pwd)
work="$target/view-test"
rm -rf "$work"
mkdir -p "$work"

summary_printed=0
on_exit() {
    local status=$?
    if [ "$summary_printed" = 0 ]; then
        echo "view-test.sh: failed before the tests reported (exit $status)" >&2
        echo "0 passed, 1 failed"
    fi
}
trap on_exit EXIT

if ! command -v chromium >/dev/null 2>&1; then
    sudo=()
    [ "$(id -u)" = 0 ] || sudo=(sudo)
    "${sudo[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends chromium >&2
fi

echo "-- pages"
# The release CLI, as the rest of scripts/test.sh uses (one CLI build for the whole suite).
cargo build --release -p waymark-cli --locked --quiet
waymark="$target/release/waymark"
"$waymark" view --demo --out "$work/demo.html"
"$waymark" sim-export --walk-length-m 40 --out "$work/sim"
python3 - "$work/sim/site.json" "$work/two-floors.json" <<'PY'
import json, sys
site = json.load(open(sys.argv[1]))
offset = max(s["id"] for s in site["states"]) + 1
site["name"] += ", two floors"
site["floors"].append({"name": "upstairs", "elevation_m": 4.0})
upper = [dict(s, id=s["id"] + offset, floor=1) for s in site["states"] if s["floor"] == 0]
edges = [dict(e, **{"from": e["from"] + offset, "to": e["to"] + offset}) for e in site["edges"]]
stairs = max(upper, key=lambda s: (s["x"], s["y"]))["id"]  # the stair hall's far corner
site["edges"] += edges + [{"from": stairs - offset, "to": stairs, "length_m": 6.0}]
site["zones"] += [dict(z, name=z["name"] + " upstairs", states=[i + offset for i in z["states"]])
                  for z in site.get("zones", [])]
site["states"] += upper
json.dump(site, open(sys.argv[2], "w"))
PY
"$waymark" view --site "$work/two-floors.json" --out "$work/two-floors.html"
# The same site on the Earth, and held-out epochs beyond its map as `waymark survey
# --coverage-out` writes them (x east and y north of the anchor; 111 320 m a degree of
# latitude is close enough to land them by the states they are put beside).
python3 - "$work/two-floors.json" "$work/anchored.json" "$work/coverage.geojson" <<'PY'
import json, math, sys
site = json.load(open(sys.argv[1]))
lat0, lon0 = 30.19, 120.08
site["anchor"] = {"lat_deg": lat0, "lon_deg": lon0, "azimuth_rad": 0.0, "scale": [1.0, 1.0]}
json.dump(site, open(sys.argv[2], "w"))
features = []
for floor, name, count in [(0, site["floors"][0]["name"], 5), (1, "upstairs", 3)]:
    states = [s for s in site["states"] if s["floor"] == floor][:count]
    for s in states:
        x, y = s["x"] + 1.5, s["y"] + 1.5
        at = [lon0 + x / (111320.0 * math.cos(math.radians(lat0))), lat0 + y / 111320.0]
        features.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": at},
                         "properties": {"floor": name, "level": floor, "walk": "w", "beyond_map_m": 3.0,
                                        "error_m": 12.0}})
json.dump({"type": "FeatureCollection", "features": features}, open(sys.argv[3], "w"))
PY
"$waymark" view --site "$work/anchored.json" --coverage "$work/coverage.geojson" --out "$work/coverage.html"
# Controls: a page that logs an error, and one whose map is hidden (blank).
sed 's|</body>|<script>console.error("control error")</script></body>|' "$work/demo.html" >"$work/control-error.html"
sed 's|</style>|#map { visibility: hidden; }</style>|' "$work/demo.html" >"$work/control-blank.html"

# One Chromium run per output, each with a fresh profile; no network, no background services.
chrome() {
    local profile
    profile=$(mktemp -d "$work/profile.XXXXXX")
    timeout 120 chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
        --disable-background-networking --disable-component-update --disable-sync \
        --user-data-dir="$profile" --window-size=1200,800 --force-device-scale-factor=1 \
        --hide-scrollbars "$@" 2>>"$work/chromium.log"
    rm -rf "$profile"
}

# The checks of one floor: the page's DOM as Chromium left it, and its screenshot.
cat >"$work/check.py" <<'PY'
import re, struct, sys, zlib
dom_path, png_path, floor, floors = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
coverage = sys.argv[5] if len(sys.argv) > 5 else "0"
problems = []
dom = open(dom_path, errors="replace").read()
tag = re.search(r"<body([^>]*)>", dom)
attrs = dict(re.findall(r'([\w-]+)="([^"]*)"', tag.group(1))) if tag else {}
def attr(name):
    return attrs.get("data-" + name)
if attr("rendered") != "1":
    problems.append("not rendered (body[data-rendered] %r)" % attr("rendered"))
if attr("errors") != "0":
    shown = re.search(r'<pre id="errors"[^>]*>(.*?)</pre>', dom, re.S)
    problems.append("errors recorded: %s" % (shown.group(1).strip() if shown else attr("errors")))
if attr("floor") != str(floor) or attr("floors") != str(floors):
    problems.append("drew floor %s of %s, not %d of %d" % (attr("floor"), attr("floors"), floor, floors))
if not (attr("states") or "0").isdigit() or int(attr("states") or "0") == 0:
    problems.append("no states drawn")
if attr("coverage") != coverage:
    problems.append("drew %s coverage points, not %s" % (attr("coverage"), coverage))

def pixels(path):
    """Rows of (r, g, b) of an 8-bit RGB or RGBA, non-interlaced PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        chunk = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat += chunk
    width, height, depth, color, _, _, interlace = header
    if depth != 8 or color not in (2, 6) or interlace:
        raise ValueError("unsupported PNG (depth %d, colour type %d)" % (depth, color))
    bpp = 3 if color == 2 else 4
    raw, stride, rows, prev = zlib.decompress(idat), width * bpp, [], bytearray(width * bpp)
    for y in range(height):
        kind, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if kind == 1: line[i] = (line[i] + a) & 255
            elif kind == 2: line[i] = (line[i] + b) & 255
            elif kind == 3: line[i] = (line[i] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append([tuple(line[x * bpp:x * bpp + 3]) for x in range(width)])
        prev = line
    return rows

try:
    rows = pixels(png_path)
    # The map's band (between the control bar and the status line); background #f4f3ef.
    band = rows[len(rows) // 10:len(rows) * 9 // 10]
    drawn = sum(1 for row in band for p in row if max(abs(p[0] - 244), abs(p[1] - 243), abs(p[2] - 239)) > 24)
    share = drawn / max(1, sum(len(row) for row in band))
    if share < 0.01:
        problems.append("blank screenshot: %.2f%% of the map drawn" % (100 * share))
except (OSError, ValueError, TypeError, zlib.error) as e:
    problems.append("screenshot: %s" % e)
for p in problems:
    print("   " + p)
sys.exit(1 if problems else 0)
PY

passed=0
failed=0
# check PAGE FLOOR FLOORS EXPECT [COVERAGE]: EXPECT is "pass", or "fail" for a control;
# COVERAGE the coverage points the floor must draw (default 0).
check() {
    local page=$1 floor=$2 floors=$3 expect=$4 coverage=${5:-0} name
    name="$(basename "$page" .html) floor $floor"
    local url="file://$work/$page#floor=$floor" out="$work/${page%.html}-$floor"
    chrome --virtual-time-budget=2000 --dump-dom "$url" >"$out.html" || true
    chrome --virtual-time-budget=2000 --screenshot="$out.png" "$url" >/dev/null || true
    if python3 "$work/check.py" "$out.html" "$out.png" "$floor" "$floors" "$coverage"; then result=pass; else result=fail; fi
    if [ "$result" = "$expect" ]; then
        passed=$((passed + 1))
        echo "ok: $name ($expect)"
    else
        failed=$((failed + 1))
        echo "FAILED: $name: expected $expect, got $result"
    fi
}

echo "-- floors in headless Chromium ($(chromium --version 2>/dev/null))"
check demo.html 0 1 pass
check two-floors.html 0 2 pass
check two-floors.html 1 2 pass
check coverage.html 0 2 pass 5
check coverage.html 1 2 pass 3
check control-error.html 0 1 fail
check control-blank.html 0 1 fail

summary_printed=1
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]
