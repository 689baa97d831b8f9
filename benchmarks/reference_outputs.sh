#!/usr/bin/env bash
# The result folder that benchmarks/compare_outputs.py compares: the demo, the quick plant and row
# experiments, one quick greenhouse pair and every notebook in reader's mode, each with fresh caches
# under the folder, so a refactor can be checked bit for bit:
#   git worktree add ../before <rev>; (cd ../before && benchmarks/reference_outputs.sh /tmp/before)
#   benchmarks/reference_outputs.sh /tmp/after; python benchmarks/compare_outputs.py /tmp/before /tmp/after
set -euo pipefail
out=$(realpath -m "${1:?usage: reference_outputs.sh OUTPUT_FOLDER}")
python=${PYTHON:-$(dirname "$0")/../.venv/bin/python}
[ -x "$python" ] || python=python3
cd "$(dirname "$0")/.."
export PYTHONPATH=$PWD TPVP_CACHE_DIR=$out/cache/oracles TPVP_EXPERIMENT_CACHE=$out/cache/notebooks \
       TPVP_NOTEBOOK_RESULTS=$out/none
mkdir -p "$out"
run() { echo "== $*"; /usr/bin/time -f "   %e s" "$python" -m tpvp "$@"; }
run demo --output "$out/demo"
run plan --previous tpvp/data/pheno4d/tomato_0305.xyz.gz --current tpvp/data/pheno4d/tomato_0306.xyz.gz --output "$out/plan"
run experiments plants --quick --workers 2 --no-comparison --output "$out/plants" --cache "$out/cache/plants"
run experiments rows --quick --workers 2 --output "$out/rows" --cache "$out/cache/rows"
run greenhouse --quick --output "$out/greenhouse" --cache "$out/cache/oracles"
echo "== notebooks (reader's mode)"
/usr/bin/time -f "   %e s" "$python" -m tools.notebooks --output "$out/notebooks"
