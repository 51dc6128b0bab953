#!/usr/bin/env bash
# Per-texel map recovery as a Slurm job array (README, "Per-texel maps past one machine").
#
#   scripts/slurm_maps.sh CAPTURE.toml CONFIG.toml OUT_DIR [TILES]
#
# 1. the global parameters, once:            fibrefit fit ... --map-globals --out OUT_DIR/globals.json
# 2. one array task per band of rows:        fibrefit fit ... --globals ... --tile $SLURM_ARRAY_TASK_ID/TILES
# 3. after the array, the merge:             fibrefit merge-maps OUT_DIR/tiles --globals ... --maps OUT_DIR/maps
# Each step is a job that depends on the previous one; nothing is written in place until each
# step succeeds. Not run by CI (CI runs the tiles as parallel local processes: tests/maps.rs).
set -euo pipefail
capture=$(realpath "$1"); config=$(realpath "$2"); out=$(realpath -m "$3"); tiles=${4:-16}
bin=${FIBREFIT:-$(command -v fibrefit || echo "$(dirname "$0")/../target/release/fibrefit")}
bin=$(realpath "$bin")
mkdir -p "$out/logs"
globals=$(sbatch --parsable --job-name=fibrefit-globals --output="$out/logs/globals.out" \
  --wrap "'$bin' fit '$capture' --config '$config' --map-globals --out '$out/globals.json' -q")
array=$(sbatch --parsable --job-name=fibrefit-tiles --dependency="afterok:$globals" \
  --array="0-$((tiles - 1))" --output="$out/logs/tile_%a.out" \
  --wrap "'$bin' fit '$capture' --config '$config' --globals '$out/globals.json' --tile \$SLURM_ARRAY_TASK_ID/$tiles --maps '$out/tiles' -q")
merge=$(sbatch --parsable --job-name=fibrefit-merge --dependency="afterok:$array" \
  --output="$out/logs/merge.out" \
  --wrap "'$bin' merge-maps '$out/tiles' --globals '$out/globals.json' --maps '$out/maps' --out '$out/result.json'")
echo "submitted: globals $globals, tiles $array (0-$((tiles - 1))), merge $merge"
