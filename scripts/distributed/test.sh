#!/usr/bin/env bash
# The distributed example (scripts/distributed/pipeline.py) on a Dask LocalCluster, checked
# against one machine: site1's F1, its first 8 walks labelled and the next 10 without labels.
# The site the cluster's evidence refits must be byte for byte the site that
# `waymark survey --unlabelled --anchor-rounds 0 --evidence-rounds 1` makes (docs/evidence.md#at-scale).
#
#   scripts/distributed/test.sh [path/to/waymark]
#
# Installs Dask (requirements.txt) in a venv under target/. Ends with `N passed, N failed`.
set -euo pipefail
cd "$(dirname "$0")/../.."
target=${CARGO_TARGET_DIR:-$PWD/target}
waymark=${1:-$target/release/waymark}
floor=$PWD/target/ilc/site1/F1
if [[ ! -d $floor/path_data_files ]]; then
    if [[ -n ${WAYMARK_REQUIRE_DATA:-} && ${WAYMARK_REQUIRE_DATA} != 0 ]]; then
        echo "distributed: $floor is missing and WAYMARK_REQUIRE_DATA is set (docs/testing.md#real-data)" >&2
        echo "0 passed, 1 failed"
        exit 1
    fi
    echo "distributed: skipping, $floor is missing (docs/testing.md#real-data)"
    exit 0
fi
[[ -x $waymark ]] || cargo build --release -p waymark-cli --locked --quiet

venv=$target/distributed-venv
if [[ ! -x $venv/bin/python ]]; then python3 -m venv "$venv"; fi
"$venv/bin/pip" install --quiet --disable-pip-version-check -r scripts/distributed/requirements.txt

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/F1/path_data_files" "$work/walks"
cp "$floor/floor_info.json" "$floor/geojson_map.json" "$work/F1/"
mapfile -t walks < <(find "$floor/path_data_files" -name '*.txt' | sort | head -18)
cp "${walks[@]:0:8}" "$work/F1/path_data_files/"
cp "${walks[@]:8:10}" "$work/walks/"

# One machine.
"$waymark" survey "$work/F1" --unlabelled "$work"/walks/*.txt --anchor-rounds 0 --evidence-rounds 1 \
    --out "$work/one.json" | grep "^map evidence"
# Many: the labelled site, then the cluster.
"$waymark" survey "$work/F1" --out "$work/site0.json" > /dev/null
"$venv/bin/python" scripts/distributed/pipeline.py --waymark "$waymark" --floors "$work/F1" \
    --site0 "$work/site0.json" --work "$work/evidence" --fan-in 3 --out "$work/many.json" "$work"/walks/*.txt

passed=0 failed=0
check() {
    if "${@:2}"; then echo "ok: $1"; passed=$((passed + 1)); else echo "FAILED: $1"; failed=$((failed + 1)); fi
}
check "the cluster's site is byte-identical to one machine's" cmp -s "$work/one.json" "$work/many.json"
check "the evidence changed the labelled site" bash -c '! cmp -s "$1" "$2"' _ "$work/site0.json" "$work/many.json"
echo "$passed passed, $failed failed"
(( failed == 0 ))
