"""The fibrefit Mitsuba plugin's speed and memory against Mitsuba's own BSDFs (issue 41 item 3).

    python3 python/examples/mitsuba_speed.py [--runs 5] [--out reports] [--synthetic-size 128] [--synthetic-spp 4]

Fits the RGL acrylic felt (tests/data/rgl/acrylic_felt_green_rgb.bsdf) with `--model auto`,
then renders one scene (a sphere under a constant environment and a directional light,
perspective camera, path tracer with max depth 3, independent sampler, variant llvm_ad_rgb) at
256 x 256 with 16 spp and at 512 x 512 with 64 spp, with four BSDFs side by side:
the plugin's fast mode, the plugin's exact mode, Mitsuba's `measured` BSDF on the felt file
the fit came from, and `roughconductor` (GGX, alpha 0.1). Each BSDF and size runs in its own
process (so the peak RSS is its own): load the scene, one render to compile, then the median of
`--runs` renders (each `mi.render` forced to finish). The exact mode runs with Dr.Jit's
symbolic loops and calls off (it converts arrays to numpy); the others with Mitsuba's defaults.

Then the shipped synthetic goniometric tables, fitted with the rungs their captures were made
with (data_synthetic/brushed/gonio.csv with poulin-fournier, data_synthetic/silk/gonio.csv with
varying-topology: the cross-section rungs), in the same scene at a smaller size
(`--synthetic-size`, `--synthetic-spp`; the silk's model evaluates 16 height nodes x 2 fibres
of arcs per value, times its spread's nodes: 16 while its fit kept a spread of 0.12 deg, one since
the fit holds a spread the data cannot tell from 0 at 0), fast against exact; there is no measured file for
synthetic data, so the felt's fast mode and `measured` are rendered at that size too, as the
yardstick.

Writes the section between the `mitsuba_speed` markers of OUT/mitsuba.md (the rest of that file
is capture_side_by_side.py's) and OUT/mitsuba_speed.csv.
"""

import argparse
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
FELT = ROOT / "tests/data/rgl/acrylic_felt_green_rgb.bsdf"
#: the synthetic fits: name -> (goniometric table, rung)
SYNTHETIC = {
    "brushed": (ROOT / "data_synthetic/brushed/gonio.csv", "poulin-fournier"),
    "silk": (ROOT / "data_synthetic/silk/gonio.csv", "varying-topology"),
}
#: the synthetic table's rows: (fit, kind)
SYNTHETIC_ROWS = [("felt", "fast"), ("felt", "measured"), ("brushed", "fast"), ("brushed", "exact"), ("silk", "fast"), ("silk", "exact")]
BEGIN, END = "<!-- mitsuba_speed: begin -->", "<!-- mitsuba_speed: end -->"
KINDS = ["fast", "measured", "roughconductor", "fast-evaluated", "measured-evaluated", "exact"]
LABELS = {
    "fast": "fibrefit fast (`register()`)",
    "measured": "measured",
    "roughconductor": "roughconductor",
    "fast-evaluated": "fibrefit fast, symbolic off (`register(exact_flags=True)`)",
    "measured-evaluated": "measured, symbolic off",
    "exact": "fibrefit exact (`register(exact_flags=True)`)",
}


def scene_dict(mi, bsdf, size, spp):
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {
            "type": "perspective",
            "fov": 30,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 3], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 0.5}},
        "sun": {"type": "directional", "direction": [-0.3, 0.5, -0.8], "irradiance": {"type": "rgb", "value": 3.0}},
    }


def child(kind, fit, size, spp, runs):
    """One BSDF at one size in this process: prints a JSON line."""
    import resource

    import drjit as dr
    import fibrefit.mitsuba as fm
    import mitsuba as mi
    import numpy as np

    mi.set_variant("llvm_ad_rgb")
    # Mitsuba's defaults (symbolic loops and calls on: what `register()` keeps), or those
    # switched off as the exact mode needs (`register(exact_flags=True)`)
    fm.register(exact_flags=kind in ("fast-evaluated", "exact", "measured-evaluated"))
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    bsdf = {
        "fast": {"type": "fibrefit", "filename": fit, "mode": "fast"},
        "fast-evaluated": {"type": "fibrefit", "filename": fit, "mode": "fast"},
        "measured-evaluated": {"type": "measured", "filename": str(FELT)},
        "exact": {"type": "fibrefit", "filename": fit, "mode": "exact"},
        "measured": {"type": "measured", "filename": str(FELT)},
        "roughconductor": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1},
    }[kind]
    t0 = time.perf_counter()
    scene = mi.load_dict(scene_dict(mi, bsdf, size, spp))
    load_s = time.perf_counter() - t0
    extra = {}
    if kind in ("fast", "fast-evaluated", "exact"):
        b = scene.shapes()[0].bsdf()  # the plugin's Python object
        extra = {"table_bytes": b.table_bytes, "mode": b.mode, "check": b.fast_check}
        if b.mode == "fast":
            extra["table_res"] = list(b.table_res)
    t0 = time.perf_counter()
    img = mi.render(scene, seed=0)
    dr.eval(img)
    first_s = time.perf_counter() - t0
    times = []
    for k in range(runs):
        t0 = time.perf_counter()
        img = mi.render(scene, seed=k + 1)
        dr.eval(img)
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    a = np.array(img, dtype=np.float64)[..., :3]
    out = {
        "kind": kind,
        "size": size,
        "spp": spp,
        "times": times,
        "median_s": float(np.median(times)),
        "first_s": first_s,
        "load_s": load_s,
        "rss_base": rss0,
        "rss_peak": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "mean_rgb": a.mean(axis=(0, 1)).tolist(),
        **extra,
    }
    print("RESULT " + json.dumps(out), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="timed renders per BSDF and size [5; 3 for the exact mode at the larger size]")
    ap.add_argument("--out", default=str(ROOT / "reports"))
    ap.add_argument("--synthetic-size", type=int, default=128, help="image size of the synthetic fits' renders [128]")
    ap.add_argument("--synthetic-spp", type=int, default=4, help="samples per pixel of the synthetic fits' renders [4]")
    ap.add_argument("--child", nargs=5, metavar=("KIND", "FIT", "SIZE", "SPP", "RUNS"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        kind, fit, size, spp, runs = a.child
        child(kind, fit, int(size), int(spp), int(runs))
        return

    import fibrefit

    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    work = pathlib.Path(tempfile.mkdtemp(prefix="fibrefit_mitsuba_speed_"))
    print(f"fitting {FELT.name} with --model auto ...", file=sys.stderr)
    t0 = time.perf_counter()
    r = fibrefit.fit(FELT, model="auto")
    fit_s = time.perf_counter() - t0
    fit = work / "felt.json"
    r.to_json(fit)
    rows = []
    for size, spp in [(256, 16), (512, 64)]:
        for kind in KINDS:
            runs = 3 if (kind == "exact" and size > 256) else a.runs
            print(f"{kind} {size} x {size}, {spp} spp ...", file=sys.stderr)
            rows.append(run_child(kind, fit, size, spp, runs))
    fits = {"felt": str(fit)}
    models = {}
    for name, (data, model) in SYNTHETIC.items():
        print(f"fitting {data.relative_to(ROOT)} with --model {model} ...", file=sys.stderr)
        t0 = time.perf_counter()
        rs = fibrefit.fit(data, model=model)
        models[name] = (rs.model, time.perf_counter() - t0)
        fits[name] = str(work / f"{name}.json")
        rs.to_json(fits[name])
        from fibrefit import _drjit_model

        p = _drjit_model.parse_wgsl(fibrefit.export(fits[name], shader="wgsl").shader)
        models[name] += ({"heights": len(p["heights"]), "spread": len(p["spread"]), "exponent": float(p["shape"][0]),
                          "order": len(p["gauss_legendre"])},)
    size, spp = a.synthetic_size, a.synthetic_spp
    synthetic = []
    for name, kind in SYNTHETIC_ROWS:
        runs = 3
        print(f"{name} {kind} {size} x {size}, {spp} spp ...", file=sys.stderr)
        synthetic.append(dict(run_child(kind, fits[name], size, spp, runs), fit=name))
    write(out, rows, r, fit_s, synthetic, models)


def run_child(kind, fit, size, spp, runs):
    p = subprocess.run(
        [sys.executable, __file__, "--child", kind, str(fit), str(size), str(spp), str(runs)],
        capture_output=True,
        text=True,
        env=dict(os.environ, PYTHONWARNINGS="ignore"),
    )
    line = [x for x in p.stdout.splitlines() if x.startswith("RESULT ")]
    if p.returncode != 0 or not line:
        sys.stderr.write(p.stderr)
        raise SystemExit(f"{kind} ({fit}) at {size}: failed")
    return json.loads(line[0][7:])


def correction_text(r):
    """The fit's smooth correction in words (empty without one)."""
    c = r.correction
    if c is None:
        return ""
    return (
        f", and the smooth correction kept on it: degree {c['degree']}, held-out log error "
        f"{c['heldout_error']:.4f} against the rung's {c['rung_heldout_error']:.4f}; the fast path evaluates it"
    )


def write(out, rows, r, fit_s, synthetic, models):
    import numpy as np

    by = {(x["kind"], x["size"]): x for x in rows}
    with open(out / "mitsuba_speed.csv", "w") as f:
        f.write("bsdf,width,spp,median_s,runs,first_render_s,load_s,rss_base_bytes,rss_peak_bytes,table_bytes,mean_r,mean_g,mean_b\n")
        for x in rows:
            f.write(
                f"{x['kind']},{x['size']},{x['spp']},{x['median_s']:.4f},{len(x['times'])},{x['first_s']:.3f},{x['load_s']:.3f},"
                f"{x['rss_base']},{x['rss_peak']},{x.get('table_bytes', '')},"
                + ",".join(f"{c:.5f}" for c in x["mean_rgb"])
                + "\n"
            )
    with open(out / "mitsuba_speed_synthetic.csv", "w") as f:
        f.write("fit,bsdf,width,spp,median_s,runs,first_render_s,load_s,mode,check_max_relative,check_p99_relative,mean_r,mean_g,mean_b\n")
        for x in synthetic:
            c = x.get("check") or {}
            f.write(
                f"{x['fit']},{x['kind']},{x['size']},{x['spp']},{x['median_s']:.4f},{len(x['times'])},{x['first_s']:.3f},"
                f"{x['load_s']:.3f},{x.get('mode', '')},{c.get('max_relative', '')},{c.get('p99_relative', '')},"
                + ",".join(f"{v:.5f}" for v in x["mean_rgb"])
                + "\n"
            )
    mb = lambda b: f"{b / 2**20:.1f}"  # noqa: E731
    fast = by[("fast", 256)]
    check = fast["check"]
    lines = [
        BEGIN,
        "## Speed and memory: the plugin's fast mode against Mitsuba's own BSDFs",
        "",
        f"Written by `python3 python/examples/mitsuba_speed.py` (issue 41 item 3; CSV: `mitsuba_speed.csv`), on this machine "
        f"({os.cpu_count()} cores; the machine is shared: read the ratios, not the digits). "
        f"The felt `tests/data/rgl/acrylic_felt_green_rgb.bsdf` fitted with `--model auto` ({fit_s:.0f} s): {r.model} "
        f"(the choice's fuzz layer included{correction_text(r)}). One scene: a sphere under a constant environment (0.5) and a directional light, "
        "perspective camera, `path` with max depth 3, `independent` sampler, variant `llvm_ad_rgb`; each BSDF and size in its own "
        "process; the median of the timed renders after one that compiles the kernels. Mitsuba's defaults (symbolic loops and "
        "calls on, which `register()` keeps) but in the rows marked symbolic off (`register(exact_flags=True)`: what the exact "
        "mode needs, and what a scene with an exact instance renders under). `measured` renders the RGL file the fit came from; "
        "`roughconductor` is GGX, alpha 0.1.",
        "",
        "| size, spp | BSDF | median s (runs) | x fast | first render s | peak RSS MiB | RSS over the bare process MiB | mean RGB |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for size, spp in [(256, 16), (512, 64)]:
        base = by[("fast", size)]["median_s"]
        for kind in KINDS:
            x = by[(kind, size)]
            lines.append(
                f"| {size} x {size}, {spp} | {LABELS[kind]} | "
                f"{x['median_s']:.3f} ({len(x['times'])}) | {x['median_s'] / base:.2f} | {x['first_s']:.2f} | "
                f"{mb(x['rss_peak'])} | {mb(x['rss_peak'] - x['rss_base'])} | "
                + ", ".join(f"{c:.4f}" for c in x["mean_rgb"])
                + " |"
            )
    m256, m512 = by[("measured", 256)]["median_s"], by[("measured", 512)]["median_s"]
    e256, e512 = by[("exact", 256)]["median_s"], by[("exact", 512)]["median_s"]
    f512 = by[("fast", 512)]["median_s"]
    mr256, mr512 = by[("measured-evaluated", 256)]["median_s"], by[("measured-evaluated", 512)]["median_s"]
    fe256, fe512 = by[("fast-evaluated", 256)]["median_s"], by[("fast-evaluated", 512)]["median_s"]
    felt_bytes = (ROOT / "tests/data/rgl/acrylic_felt_green_rgb.bsdf").stat().st_size
    rss = lambda k, s: by[(k, s)]["rss_peak"] - by[(k, s)]["rss_base"]  # noqa: E731
    lines += [
        "",
        f"**Time.** The fast mode takes {fast['median_s'] / m256:.2f}x `measured`'s time at 256 x 256 / 16 spp and "
        f"{f512 / m512:.2f}x at 512 x 512 / 64 spp (goal: at most 1x); with symbolic recording off (a scene that also holds "
        f"an exact instance) {fe256 / mr256:.2f}x / {fe512 / mr512:.2f}x `measured`'s under the same flags. The exact mode takes "
        f"{e256 / fast['median_s']:.1f}x and {e512 / f512:.1f}x the fast mode's time. The first render of each process compiles the kernels (the fast mode's "
        "Python methods are traced into them; Dr.Jit caches the compiled kernels on disk between runs).",
        "",
        f"**Memory.** The fast mode's only table is its sampler's: {fast['table_bytes']} bytes of float32 density "
        f"({mb(fast['table_bytes'])} MiB; Mitsuba's warp adds its conditional and marginal CDFs, about as much again), "
        f"at the default resolution {' x '.join(map(str, fast['table_res']))} (the plugin's properties table_theta_v, "
        "table_phi_v, table_theta_l, table_phi_l; stored with one more azimuth node each, the period's end); the model itself "
        "is a few dozen constants in the kernel. "
        f"`measured` reads the {mb(felt_bytes)} MiB RGL file. Peak RSS over the bare process (Mitsuba imported, variant set): "
        f"fast {mb(rss('fast', 256))} MiB, measured {mb(rss('measured', 256))} MiB (ratio "
        f"{rss('fast', 256) / max(rss('measured', 256), 1):.2f}), exact {mb(rss('exact', 256))} MiB at 256 x 256; "
        f"fast {mb(rss('fast', 512))}, measured {mb(rss('measured', 512))} MiB (ratio "
        f"{rss('fast', 512) / max(rss('measured', 512), 1):.2f}) at 512 x 512. The fast mode's excess over `measured` "
        "is mostly its loading, not its table: fibrefit's native material and the load check's Dr.Jit kernel (compiled "
        "once). Symbolic recording off costs any BSDF its evaluated wavefront, every variable of every sample held at once "
        f"(at 512 x 512 / 64 spp: `measured` {rss('measured-evaluated', 512) / 2**30:.1f} GiB, the fast mode "
        f"{rss('fast-evaluated', 512) / 2**30:.1f} GiB, the exact mode {rss('exact', 512) / 2**30:.1f} GiB): why "
        "`register()` leaves it on unless asked.",
        "",
        f"**Accuracy.** The fast mode's load check ({check['cases']} direction pairs: uniform, both within 5 degrees of the "
        f"horizon, the normal against 0-89.9 degrees) against `fibrefit.Material.eval` (the Rust model, f64): largest error "
        f"{check['max_relative']:.2g} of each value, relative to max(|value|, 1e-4 of the largest), 99th percentile "
        f"{check['p99_relative']:.2g}; largest absolute error {check['max_absolute']:.2g} 1/sr where the largest value is "
        f"{check['largest']:.3g} 1/sr (bound: 1e-3, the plugin falls back to its exact mode above it). The mean RGB of the "
        "fast and exact renders differ by the renders' noise only.",
    ]
    sy = {(x["fit"], x["kind"]): x for x in synthetic}
    size, spp = synthetic[0]["size"], synthetic[0]["spp"]
    felt_fast, felt_measured = sy[("felt", "fast")]["median_s"], sy[("felt", "measured")]["median_s"]
    lines += [
        "",
        "### The cross-section rungs: the synthetic brushed and silk fits",
        "",
        "The shipped synthetic goniometric tables fitted with the rungs their captures were made with: "
        + "; ".join(
            f"`data_synthetic/{n}/gonio.csv` with `--model {SYNTHETIC[n][1]}` ({models[n][1]:.0f} s): {models[n][0]}"
            for n in SYNTHETIC
        )
        + f". The same scene at {size} x {size}, {spp} spp; the felt's fast mode and `measured` (Mitsuba's defaults) "
        "as the yardstick, there being no measured file for synthetic data. Fast: `register()`; exact: "
        "`register(exact_flags=True)`. CSV: `mitsuba_speed_synthetic.csv`.",
        "",
        "| fit | BSDF | mode | median s (runs) | x felt `measured` | x the fit's fast | first render s | load s | load check: max, p99 | mean RGB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, kind in SYNTHETIC_ROWS:
        x = sy[(name, kind)]
        own_fast = sy[(name, "fast")]["median_s"]
        c = x.get("check")
        chk = f"{c['max_relative']:.2g}, {c['p99_relative']:.2g}" if c else ""
        label = "measured (the RGL file)" if kind == "measured" else f"fibrefit {kind}"
        lines.append(
            f"| {name} | {label} | {x.get('mode', '')} | {x['median_s']:.3f} ({len(x['times'])}) | "
            f"{x['median_s'] / felt_measured:.2f} | {x['median_s'] / own_fast:.2f} | {x['first_s']:.2f} | {x['load_s']:.2f} | "
            f"{chk} | " + ", ".join(f"{v:.4f}" for v in x["mean_rgb"]) + " |"
        )
    b, sk = sy[("brushed", "fast")]["median_s"], sy[("silk", "fast")]["median_s"]
    lines += [
        "",
        f"**Time.** The brushed fit's fast mode (poulin-fournier: {models['brushed'][2]['spread']} spread node(s), one "
        f"pattern, a {models['brushed'][2]['order']}-node Gauss-Legendre lobe) "
        f"takes {b / felt_measured:.2f}x the felt's `measured` time and {sy[('brushed', 'exact')]['median_s'] / b:.1f}x less "
        f"than its exact mode; the silk's ({models['silk'][0]}: {models['silk'][2]['heights']} height nodes x 2 fibres x "
        f"{models['silk'][2]['spread']} spread nodes, each with the arcs' merge and the lobe) {sk / felt_measured:.0f}x "
        "`measured`'s and "
        f"{sy[('silk', 'exact')]['median_s'] / sk:.1f}x less than its exact mode. The felt's fast mode took "
        f"{felt_fast / felt_measured:.2f}x `measured`'s here. The load check (columns) is the plugin's: each value within "
        "1e-3 of `Material.eval` relative to max(|value|, 1e-4 of the largest); the brushed fit's exponent "
        f"({models['brushed'][2]['exponent']:.0f}) makes its lobe the most sensitive to f32 rounding of the arcs' angles.",
        END,
    ]
    section = "\n".join(lines) + "\n"
    md = out / "mitsuba.md"
    text = md.read_text() if md.exists() else ""
    if BEGIN in text:
        text = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END) + "\n?", lambda _: section, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n" + section
    md.write_text(text)
    print(f"wrote {md} and {out / 'mitsuba_speed.csv'}", file=sys.stderr)
    del np


if __name__ == "__main__":
    main()
