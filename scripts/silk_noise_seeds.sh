#!/bin/bash
# Are the silk gonio fit's standard errors honest? (issue 22 item 13)
# Re-synthesise data_synthetic/silk/gonio.csv (configs/synth_silk.toml, same 3000 directions)
# with noise seeds 1..N, fit each with configs/fit_silk.toml, and compare the estimates with
# truth: z = (value - truth) / std_error per parameter, and sum z^2 over the 10 free
# parameters (about 10 when the errors are honest). Seed 5 is the shipped set's.
#   FIBREFIT=target/release/fibrefit scripts/silk_noise_seeds.sh 30 /tmp/silk_seeds
set -euo pipefail
N=${1:-30}
OUT=${2:-$(mktemp -d)}
BIN=${FIBREFIT:-fibrefit}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$OUT"
head=$(sed '/^\[capture\]/,$d' "$ROOT/configs/synth_silk.toml")
for s in $(seq 1 "$N"); do
  printf '%s\n[noise]\nrelative = 0.01\nseed = %s\n' "$head" "$s" > "$OUT/synth$s.toml"
  "$BIN" synth --config "$OUT/synth$s.toml" --out "$OUT/d$s" -q
  sed "s#../data_synthetic/silk/topology.png#d$s/topology.png#" "$ROOT/configs/fit_silk.toml" \
    > "$OUT/fit$s.toml"
  "$BIN" fit "$OUT/d$s/gonio.csv" --config "$OUT/fit$s.toml" --out "$OUT/r$s.json" -q 2>/dev/null
done
python3 - "$OUT" "$N" <<'EOF'
import json, math, statistics as st, sys
out, n = sys.argv[1], int(sys.argv[2])
truth = json.load(open(f"{out}/d1/truth.json"))
zs, sums = {}, []
for s in range(1, n + 1):
    p = json.load(open(f"{out}/r{s}.json"))["parameters"]
    tot = 0.0
    for k, e in p.items():
        if e["fixed"]:
            continue
        vals = e["value"] if isinstance(e["value"], list) else [e["value"]]
        errs = e["std_error"] if isinstance(e["std_error"], list) else [e["std_error"]]
        t = truth[k] if isinstance(truth[k], list) else [truth[k]] * len(vals)
        for c, (v, se, tv) in enumerate(zip(vals, errs, t)):
            name = k if len(vals) == 1 else f"{k}[{'rgb'[c]}]"
            z = (v - tv) / se
            zs.setdefault(name, []).append((z, v, se))
            tot += z * z
    sums.append(tot)
print(f"{n} noise seeds; parameter, mean z, sd z, sd(value) / median(std_error)")
for k, l in zs.items():
    z = [x[0] for x in l]
    print(f"  {k:<20} {st.mean(z):+6.2f} {st.stdev(z):5.2f} {st.stdev([x[1] for x in l]) / st.median([x[2] for x in l]):5.2f}")
print(f"sum z^2 per seed: mean {st.mean(sums):.1f} (honest: the number of free parameters), "
      f"median {st.median(sums):.1f}, max {max(sums):.1f} (seed {1 + sums.index(max(sums))})")
print("per seed:", " ".join(f"{x:.0f}" for x in sums))
EOF
