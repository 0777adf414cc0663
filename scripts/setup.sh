#!/usr/bin/env bash
# One idempotent setup step for a fresh CPU machine (run by `make setup`, and so by both README
# commands). Rerunning it when everything is in place takes seconds.
#   1. a Vulkan driver SAPIEN supports (Mesa >= 23 lavapipe from Debian bookworm-backports)
#   2. .venv at the repository root
#   3. torch==2.13.0 first, so that nothing pulls a CUDA build
#   4. this project, editable, with its test extra
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
STAMP="$VENV/.ms_construction_setup"

log() { printf '[setup] %s\n' "$*"; }

# --- 1. Vulkan -------------------------------------------------------------------------------
mesa_major() {
  # Version of the installed lavapipe/Mesa Vulkan driver, major number only (0 if absent).
  local v
  v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)
  [ -n "$v" ] && echo "${v%%.*}" | sed 's/^[0-9]*://' || echo 0
}

backports_commands() {
  # The mirror URI is taken from the machine's own Debian sources file, never written here.
  cat <<'CMDS'
src=/etc/apt/sources.list.d/debian.sources; [ -f "$src" ] || src=/etc/apt/sources.list
uri=$(grep -m1 -oE '^URIs:[[:space:]]*[^[:space:]]+' "$src" | awk '{print $2}')
[ -n "$uri" ] || uri=$(grep -m1 -E '^deb[[:space:]]' "$src" | awk '{print $2}')
printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' "$uri" > /etc/apt/sources.list.d/bookworm-backports.sources
apt-get update
DEBIAN_FRONTEND=noninteractive apt-get install -y -t bookworm-backports mesa-vulkan-drivers libvulkan1
CMDS
}

if [ "$(uname -s)" = Linux ] && command -v dpkg-query >/dev/null 2>&1; then
  if [ "$(mesa_major)" -lt 23 ] && ! ls /usr/share/vulkan/icd.d/nvidia*.json >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ]; then
      log "installing Mesa >= 23 Vulkan drivers from bookworm-backports (Mesa $(mesa_major) found)"
      bash -c "$(backports_commands)"
    else
      log "SAPIEN needs a Vulkan driver; Mesa $(mesa_major) is too old (need 23+). As root, run:"
      backports_commands | sed 's/^/    /'
      exit 1
    fi
  fi
fi

# --- 2.-4. Python environment ----------------------------------------------------------------
HASH=$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -c1-16)
if [ -x "$VENV/bin/python" ] && [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$HASH" ]; then
  log "environment up to date ($VENV)"
  exit 0
fi
[ -x "$VENV/bin/python" ] || { log "creating $VENV with $PY"; "$PY" -m venv "$VENV"; }
pip_install() {
  # the machine's pip config lists local indexes that may be absent; their warnings are noise
  "$VENV/bin/python" -m pip install --disable-pip-version-check -q "$@" 2> >(grep -v 'is ignored: it is neither' >&2)
}
log "installing torch==2.13.0 (CPU) before anything that depends on torch"
pip_install "torch==2.13.0"
log "installing ms_construction (editable, with tests)"
pip_install -e ".[test]"
echo "$HASH" > "$STAMP"
log "done: activate with 'source .venv/bin/activate'"
