#!/usr/bin/env bash
# Build ArduPilot's ArduSub SITL binary (the real firmware with a simulated vehicle) from source:
# the binary tests/test_sitl_ardusub.py runs as the UUV's autopilot.
#
#   deploy/build_ardusub.sh [--ref REF] [--out DIR] [--work DIR] [--jobs N]
#
#   --ref REF   ArduPilot commit, tag or branch (default 90700977c5: master of 2025-07-21,
#               "ArduSub V4.7.0-dev", the build skyfix's tests were written against)
#   --out DIR   where ardusub and sub.parm go (default ./ardusub-sitl)
#   --work DIR  where the ArduPilot checkout and a Python venv for its build live
#               (default ./ardusub-build; reused by later runs)
#   --jobs N    parallel compile jobs (default: all cores)
#
# Steps: git clone https://github.com/ArduPilot/ardupilot (or fetch into an existing checkout),
# check out REF, update the submodules, `./waf configure --board sitl && ./waf sub`, then copy
# build/sitl/bin/ardusub and Tools/autotest/default_params/sub.parm into --out. Afterwards:
#
#   SKYFIX_ARDUSUB=ardusub-sitl/ardusub ./dev test tests/test_sitl_ardusub.py
#
# Needs git, a C++ toolchain (g++ or clang, make: Debian/Ubuntu `build-essential`), python3 with
# venv, and network access to GitHub and PyPI (ArduPilot's build runs Python generators: empy 3.x,
# pexpect, future, lxml, dronecan; installed into a venv under --work). ArduPilot is GPLv3; the
# binary is a test tool and is not part of skyfix.
#
# Status: written without network access to GitHub, so never run end to end here; checked with
# `bash -n` and shellcheck only. The waf commands are the ones that built ../shared/tools/ardusub.
set -euo pipefail

REPO_URL=https://github.com/ArduPilot/ardupilot.git
REF=90700977c5
OUT=ardusub-sitl
WORK=ardusub-build
JOBS=$(nproc 2>/dev/null || echo 2)

usage() {  # the option lines of this header
    sed -n '5,12p' "$0" | sed 's/^# \{0,1\}//'
}

while [ $# -gt 0 ]; do
    case "$1" in
        --ref) REF=${2:?--ref needs a value}; shift 2 ;;
        --out) OUT=${2:?--out needs a value}; shift 2 ;;
        --work) WORK=${2:?--work needs a value}; shift 2 ;;
        --jobs) JOBS=${2:?--jobs needs a value}; shift 2 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "build_ardusub: unknown argument: $1" >&2; usage >&2; exit 2 ;;
    esac
done

for tool in git python3; do
    command -v "$tool" >/dev/null 2>&1 || { echo "build_ardusub: $tool not found" >&2; exit 1; }
done
if ! command -v g++ >/dev/null 2>&1 && ! command -v clang++ >/dev/null 2>&1; then
    echo "build_ardusub: no C++ compiler (apt install build-essential)" >&2
    exit 1
fi

mkdir -p "$WORK" "$OUT"
WORK=$(cd "$WORK" && pwd)
OUT=$(cd "$OUT" && pwd)
SRC="$WORK/ardupilot"
VENV="$WORK/venv"

echo "build_ardusub: ArduPilot $REF in $SRC" >&2
if [ ! -d "$SRC/.git" ]; then
    git clone "$REPO_URL" "$SRC"
else
    git -C "$SRC" fetch --tags origin
fi
git -C "$SRC" checkout --detach "$REF"
git -C "$SRC" submodule sync --recursive
git -C "$SRC" submodule update --init --recursive

if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" -m pip install -q "empy==3.3.4" pexpect future lxml dronecan setuptools
fi

cd "$SRC"
"$VENV/bin/python" ./waf configure --board sitl
"$VENV/bin/python" ./waf sub -j "$JOBS"

install -m 0755 build/sitl/bin/ardusub "$OUT/ardusub"
install -m 0644 Tools/autotest/default_params/sub.parm "$OUT/sub.parm"
{
    echo "ArduPilot $(git describe --always --dirty) ($(git rev-parse HEAD)), built by deploy/build_ardusub.sh"
    echo "./waf configure --board sitl && ./waf sub"
} > "$OUT/BUILD_INFO"
echo "build_ardusub: $OUT/ardusub and $OUT/sub.parm; run the test with:" >&2
echo "  SKYFIX_ARDUSUB=$OUT/ardusub ./dev test tests/test_sitl_ardusub.py" >&2
