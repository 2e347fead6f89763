#!/usr/bin/env bash
# One set-up path for everything (make demo, make test, CI): creates .venv from PyPI, builds and
# installs ins_gnss_msgs into it, installs ins_gnss_ros editable. Idempotent: each step is skipped
# when its inputs have not changed since it last succeeded (hash stamps in .venv/.stamps).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
STAMPS="$VENV/.stamps"
cd "$ROOT"

say() { printf '[setup] %s\n' "$*"; }
# pip, without the machine's notes about absent local mirrors (its exit status is kept by pipefail)
pip() { "$PY" -m pip "$@" 2>&1 | { grep -v "is ignored: it is neither a file nor a directory" || true; }; }

# Build tools for the message package. Installed from Debian only when missing.
missing=()
command -v cmake >/dev/null || missing+=(cmake)
command -v g++ >/dev/null || missing+=(g++)
command -v python3 >/dev/null || missing+=(python3 python3-venv python3-dev)
if ((${#missing[@]})); then
  say "installing ${missing[*]} with apt-get"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
fi

if [ ! -x "$PY" ]; then
  say "creating $VENV"
  python3 -m venv "$VENV"
fi
mkdir -p "$STAMPS"

# stamp NAME FILES...: true when the hash of FILES differs from the one recorded for NAME
changed() {
  local name=$1; shift
  local now; now=$(cat "$@" | sha256sum | cut -d' ' -f1)
  [ "$(cat "$STAMPS/$name" 2>/dev/null)" != "$now" ] && { echo "$now" > "$STAMPS/$name.new"; return 0; }
  return 1
}
done_stamp() { mv "$STAMPS/$1.new" "$STAMPS/$1"; }

if changed requirements requirements.txt constraints.txt; then
  say "installing pinned requirements"
  pip install -q --upgrade "pip==26.3"
  pip install -q -r requirements.txt -c constraints.txt
  done_stamp requirements
fi

# The ament index lives in the venv prefix; CMake needs it to find the rosidl type supports.
export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH"
if changed msgs $(find src/ins_gnss_msgs packaging/ins_gnss_msgs -type f | sort) requirements.txt; then
  say "building ins_gnss_msgs"
  pip install -q --no-build-isolation --no-deps --force-reinstall ./packaging/ins_gnss_msgs
  done_stamp msgs
fi
# tf2_msgs (for /tf, /tf_static) has no PyPI wheel: built the same way from its upstream definition.
if changed tf2_msgs $(find packaging/tf2_msgs -type f | sort) requirements.txt; then
  say "building tf2_msgs"
  pip install -q --no-build-isolation --no-deps --force-reinstall ./packaging/tf2_msgs
  done_stamp tf2_msgs
fi

if changed ins_gnss_ros src/ins_gnss_ros/setup.py src/ins_gnss_ros/setup.cfg src/ins_gnss_ros/package.xml; then
  say "installing ins_gnss_ros (editable)"
  pip install -q --no-build-isolation --no-deps -e src/ins_gnss_ros
  done_stamp ins_gnss_ros
fi

# The numba kernels' machine code (cache=True: the __pycache__ next to their sources), built here
# so that a first run does not spend its start compiling (scripts/warm_numba.py). numba compiles
# a kernel again when its source file's size or time stamp changed: the key holds those, the
# warm-up script's, the cache files present and the pinned numba.
KERNELS=(src/ins_gnss_ros/ins_gnss_ros/nav/_kernels.py src/ins_gnss_ros/ins_gnss_ros/nav/earth.py
         src/ins_gnss_ros/ins_gnss_ros/gnss/lambda_search.py scripts/warm_numba.py)
numba_key() {
  { stat -c '%n %s %Y' "${KERNELS[@]}"; ls src/ins_gnss_ros/ins_gnss_ros/{nav,gnss}/__pycache__/*.nbi 2>/dev/null
    grep -i '^numba' constraints.txt; } | sha256sum | cut -d' ' -f1
}
if [ "$(cat "$STAMPS/numba" 2>/dev/null)" != "$(numba_key)" ]; then
  say "compiling the numba kernels into their cache"
  "$PY" scripts/warm_numba.py > "$STAMPS/numba.log" 2>&1 || { cat "$STAMPS/numba.log"; exit 1; }
  numba_key > "$STAMPS/numba"
fi
say "ready: $VENV"
