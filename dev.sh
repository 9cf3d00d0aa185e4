#!/usr/bin/env bash
# Set-up and entry points for a fresh Debian/Ubuntu machine with Python 3.10+ and no ROS.
#   ./dev.sh demo   create .venv, install pinned dependencies, run the end-to-end demo
#                   (outputs in demo_out/; extra arguments go to `clusterfilter demo`)
#   ./dev.sh test   create .venv, install pinned dependencies, lint and run the tests
#   ./dev.sh install   only the set-up
# Environment: PYTHON (default python3), VENV (default .venv next to this script).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here"
PYTHON=${PYTHON:-python3}
VENV=${VENV:-$here/.venv}
PY="$VENV/bin/python"

# Every rclpy context started from here stays on loopback with its own domain.
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((100 + RANDOM % 100))}
export FASTRTPS_DEFAULT_PROFILES_FILE=${FASTRTPS_DEFAULT_PROFILES_FILE:-$here/config/fastdds_loopback.xml}
export RMW_IMPLEMENTATION=${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}

install() {
  local stamp="$VENV/.clusterfilter-installed"
  if [ -f "$stamp" ] && [ "$stamp" -nt requirements.txt ] && [ "$stamp" -nt setup.py ]; then
    return 0
  fi
  if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null; then
    echo "dev.sh: need Python 3.10 or newer as '$PYTHON' (set PYTHON=...)" >&2
    exit 2
  fi
  if [ ! -x "$PY" ]; then
    if ! "$PYTHON" -m venv "$VENV" 2>/dev/null; then
      rm -rf "$VENV"
      if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "dev.sh: installing python3-venv with apt-get" >&2
        apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null
        "$PYTHON" -m venv "$VENV"
      else
        echo "dev.sh: '$PYTHON -m venv' failed; install python3-venv (sudo apt-get install python3-venv)" >&2
        exit 2
      fi
    fi
  fi
  "$PY" -m pip install -q --upgrade pip
  "$PY" -m pip install -q -r requirements.txt
  "$PY" -m pip install -q --no-deps -e .
  touch "$stamp"
}

cmd=${1:-}
shift || true
case "$cmd" in
  install)
    install
    ;;
  demo)
    install
    exec "$VENV/bin/clusterfilter" demo --out "$here/demo_out" "$@"
    ;;
  test)
    install
    "$VENV/bin/ruff" check .
    "$VENV/bin/ruff" format --check .
    exec "$PY" -m pytest "$@"
    ;;
  *)
    echo "usage: ./dev.sh demo|test|install [args...]" >&2
    exit 2
    ;;
esac
