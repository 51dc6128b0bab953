#!/usr/bin/env python3
"""CUReT BRDF samples (../shared/data/curet: table.txt and abrdf_subset.dat, see its README) as
goniometric CSVs fibrefit reads: one file per sample, OUT/curet_N.csv, angles in degrees, the
light (theta_i, phi_i) and the camera (theta_o, phi_o), unmeasured values (0) left out.

    python3 scripts/curet_to_csv.py ../shared/data/curet OUT
"""
import math
import pathlib
import sys

src, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
out.mkdir(parents=True, exist_ok=True)
# index theta_v phi_v theta_i phi_i, radians
table = [line.split() for line in open(src / "table.txt") if line.strip()]
for line in open(src / "abrdf_subset.dat"):
    fields = line.split()
    if not fields:
        continue
    number, values = int(fields[0]), [float(x) for x in fields[1:]]
    assert len(values) == len(table), (len(values), len(table))
    with open(out / f"curet_{number}.csv", "w") as f:
        f.write("theta_i,phi_i,theta_o,phi_o,brdf\n")
        for row, value in zip(table, values):
            if value <= 0:
                continue
            tv, pv, ti, pi = (math.degrees(float(x)) for x in row[1:5])
            f.write(f"{ti:.6f},{pi:.6f},{tv:.6f},{pv:.6f},{value}\n")
