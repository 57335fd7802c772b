#!/usr/bin/env bash
# Idempotent installer of synthdet's CPU stack into ./.venv (see README "Set-up").
#
# Each step is skipped when its stamp (a hash of the step's recipe) is current, so a warm
# run only verifies the imports. Native builds use MAX_JOBS=2 and CFLAGS=-g0; pip's wheel
# cache makes a rebuild on a machine that built once take seconds.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=${SYNTHDET_VENV:-$ROOT/.venv}
PY=$VENV/bin/python
STAMPS=$VENV/.synthdet-stamps
REQ=$ROOT/requirements
# libopenblas-dev: MinkowskiEngine's build; libusb-1.0-0: open3d's import; freecad: freecadcmd
# and its GUI; xvfb: the GUI on a virtual display (screenshots, the GUI tests).
APT_PACKAGES=(libopenblas-dev libusb-1.0-0 freecad xvfb)
PIP_QUIET=(--disable-pip-version-check --progress-bar off -q)
export MAX_JOBS=${MAX_JOBS:-2} CFLAGS=${CFLAGS:--g0}

log() { printf '[setup %s] %s\n' "$(date +%H:%M:%S)" "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

# step NAME RECIPE-FILES... -- COMMAND...: run COMMAND unless the stamp for NAME matches.
step() {
  local name=$1; shift
  local files=()
  while [ "$1" != "--" ]; do files+=("$1"); shift; done
  shift
  local digest
  digest=$( { printf '%s\n' "$*"; cat "${files[@]}" 2>/dev/null; } | sha256sum | cut -c1-16)
  if [ -f "$STAMPS/$name" ] && [ "$(cat "$STAMPS/$name")" = "$digest" ]; then
    log "$name: up to date"
    return
  fi
  log "$name: installing ..."
  local start=$SECONDS
  "$@"
  mkdir -p "$STAMPS"
  echo "$digest" > "$STAMPS/$name"
  log "$name: done in $((SECONDS - start)) s"
}

apt_missing() {
  local missing=()
  local package
  for package in libopenblas-dev libusb-1.0-0 xvfb; do
    dpkg -s "$package" >/dev/null 2>&1 || missing+=("$package")
  done
  command -v freecadcmd >/dev/null 2>&1 || missing+=(freecad)
  echo "${missing[@]}"
}

install_apt() {
  local missing
  missing=$(apt_missing)
  [ -z "$missing" ] && { log "apt: $(echo "${APT_PACKAGES[@]}") present"; return; }
  if [ "$(id -u)" != 0 ]; then
    die "system packages missing: $missing. Run as root:
    apt-get update && apt-get install -y --no-install-recommends $missing
then run 'make setup' again."
  fi
  log "apt: installing $missing ..."
  local start=$SECONDS
  DEBIAN_FRONTEND=noninteractive apt-get update -qq
  # shellcheck disable=SC2086
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing >/dev/null
  log "apt: done in $((SECONDS - start)) s"
}

# The machine's pip config lists local indexes that may not exist; drop pip's warnings about them.
pip_install() {
  "$PY" -m pip install "${PIP_QUIET[@]}" "$@" 2>&1 | { grep -v 'is neither a file nor a directory' || true; }
}

install_mmcv() {
  MMCV_WITH_OPS=1 FORCE_CUDA=0 pip_install --no-build-isolation -r "$REQ/mmcv.txt"
}

install_minkowski() {
  SETUPTOOLS_USE_DISTUTILS=stdlib pip_install --no-build-isolation -r "$REQ/minkowski.txt"
  patch_minkowski
}

# MinkowskiEngine 0.5.4 imports Sequence from `collections`, removed in Python 3.10.
# pip's cached wheel is unpatched, so this runs after every (re)install.
patch_minkowski() {
  local pkg
  pkg=$("$PY" -c "import importlib.util, os; print(os.path.dirname(importlib.util.find_spec('MinkowskiEngine').origin))")
  local f
  for f in MinkowskiCommon.py MinkowskiCoordinateManager.py MinkowskiKernelGenerator.py \
           MinkowskiTensorField.py utils/quantization.py; do
    sed -i -e 's/^from collections import Sequence, namedtuple$/from collections import namedtuple\nfrom collections.abc import Sequence/' \
           -e 's/^from collections import Sequence$/from collections.abc import Sequence/' "$pkg/$f"
  done
  if grep -rq '^from collections import .*Sequence' "$pkg"; then
    die "MinkowskiEngine in $pkg still imports collections.Sequence after patching"
  fi
}

verify() {
  log "verify: importing the stack ..."
  "$PY" - <<'EOF'
import bpy  # noqa: F401  (before open3d: both ship libtbb and the first one wins)
import embreex, open3d, torch, mmcv, mmcv.ops, mmengine, mmdet, mmdet3d  # noqa: F401,E401
import MinkowskiEngine as ME
print(f"  torch {torch.__version__}, mmcv {mmcv.__version__}, mmdet3d {mmdet3d.__version__}, "
      f"MinkowskiEngine {ME.__version__}, bpy {bpy.app.version_string}, open3d {open3d.__version__}")
EOF
  # the editable install is a .pth line naming the clone: its packages import from any folder
  (cd / && "$PY" - <<'EOF'
import importlib.util
import sys
names = ('generator', 'configurator', 'projects', 'tools', 'tests')
sys.exit(' '.join(name for name in names if importlib.util.find_spec(name) is None) or None)
EOF
  ) || die "the clone's packages above do not import outside $ROOT; run 'make setup' again"
  command -v freecadcmd >/dev/null || die "freecadcmd is not on PATH"
  log "verify: freecadcmd at $(command -v freecadcmd)"
}

main() {
  local total=$SECONDS
  install_apt
  if [ ! -x "$PY" ]; then
    log "venv: creating $VENV"
    python3 -m venv "$VENV"
  fi
  step build "$REQ/build.txt" -- pip_install -r "$REQ/build.txt"
  step torch "$REQ/torch.txt" -- pip_install -r "$REQ/torch.txt"
  step base "$REQ/base.txt" -- pip_install -r "$REQ/base.txt"
  step runtime "$REQ/runtime.txt" -- pip_install -r "$REQ/runtime.txt"
  step tools "$REQ/tools.txt" -- pip_install -r "$REQ/tools.txt"
  step openmmlab "$REQ/openmmlab.txt" -- pip_install --no-deps -r "$REQ/openmmlab.txt"
  step minkowski "$REQ/minkowski.txt" -- install_minkowski
  step mmcv "$REQ/mmcv.txt" -- install_mmcv
  step synthdet "$ROOT/setup.cfg" -- pip_install --no-deps --no-build-isolation -e "$ROOT"
  verify
  log "set-up complete in $((SECONDS - total)) s"
}

main "$@"
