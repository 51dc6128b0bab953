#!/usr/bin/env bash
# Check the Slurm job array of map tiles for real (after scripts/slurm_single_node.sh): render a
# 32 x 32 synthetic capture, recover its maps once in a single run and once as globals + a job
# array of N tiles + merge (scripts/slurm_maps.sh), and compare the maps byte for byte.
#
#   scripts/slurm_maps_check.sh [N] [WORK_DIR]
set -euo pipefail
n=${1:-4}
work=$(realpath -m "${2:-/tmp/fibrefit-slurm-check}")
root=$(cd "$(dirname "$0")/.." && pwd)
bin="$root/target/release/fibrefit"
[ -x "$bin" ] || (cd "$root" && cargo build --release)
rm -rf "$work" && mkdir -p "$work"
sed -e 's/width = 24/width = 32/; s/height = 24/height = 32/' "$root/scripts/maps_check_synth.toml" > "$work/synth.toml"
"$bin" synth --config "$work/synth.toml" --out "$work/d" -q
grep -v '^tangent_map\|^topology_map' "$work/d/capture.toml" > "$work/d/blind.toml"
cp "$root/scripts/maps_check_fit.toml" "$work/fit.toml"
"$bin" fit "$work/d/blind.toml" --config "$work/fit.toml" --out "$work/single.json" --maps "$work/single" -q 2>/dev/null
FIBREFIT="$bin" "$root/scripts/slurm_maps.sh" "$work/d/blind.toml" "$work/fit.toml" "$work/slurm" "$n"
while squeue -h -n fibrefit-globals,fibrefit-tiles,fibrefit-merge | grep -q .; do sleep 2; done
sacct >/dev/null 2>&1 || true
for f in height fibre_azimuth height_std_error fibre_azimuth_std_error residual; do
  cmp "$work/single/$f.exr" "$work/slurm/maps/$f.exr"
  echo "$f.exr: identical"
done
echo "the Slurm job array ($n tiles) reproduces the single run bit for bit"
