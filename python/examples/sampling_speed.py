"""`Material.sample` on arrays, exact against one instance per row (issue 41 item 2).

    python3 python/examples/sampling_speed.py [--rows 1000000] [--runs 3]

Loads the synthetic silk's truth (varying-topology: its height histogram, 16 heights) and a
poulin-fournier material with an isotropic fibre-direction spread (16 fibre directions) and a
fuzz layer (the felt's kind of fit), then draws `--rows` samples at random views (theta_v up to
87 deg) with `m.sample(v, u)` and with `m.sample(v, u, instance=r)`, and prints the median of
`--runs` of each in samples per second (all cores). Run from the repository root.
"""

import argparse
import os
import tempfile
import time

import numpy as np

import fibrefit

FELT = """model = "poulin-fournier"
kd = 0.3
ks = 0.6
exponent = 100
spacing = 2.6
azimuth_spread_deg = 180
fuzz = 0.5
fuzz_depth = 0.3
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    n = args.rows
    z = 0.05 + 0.95 * rng.random(n)
    r, phi = np.sqrt(1 - z * z), 2 * np.pi * rng.random(n)
    v = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    u, pick = rng.random((n, 2)), rng.random(n)
    with tempfile.TemporaryDirectory() as d:
        felt = os.path.join(d, "felt.toml")
        with open(felt, "w") as f:
            f.write(FELT)
        for name, path in [
            ("silk truth (varying-topology)", "data_synthetic/silk/truth.json"),
            ("poulin-fournier + spread 180 + fuzz", felt),
        ]:
            m = fibrefit.load(path)
            for label, kw in [("exact", {}), ("one instance per row", {"instance": pick})]:
                times = []
                for _ in range(args.runs):
                    t = time.perf_counter()
                    m.sample(v, u, **kw)
                    times.append(time.perf_counter() - t)
                print(
                    f"{name} ({m.instances} instances), {label}: "
                    f"{n / sorted(times)[len(times) // 2] / 1e6:.2f} M samples/s (median of {args.runs})"
                )


if __name__ == "__main__":
    main()
