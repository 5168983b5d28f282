#!/usr/bin/env bash
# Install i2ris-calib into ./.venv, run the whole pipeline on the shipped sample session
# (video in, report out). Output: runs/sample/<session>/report/report.html
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -c constraints.txt -e .
.venv/bin/i2ris-calib run sample_data/session --out runs/sample "$@"
