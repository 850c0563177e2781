# Blender as a Python module (PyPI's bpy 5.0.x, Python 3.11 only) in its own virtual
# environment, for tests/test_glb_blender.py. Source it:  . scripts/ci_blender.sh
# On success SINMDM_BPY_PYTHON names its python; on any failure it prints one line
# and the Blender tests skip, saying why. Safe under `set -euo pipefail`: nothing
# here exits or fails the caller. SINMDM_BPY_VENV: where the venv goes
# (default ${TMPDIR:-/tmp}/sinmdm-bpy, about 1 GB).
sinmdm_ci_blender() {
  local venv="${SINMDM_BPY_VENV:-${TMPDIR:-/tmp}/sinmdm-bpy}" python="" candidate start log
  for candidate in python3.11 python3; do
    if command -v "$candidate" >/dev/null 2>&1 \
      && "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
      python="$candidate"
      break
    fi
  done
  if [ -z "$python" ]; then
    echo "ci_blender: no Python 3.11 (bpy 5.0 needs it); Blender GLB tests will skip"
    return 0
  fi
  start=$(date +%s)
  log="$(mktemp "${TMPDIR:-/tmp}/sinmdm-bpy-install.XXXXXX")" || log=/dev/null
  if { [ -x "$venv/bin/python" ] || "$python" -m venv "$venv"; } >"$log" 2>&1 \
    && "$venv/bin/python" -m pip install -q 'bpy==5.0.*' >>"$log" 2>&1 \
    && "$venv/bin/python" -c 'import bpy' >>"$log" 2>&1; then
    export SINMDM_BPY_PYTHON="$venv/bin/python"
    echo "ci_blender: bpy ready in $(( $(date +%s) - start )) s at $venv"
  else
    echo "ci_blender: installing bpy failed ($(tail -n 1 "$log" 2>/dev/null)); Blender GLB tests will skip"
  fi
  [ "$log" = /dev/null ] || rm -f "$log"
  return 0
}
sinmdm_ci_blender
unset -f sinmdm_ci_blender
