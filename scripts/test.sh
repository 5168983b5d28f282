#!/usr/bin/env bash
# Install everything the tests need into ./.venv (fresh machine OK), then run them.
# Usage: bash scripts/test.sh [pytest args...]   e.g. bash scripts/test.sh -m slow
#        PYTEST_WORKERS=0 bash scripts/test.sh    (one process, e.g. to debug)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if ! command -v chromium >/dev/null 2>&1 && [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  echo "== installing Debian chromium (report rendering test)"
  apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null \
    || echo "warning: could not install chromium; the browser test will fail" >&2
fi
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -c constraints.txt -e '.[test]'
.venv/bin/ruff check src tests benchmarks
# One pytest worker per core (pytest-xdist), whole files per worker so module fixtures are
# built once; one numba/BLAS thread per worker so the workers do not oversubscribe the cores.
export NUMBA_NUM_THREADS=${NUMBA_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
exec .venv/bin/python -m pytest -n "${PYTEST_WORKERS:-auto}" --dist loadfile "$@"
