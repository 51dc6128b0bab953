"""Fit a shipped capture, render it in Mitsuba 3 with the fibrefit plugin, and show captured |
Mitsuba | difference per image with colour bars; time the plugin against Mitsuba's built-in
anisotropic roughconductor on a 512 x 512 swatch.

    python3 python/examples/capture_side_by_side.py [--capture data_synthetic/brushed/capture.toml
        --config configs/fit_brushed.toml] [--out reports]

Writes OUT/mitsuba_capture.png and OUT/mitsuba.md (needs matplotlib and mitsuba).
"""

import argparse
import json
import pathlib
import sys
import tempfile
import time

import numpy as np

import fibrefit
import fibrefit.mitsuba as fm

ROOT = pathlib.Path(__file__).resolve().parents[2]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--capture", default=str(ROOT / "data_synthetic/brushed/capture.toml"))
    ap.add_argument("--config", default=str(ROOT / "configs/fit_brushed.toml"))
    ap.add_argument("--out", default=str(ROOT / "reports"))
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--spp", type=int, default=None, help="rays over each pixel's area [default: one through its centre, as a capture's pixel is defined]")
    a = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mitsuba as mi

    mi.set_variant(a.variant)
    fm.register(exact_flags=True)  # the brushed fit (poulin-fournier) renders through the exact path
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    capture = pathlib.Path(a.capture)
    work = pathlib.Path(tempfile.mkdtemp(prefix="fibrefit_mitsuba_"))
    print(f"fitting {capture} with {a.config} ...", file=sys.stderr)
    r = fibrefit.fit(capture, config=a.config)
    result = work / "fit.json"
    r.to_json(result)
    m = fibrefit.load(result)
    images = fm.capture_geometry(capture)["images"]
    rows = []
    fig, axes = plt.subplots(len(images), 3, figsize=(10, 3.1 * len(images)), squeeze=False)
    for k in range(len(images)):
        t0 = time.perf_counter()
        rendered = np.array(mi.render(mi.load_dict(fm.capture_scene(capture, result, k, spp=a.spp))), dtype=np.float64)
        seconds = time.perf_counter() - t0
        own = m.render_capture(capture, k).astype(np.float64)
        captured, saturated = fm.captured_image(capture, k)
        c = m.channels
        captured, rendered = captured.astype(np.float64)[..., :c], rendered[..., :c]
        diff = (rendered - captured).mean(axis=2)
        top = max(captured.max(), rendered.max())
        show = lambda x: np.clip(x / top, 0, 1) ** (1 / 2.2) if c == 3 else np.clip(x[..., 0] / top, 0, 1) ** (1 / 2.2)
        axes[k, 0].imshow(show(captured), cmap=None if c == 3 else "gray", vmin=0, vmax=1)
        axes[k, 0].set_title(f"image {k}: captured")
        axes[k, 1].imshow(show(rendered), cmap=None if c == 3 else "gray", vmin=0, vmax=1)
        axes[k, 1].set_title("Mitsuba 3 + fibrefit plugin")
        lim = np.abs(diff).max()
        im = axes[k, 2].imshow(diff, cmap="RdBu_r", vmin=-lim, vmax=lim)
        axes[k, 2].set_title("Mitsuba - captured (radiance)")
        fig.colorbar(im, ax=axes[k, 2], fraction=0.046)
        for ax in axes[k]:
            ax.set_xticks([])
            ax.set_yticks([])
        rel_own = np.max(np.abs(rendered - own)) / np.abs(own).max()
        rows.append((k, np.sqrt(np.mean((rendered - captured)[~saturated] ** 2)), rel_own, seconds))
    fig.tight_layout()
    fig.savefig(out / "mitsuba_capture.png", dpi=90)

    # timing: 512 x 512 orthographic swatch, plugin against Mitsuba's built-in anisotropic
    # roughconductor, same scene and samples, median of 3
    def swatch(bsdf, spp=4):
        return mi.load_dict(
            {
                "type": "scene",
                "integrator": {"type": "path", "max_depth": 2},
                "sensor": {
                    "type": "orthographic",
                    "to_world": mi.ScalarTransform4f().look_at(origin=[0.3, -0.4, 2], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": 512, "height": 512},
                    "sampler": {"type": "independent", "sample_count": spp},
                },
                "swatch": {"type": "rectangle", "bsdf": bsdf},
                "light": {"type": "directional", "direction": [-0.3, -0.5, -0.8]},
            }
        )

    def median_seconds(scene):
        mi.render(scene)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            np.array(mi.render(scene))
            times.append(time.perf_counter() - t0)
        return float(np.median(times))

    plugin_mode = mi.load_dict({"type": "fibrefit", "filename": str(result)}).mode
    t_plugin = median_seconds(swatch({"type": "fibrefit", "filename": str(result)}))
    t_builtin = median_seconds(swatch({"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.05, "alpha_v": 0.3}))
    # mitsuba_speed.py's section of the same file is kept as it is
    md = out / "mitsuba.md"
    old = md.read_text() if md.exists() else ""
    begin, end = old.find("<!-- mitsuba_speed: begin -->"), old.find("<!-- mitsuba_speed: end -->")
    speed = old[begin : end + len("<!-- mitsuba_speed: end -->")] + "\n" if 0 <= begin < end else ""
    with open(md, "w") as f:
        f.write("# A capture re-rendered by Mitsuba 3 with the fibrefit plugin\n\n")
        f.write(f"Written by `python3 python/examples/capture_side_by_side.py` (variant {a.variant}, {'one ray through each pixel centre' if a.spp is None else f'{a.spp} rays over each pixel'}).\n")
        f.write(f"Capture `{capture.relative_to(ROOT) if capture.is_relative_to(ROOT) else capture}`, fitted with `{pathlib.Path(a.config).name}`: {r.model}, ")
        f.write(f"relative RMSE {r.statistics['relative_rmse']:.4f}.\n\n")
        f.write("![captured, Mitsuba, difference](mitsuba_capture.png)\n\n")
        f.write("| image | RMS(Mitsuba - captured) | max \\|Mitsuba - fibrefit\\| / max | render s |\n|---|---|---|---|\n")
        for k, rms, rel, sec in rows:
            f.write(f"| {k} | {rms:.3g} | {rel:.2g} | {sec:.2f} |\n")
        f.write(
            f"\n512 x 512 swatch, path tracer (max depth 2), 4 spp, median of 3 renders: plugin ({plugin_mode} mode"
            f"{': the rung is not ported to the fast mode' if plugin_mode == 'exact' else ''}) {t_plugin:.2f} s, "
            f"built-in anisotropic `roughconductor` {t_builtin:.2f} s: ratio {t_plugin / t_builtin:.1f}x.\n"
        )
        if speed:
            f.write("\n" + speed)
    print(f"wrote {out / 'mitsuba_capture.png'} and {out / 'mitsuba.md'}", file=sys.stderr)


if __name__ == "__main__":
    main()
