#!/usr/bin/env bash
# Installs what nidar_mi needs on a Debian/Ubuntu machine: libLLVM >= 16 for Dr.Jit's CPU
# back end (via apt when missing and running as root), then a virtual environment with the
# package, every optional extra and the development tools, at the versions of constraints.txt.
set -euo pipefail
PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}

have_any() {  # true when at least one of the (glob-expanded) paths exists
    for f in "$@"; do [ -e "$f" ] && return 0; done
    return 1
}

have_llvm() {
    have_any /usr/lib/*-linux-gnu/libLLVM-1[6-9]*.so* /usr/lib/*-linux-gnu/libLLVM-[2-9][0-9]*.so* \
        /usr/lib/llvm-1[6-9]/lib/libLLVM*.so* /usr/lib/llvm-[2-9][0-9]/lib/libLLVM*.so*
}

have_libusb() {  # Open3D (benchmarks) needs it
    have_any /usr/lib/*-linux-gnu/libusb-1.0.so* /usr/lib/libusb-1.0.so*
}

if ! have_llvm || ! have_libusb; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "setup: installing libllvm19 and libusb-1.0-0 with apt-get"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 libusb-1.0-0 >/dev/null
    elif ! have_llvm; then
        echo "setup: libLLVM >= 16 not found; run: sudo apt-get install libllvm19" >&2
        exit 1
    fi
fi

if [ ! -x "$VENV/bin/python" ]; then
    if ! "$PYTHON" -m venv "$VENV" >/dev/null 2>&1; then
        rm -rf "$VENV"
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
            echo "setup: installing python3-venv with apt-get"
            apt-get update -qq
            DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
            "$PYTHON" -m venv "$VENV"
        else
            echo "setup: '$PYTHON -m venv' failed; run: sudo apt-get install python3-venv" >&2
            exit 1
        fi
    fi
fi
# pip's output (build-backend notices included) is shown only when a step fails.
LOG=$(mktemp "${TMPDIR:-/tmp}/nidar_setup.XXXXXX")
trap 'rm -f "$LOG"' EXIT
quietly() {  # run a command with its output in $LOG; print the log and stop when it fails
    if ! "$@" >"$LOG" 2>&1; then
        cat "$LOG" >&2
        echo "setup: '$*' failed" >&2
        exit 1
    fi
}
# Every version comes from constraints.txt (scripts/lock_dependencies.py writes it), so two
# set-ups a month apart install the same packages.
PIN=(-c constraints.txt)
quietly "$VENV/bin/python" -m pip install -q "${PIN[@]}" --upgrade pip
# The CPU build of torch; an unpinned torch would pull a multi-GB CUDA build.
quietly "$VENV/bin/python" -m pip install -q "${PIN[@]}" "torch==2.13.0"
# The package with every extra the tests need (.[dev]; a plain `pip install .` is the lean core).
quietly "$VENV/bin/python" -m pip install -q "${PIN[@]}" -e ".[dev]"
"$VENV/bin/python" -c "import nidar_mi, mitsuba, drjit, torch" \
    || { echo "setup: the environment in $VENV does not import (try: $VENV/bin/python -m pip install -e '.[dev]')" >&2; exit 1; }
echo "setup: ready ($VENV)"
