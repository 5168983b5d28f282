#!/usr/bin/env bash
# The refactoring check of issue 34: run the sample session (with compensation), fit the
# four sample datasets and diagnose one, then print a SHA-256 per output file. Two commits
# whose digests match wrote byte-identical outputs.
#   bash scripts/output_digest.sh [OUT_DIR]  > digest.txt
# Uses ./.venv (run scripts/demo.sh or the README's install first). Takes about 2 minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/i2ris-digest}   # the same folder each time: outputs record their paths
rm -rf "$OUT" && mkdir -p "$OUT"
CLI=".venv/bin/i2ris-calib"
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1
$CLI run sample_data/session --out "$OUT/run" --config configs/compensate.example.toml >/dev/null
$CLI fit sample_data/datasets/yaw_pos.csv sample_data/datasets/yaw_neg.csv --axis yaw --out "$OUT/fit_yaw" >/dev/null
$CLI fit sample_data/datasets/pitch_pos.csv sample_data/datasets/pitch_neg.csv --axis pitch --out "$OUT/fit_pitch" >/dev/null
$CLI compensate "$OUT/fit_yaw/fit.json" --dataset yaw+ --target sample_data/session/target.csv --out "$OUT/compensate/commands.csv" >/dev/null
$CLI diagnose sample_data/datasets/yaw_pos.csv --axis yaw --out "$OUT/diagnose_yaw" >/dev/null
# JSON is hashed without its run-time figures (seconds, frames per second), which vary.
.venv/bin/python - "$OUT" <<'PY'
import hashlib, json, pathlib, sys
VOLATILE = {"seconds", "cpu_seconds", "frames_per_s", "frames_per_cpu_s", "elapsed_s", "wall_s", "cpu_s"}
def strip(x):
    if isinstance(x, dict):
        return {k: strip(v) for k, v in x.items() if k not in VOLATILE}
    if isinstance(x, list):
        return [strip(v) for v in x]
    return x
root = pathlib.Path(sys.argv[1])
for f in sorted(p for p in root.rglob("*") if p.is_file() and not p.name.endswith(".lock")):
    data = f.read_bytes()
    if f.suffix == ".json":
        data = json.dumps(strip(json.loads(data)), sort_keys=True).encode()
    print(hashlib.sha256(data).hexdigest(), f.relative_to(root))
PY
