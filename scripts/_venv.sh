# Sourced by scripts/demo and scripts/test: create or reuse ./.venv and install the project into it.
# Re-installs only when pyproject.toml changed since the last install (stamp file).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
py="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "[taskflight] creating virtual environment in .venv" >&2
  "$py" -m venv .venv
fi
stamp=.venv/.taskflight-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "[taskflight] installing dependencies (first run takes about a minute)" >&2
  .venv/bin/python -m pip install -q --upgrade pip >&2
  .venv/bin/python -m pip install -q -e ".[dev]" >&2
  echo "$want" > "$stamp"
fi
export PATH="$root/.venv/bin:$PATH"
