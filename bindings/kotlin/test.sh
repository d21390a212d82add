#!/usr/bin/env bash
# The Kotlin test of Waymark on the JVM: builds the library and uniffi's generator, generates the
# Kotlin bindings, exports a simulated site and walk, compiles the bindings, the Android
# library's plain Kotlin and the JUnit 4 test with kotlinc (and a Java caller with javac) and
# runs it. Installs what is missing (Debian: libjna-java junit4; npm: the Kotlin
# compiler, unpacked under $TARGET/tools). Last line: exactly "N passed, N failed".
# Usage: bash bindings/kotlin/test.sh        (from anywhere; honours CARGO_TARGET_DIR)
#        bash bindings/kotlin/test.sh --tools-only   (installs and unpacks the tools, then stops;
#        scripts/test.sh runs it in the background during its demo step)
set -euo pipefail
tools_only=0
[ "${1:-}" = --tools-only ] && tools_only=1

KOTLIN_VERSION=2.4.20
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
REPO=$(cd "$HERE/../.." && pwd)
TARGET=${CARGO_TARGET_DIR:-$REPO/target}
mkdir -p "$TARGET"
TARGET=$(cd "$TARGET" && pwd) # absolute, whatever the caller's directory
export CARGO_TARGET_DIR=$TARGET
TOOLS=$TARGET/tools
KOTLIN_HOME=$TOOLS/kotlin-compiler-$KOTLIN_VERSION
OUT=$TARGET/kotlin-test
BINDINGS=$TARGET/bindings/kotlin
SIM=$TARGET/sim-export

# Whatever stops the script before the tests report, CI still gets its line.
summary_printed=0
on_exit() {
    local status=$?
    if [ "$summary_printed" = 0 ]; then
        echo "test.sh: failed before the tests reported (exit $status)" >&2
        echo "0 passed, 1 failed"
    fi
}
trap on_exit EXIT
step() { echo "== $*" >&2; }

# --- Tools -------------------------------------------------------------------------------------
missing=()
for pkg in libjna-java junit4; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
    step "apt-get install ${missing[*]}"
    sudo=()
    [ "$(id -u)" = 0 ] || sudo=(sudo)
    "${sudo[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
fi
command -v java >/dev/null || { echo "test.sh: no java on PATH (Java 17 expected)" >&2; exit 1; }

if [ ! -x "$KOTLIN_HOME/bin/kotlinc" ]; then
    step "npm pack kotlin-compiler@$KOTLIN_VERSION -> $KOTLIN_HOME"
    mkdir -p "$TOOLS"
    scratch=$(mktemp -d "$TOOLS/.kotlin.XXXXXX")
    (cd "$scratch" && npm pack --silent "kotlin-compiler@$KOTLIN_VERSION" >/dev/null)
    tar -xzf "$scratch"/kotlin-compiler-*.tgz -C "$scratch"
    rm -rf "$KOTLIN_HOME"
    mv "$scratch/package" "$KOTLIN_HOME"
    rm -rf "$scratch"
fi
KOTLINC=$KOTLIN_HOME/bin/kotlinc
STDLIB=$KOTLIN_HOME/lib/kotlin-stdlib.jar
COROUTINES=$KOTLIN_HOME/lib/kotlinx-coroutines-core-jvm.jar
JNA=/usr/share/java/jna.jar
JUNIT=/usr/share/java/junit4.jar
HAMCREST=/usr/share/java/hamcrest-core.jar
[ -f "$HAMCREST" ] || HAMCREST=/usr/share/java/hamcrest.jar
for jar in "$STDLIB" "$COROUTINES" "$JNA" "$JUNIT" "$HAMCREST"; do
    [ -f "$jar" ] || { echo "test.sh: missing $jar" >&2; exit 1; }
done
if (( tools_only )); then
    summary_printed=1
    exit 0
fi

# --- Build, generate, export ---------------------------------------------------------------------
cd "$REPO"
step "cargo build -p uniffi-bindgen"
cargo build -p uniffi-bindgen
# The simulated site and walk, by the release CLI: the survey test builds a site with it, which
# takes minutes in a debug build and seconds in release (the test is of the recorder and the
# CLI's pipeline, not of the build profile). A release build leaves target/debug alone.
step "waymark sim-export --out $SIM"
cargo build --release -p waymark-cli
"$TARGET/release/waymark" sim-export --out "$SIM"
# The same site with its transmitter ids hashed, under a fixed test salt.
echo 5a1f00d0c0ffee00112233445566778899aabbccddeeff0123456789abcdef01 > "$SIM/salt.hex"
"$TARGET/release/waymark" site hash --salt-file "$SIM/salt.hex" "$SIM/site.json" "$SIM/site-hashed.json" >&2
# The same site in the binary encoding an app ships.
"$TARGET/release/waymark" site pack "$SIM/site.json" "$SIM/site.wmsite" >&2
# The shipped library (plus the test-only fault injection): the one the JVM loads.
step "cargo build --lib"
# A test build: a scan at ULong.MAX - 7 panics inside the engine (feature fault-injection).
cargo build -p waymark --lib --features fault-injection
LIB=$TARGET/debug/libwaymark.so
step "uniffi-bindgen generate -> $BINDINGS"
rm -rf "$BINDINGS"
"$TARGET/debug/uniffi-bindgen" generate --no-format --library "$LIB" --language kotlin --out-dir "$BINDINGS"
GENERATED=$BINDINGS/dev/waymark/waymark.kt
[ -f "$GENERATED" ] || { echo "test.sh: uniffi-bindgen wrote no $GENERATED" >&2; exit 1; }

# --- Compile and run -----------------------------------------------------------------------------
# The Android library's plain Kotlin (every file without an android.* import: the location
# client, its ports, the conversions); the files that do import android.* are its thin shell.
mapfile -t ANDROID_PLAIN < <(grep -L '^import android\.' "$REPO"/android/src/main/kotlin/dev/waymark/android/*.kt)
# kotlinx-coroutines: the client's Flow (and the generated code's async functions, if any).
compile_cp=$JNA:$JUNIT:$COROUTINES
run_cp=$STDLIB:$JNA:$JUNIT:$HAMCREST:$COROUTINES
step "kotlinc (with the README's Kotlin quickstart and the Android guide's code)"
rm -rf "$OUT"
mkdir -p "$OUT/classes"
python3 "$REPO/scripts/readme-snippet.py" kotlin-quickstart > "$OUT/ReadmeQuickstart.kt"
python3 "$REPO/scripts/readme-snippet.py" android-statuses docs/android.md > "$OUT/AndroidGuideStatuses.kt"
python3 "$REPO/scripts/readme-snippet.py" kotlin-survey docs/surveying.md > "$OUT/SurveyingGuide.kt"
python3 "$REPO/scripts/readme-snippet.py" android-survey docs/android.md > "$OUT/AndroidGuideSurvey.kt"
python3 "$REPO/scripts/readme-snippet.py" building-map-kotlin docs/your-building.md > "$OUT/BuildingGuideMap.kt"
"$KOTLINC" -nowarn -jvm-target 17 -cp "$compile_cp" -d "$OUT/classes" \
    "$GENERATED" "$HERE"/src/test/kotlin/dev/waymark/*.kt "$OUT/ReadmeQuickstart.kt" \
    "$OUT/AndroidGuideStatuses.kt" "$OUT/SurveyingGuide.kt" "$OUT/AndroidGuideSurvey.kt" "$OUT/BuildingGuideMap.kt" \
    "${ANDROID_PLAIN[@]}"
# Java callers of the Android client (no unsigned type, default methods, the builder): javac
# against the classes kotlinc made.
step "javac (the client from Java)"
javac -nowarn -source 17 -target 17 -cp "$OUT/classes:$compile_cp:$STDLIB" -d "$OUT/classes" "$HERE"/src/test/java/dev/waymark/*.java

step "JUnit 4"
set +e
java -Djna.library.path="$TARGET/debug" \
    -Dwaymark.site="$SIM/site.json" -Dwaymark.walk="$SIM/walk.json" \
    -Dwaymark.hashedSite="$SIM/site-hashed.json" -Dwaymark.salt="$SIM/salt.hex" \
    -Dwaymark.packedSite="$SIM/site.wmsite" \
    -Dwaymark.surveyWalks="$SIM/survey" -Dwaymark.cli="$TARGET/release/waymark" \
    -Dwaymark.android="$REPO/android" \
    -cp "$OUT/classes:$run_cp" dev.waymark.RunTests 2>&1 | tee "$OUT/junit.log"
status=${PIPESTATUS[0]}
set -e
summary_printed=1
last=$(tail -n 1 "$OUT/junit.log")
if ! [[ "$last" =~ ^[0-9]+\ passed,\ [0-9]+\ failed$ ]]; then
    # The JVM died before the runner's summary (a crash in native code, say).
    echo "test.sh: the JVM exited with $status before the summary" >&2
    echo "$(grep -c '^PASS ' "$OUT/junit.log" || true) passed, 1 failed"
    exit 1
fi
exit "$status"
