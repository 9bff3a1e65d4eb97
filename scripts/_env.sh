# Sourced by the scripts: make (once) and activate the project's virtual environment.
# GISNOISE_VENV overrides its place (default: .venv in the repository).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${GISNOISE_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
    echo "gisnoise: creating the environment in $VENV" >&2
    "$PY" -m venv "$VENV"
fi
# shellcheck disable=SC1091
. "$VENV/bin/activate"
stamp="$VENV/.gisnoise-installed-$1"
if [ ! -f "$stamp" ] || [ "$ROOT/pyproject.toml" -nt "$stamp" ]; then
    echo "gisnoise: installing gisnoise[$1] (first run only)" >&2
    python -m pip install -q --upgrade pip >&2
    python -m pip install -q -e "$ROOT[$1]" >&2
    if python -c "import numba" 2>/dev/null; then
        echo "gisnoise: compiling the fast kernels (once; numba caches them)" >&2
        python -c "from gisnoise.maps import warm_up; warm_up()" >&2
    fi
    touch "$stamp"
fi
cd "$ROOT"
