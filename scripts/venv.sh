#!/usr/bin/env bash
# Create or reuse the project's virtual environment and install flexure_sim into it.
# Usage: source scripts/venv.sh   (sets VENV, PATH, AMENT_PREFIX_PATH)
# FLEXURE_VENV overrides the location (default: <repo>/.venv).
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${FLEXURE_VENV:-$REPO/.venv}"
PY="${PYTHON:-python3}"
stamp="$VENV/.flexure_requirements.sha"
want="$(sha256sum "$REPO/requirements.txt" | cut -d' ' -f1)"
if [ ! -x "$VENV/bin/python" ]; then
  echo "[venv] creating $VENV" >&2
  "$PY" -m venv "$VENV"
fi
if [ "$(cat "$stamp" 2>/dev/null || true)" != "$want" ]; then
  echo "[venv] installing requirements into $VENV" >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
  "$VENV/bin/python" -m pip install --quiet -r "$REPO/requirements.txt" >&2
  echo "$want" > "$stamp"
fi
# Install the package itself (not editable: data_files put the ros2-run launcher under
# <prefix>/lib/flexure_sim and the package marker in the ament index).
echo "[venv] installing flexure_sim from $REPO" >&2
"$VENV/bin/python" -m pip install --quiet --no-deps --force-reinstall "$REPO" >&2
export VENV
export PATH="$VENV/bin:$PATH"
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
set +euo pipefail
