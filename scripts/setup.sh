#!/usr/bin/env bash
# Install mincam_render on a fresh Debian machine: a recent libLLVM for Dr.Jit's
# CPU backend, a virtual environment in .venv, and the package with pinned deps.
#
# Usage: scripts/setup.sh [--dev]
#   --dev   also install the test and lint tools (pytest, hypothesis, ruff), the
#           traffic (Eclipse SUMO) and ray extras, so the traffic and Ray tests run,
#           and Debian's chromium, so the HTML reports are checked in a real browser
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
extras=""
if [[ "${1:-}" == "--dev" ]]; then extras="[dev,traffic,ray]"; fi

log() { echo "[setup] $*" >&2; }
die() { echo "[setup] ERROR: $*" >&2; exit 1; }

# Dr.Jit's LLVM backend aborts with LLVM <= 15 ("Cannot select ... fminimum").
find_libllvm() {
    local f best="" best_major=0 major
    for f in /usr/lib/*/libLLVM*.so* /usr/lib/llvm-*/lib/libLLVM*.so*; do
        [[ -e "$f" ]] || continue
        major="$(basename "$f" | sed -n 's/^libLLVM[.-]\{0,1\}\([0-9][0-9]*\).*/\1/p')"
        [[ -n "$major" ]] || continue
        if (( major >= 16 && major > best_major )); then best="$f"; best_major=$major; fi
    done
    echo "$best"
}

# apt_install PACKAGE WHY: install a Debian package as root (or with sudo)
apt_install() {
    local sudo=""
    if [[ "$(id -u)" != "0" ]]; then
        command -v sudo >/dev/null || die "$2 and we are not root: run 'apt-get install -y $1' as root"
        sudo="sudo"
    fi
    command -v apt-get >/dev/null || die "$2 and apt-get is unavailable: install $1 by other means"
    $sudo apt-get update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "$1" >/dev/null \
        || die "apt-get install $1 failed ($2)"
}

llvm="${DRJIT_LIBLLVM_PATH:-$(find_libllvm)}"
if [[ -z "$llvm" ]]; then
    log "no libLLVM >= 16 found; installing Debian's libllvm19"
    apt_install libllvm19 "libLLVM >= 16 is missing (or set DRJIT_LIBLLVM_PATH to an LLVM 16-19 libLLVM .so)"
    llvm="$(find_libllvm)"
    [[ -n "$llvm" ]] || die "libllvm19 installed but no libLLVM >= 16 found under /usr/lib: set DRJIT_LIBLLVM_PATH"
fi
log "using libLLVM: $llvm"

py="${PYTHON:-python3.11}"
command -v "$py" >/dev/null || py=python3
"$py" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' 2>/dev/null \
    || die "Python 3.11 is required (found: $("$py" --version 2>&1)); set PYTHON=/path/to/python3.11"

if [[ ! -x .venv/bin/python ]]; then
    log "creating virtual environment .venv"
    "$py" -m venv .venv
fi
log "installing mincam_render$extras (pinned: mitsuba 3.9.1, drjit 1.5.0, torch 2.13.0 CPU)"
# torch first and pinned: an unpinned resolve would pull a multi-GB CUDA build.
.venv/bin/python -m pip install -q --disable-pip-version-check "torch==2.13.0" \
    || die "pip could not install torch==2.13.0"
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".$extras" \
    || die "pip could not install mincam_render$extras"
.venv/bin/python -c "import mincam_render" || die "installation failed: 'import mincam_render' does not work in .venv"
DRJIT_LIBLLVM_PATH="$llvm" .venv/bin/python -m mincam_render.render.backend \
    || die "Dr.Jit cannot use $llvm; install libllvm19 or set DRJIT_LIBLLVM_PATH"
if [[ -n "$extras" && ! -x /usr/bin/chromium ]]; then
    log "installing Debian's chromium (headless checks of the HTML reports)"
    apt_install chromium "the report tests need a headless browser"
fi
log "ready: .venv/bin/mincam-render --help"
