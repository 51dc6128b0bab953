#!/usr/bin/env bash
# Many swatches as a Slurm job array, one swatch per task (docs/guide/batch.md).
#
#   scripts/slurm_fit_many.sh LIST OUT_DIR [FIT OPTIONS...]
#
# LIST: a text file naming one data file per line (`ls swatches/*.csv > list.txt`; blank lines
# are ignored; relative paths are read from the directory you submit from). Task k fits the
# k-th file (from 0) with
#     fibrefit fit FILE --out-dir OUT_DIR --skip-done --threads $SLURM_CPUS_PER_TASK [FIT OPTIONS]
# into OUT_DIR/NAME/ (result.json, report.md, figures) and adds its row to OUT_DIR/summary.csv
# (under a lock: the tasks finish in any order). A resubmitted or requeued array skips the
# swatches already done. FIT OPTIONS default to `--model auto`. Environment: FIBREFIT (the
# binary), FIBREFIT_CPUS (cores per task, default 2), FIBREFIT_SBATCH (more sbatch options,
# e.g. "--partition=short --time=00:30:00"). The batch script is kept as OUT_DIR/fit_array.sbatch.
set -euo pipefail
[ $# -ge 2 ] || { sed -n '2,15p' "$0" >&2; exit 2; }
list=$(realpath "$1"); out=$(realpath -m "$2"); shift 2
opts=("$@"); [ ${#opts[@]} -gt 0 ] || opts=(--model auto)
n=$(grep -cv '^[[:space:]]*$' "$list" || true)
[ "$n" -gt 0 ] || { echo "$list: names no data file" >&2; exit 2; }
while IFS= read -r f; do
  [ -z "${f//[[:space:]]/}" ] || [ -f "$f" ] || { echo "$list: $f: no such file" >&2; exit 2; }
done < "$list"
bin=${FIBREFIT:-$(command -v fibrefit || echo "$(dirname "$0")/../target/release/fibrefit")}
bin=$(realpath "$bin")
cpus=${FIBREFIT_CPUS:-2}
mkdir -p "$out/logs"
script="$out/fit_array.sbatch"
cat > "$script" <<SBATCH
#!/usr/bin/env bash
#SBATCH --job-name=fibrefit-fit
#SBATCH --array=0-$((n - 1))
#SBATCH --cpus-per-task=$cpus
#SBATCH --output=$out/logs/fit_%a.out
set -euo pipefail
file=\$(grep -v '^[[:space:]]*\$' $(printf %q "$list") | sed -n "\$((SLURM_ARRAY_TASK_ID + 1))p")
exec $(printf %q "$bin") fit "\$file" --out-dir $(printf %q "$out") --skip-done --threads "\${SLURM_CPUS_PER_TASK:-1}" $(printf '%q ' "${opts[@]}")
SBATCH
# shellcheck disable=SC2086
job=$(sbatch --parsable ${FIBREFIT_SBATCH:-} "$script")
echo "submitted: job array $job (tasks 0-$((n - 1))): $n swatches into $out; summary: $out/summary.csv; logs: $out/logs/"
