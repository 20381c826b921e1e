#!/usr/bin/env bash
# Set up cablesim on a fresh Debian/Ubuntu machine: headless GL libraries (when missing),
# a virtual environment in .venv and the package itself (editable).
#   bash scripts/setup.sh          # runtime only
#   bash scripts/setup.sh dev      # + test tools and the optional torch back end
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"

need_debs=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_lib "libEGL.so.1" || need_debs+=(libegl1)
have_lib "libGL.so.1" || need_debs+=(libgl1)
have_lib "libOSMesa.so" || need_debs+=(libosmesa6)
[ -e /usr/lib/x86_64-linux-gnu/libEGL_mesa.so.0 ] || [ -e /usr/lib/aarch64-linux-gnu/libEGL_mesa.so.0 ] \
  || need_debs+=(libegl-mesa0 libgl1-mesa-dri)
# the RealSense driver (real extra, also used by the tests) loads libusb
have_lib "libusb-1.0.so.0" || need_debs+=(libusb-1.0-0)
if [ ${#need_debs[@]} -gt 0 ]; then
  echo "[setup] installing headless GL packages: ${need_debs[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_debs[@]}" >/dev/null
fi

# pip's output less its location warnings; pip's own exit status stands (pipefail)
quiet_pip() { grep -v '^WARNING: Location' || true; }

PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $PY"
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip 2>&1 | quiet_pip
spec="."
case "$extras" in
  dev) spec=".[dev,torch]" ;;
  "") spec="." ;;
  *) spec=".[$extras]" ;;
esac
echo "[setup] installing cablesim $spec"
# setuptools notes every editable install ("Editable installation. Please be careful with
# folders ... with the same name as your package"): advice, not a problem of this project
# with the versions the tests and pinned results were made with (scripts/constraints.txt)
PYTHONWARNINGS="ignore:Editable installation" \
  .venv/bin/python -m pip install -q -c scripts/constraints.txt -e "$spec" 2>&1 | quiet_pip
if [ "$extras" = "dev" ] && [ ! -x .cache/franka-sim-venv/bin/python ]; then
  # the franka-sim test server for the real-robot adapter needs mujoco 3.2 and numpy 1.26:
  # it gets an environment of its own (tests/robot/test_franky_panda.py looks for it here)
  echo "[setup] installing the franka-sim test server into .cache/franka-sim-venv"
  "$PY" -m venv .cache/franka-sim-venv
  .cache/franka-sim-venv/bin/python -m pip install -q -c scripts/constraints-franka-sim.txt \
    franka-sim==1.1.7 2>&1 | quiet_pip
fi
.venv/bin/python -c "import cablesim, mujoco; print('[setup] cablesim', cablesim.__version__, 'mujoco', mujoco.__version__, 'GL', cablesim.gl.select_backend())"
