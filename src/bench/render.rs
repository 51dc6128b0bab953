//! `fibrefit bench render`: how long a preview takes per rung, side by side with and without
//! adaptive shading of the subsamples, and how far apart the two pictures are. Every rung
//! (but `reference`, seconds per evaluation) at its registry example, and the kinds of fit real
//! cloth gets (poulin-fournier and varying-topology with a fibre-direction spread and the fuzz
//! layer), on the default preview: a torus, the studio lights and the fill, 512 x 512 with
//! supersample 2, `fibrefit render`'s own path ([`crate::api::render::Render`]). Goal (issue
//! 41): at most 1 s for any rung.

use crate::api::render::{FlagScene, LightPreset, Render, RenderRequest, SceneSource};
use crate::export::picture::{auto_exposure, srgb_rgba};
use crate::model::frame::direction_from_angles;
use crate::model::ModelId;
use crate::render::{Picture, Subsamples, ADAPTIVE_TOLERANCE};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// The goal: seconds per 512 x 512 preview with supersample 2.
pub const GOAL_SECONDS: f64 = 1.0;

/// One material's figures (a row of `render_speed.csv`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RenderRow {
    pub name: String,
    /// Median wall seconds, adaptive and every subsample shaded.
    pub adaptive_s: f64,
    pub every_s: f64,
    /// Share of the covered pixels (any ray hits) whose every subsample the adaptive picture
    /// shaded.
    pub refined: f64,
    /// Largest difference between the pictures (any pixel and channel) over the picture's level
    /// (the 99.5th percentile of the lit pixels).
    pub max_rel_level: f64,
    /// Largest difference of the PNGs' 8-bit sRGB codes at the exact picture's auto exposure.
    pub max_codes: u8,
    /// Share of the pixels whose PNG codes differ at all.
    pub codes_differ: f64,
}

/// The study: its rows, the size and repeats.
pub struct RenderRun {
    pub rows: Vec<RenderRow>,
    pub size: usize,
    pub repeats: usize,
}

/// The materials: (name, parameter TOML).
fn materials() -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = ModelId::ALL
        .iter()
        .filter(|&&id| id != ModelId::Reference)
        .map(|&id| {
            (
                id.to_string(),
                format!("model = \"{id}\"\n{}", id.rung().example_text(None)),
            )
        })
        .collect();
    let fuzz = "fuzz = 3.0\nfuzz_depth = 0.3\nfuzz_asymmetry = 0.6\n";
    out.push((
        "poulin-fournier + spread 180 + fuzz (felt)".into(),
        format!(
            "model = \"poulin-fournier\"\n{}azimuth_spread_deg = 180\n{fuzz}",
            ModelId::PoulinFournier.rung().example_text(Some(20.0))
        ),
    ));
    out.push((
        "varying-topology + spread 30 + fuzz".into(),
        format!(
            "model = \"varying-topology\"\n{}azimuth_spread_deg = 30\n{fuzz}",
            ModelId::VaryingTopology.rung().example_text(None)
        ),
    ));
    out
}

/// Render the material of `params` once with `subsamples`; the picture and its wall time.
fn once(params: &Path, size: usize, subsamples: Subsamples) -> Result<(Picture, f64)> {
    let req = RenderRequest {
        params: params.to_path_buf(),
        model: None,
        scene: SceneSource::Flags(FlagScene {
            object: "torus".into(),
            tangents: "curvature".into(),
            preset: LightPreset::Studio,
            lights: vec![],
            camera: direction_from_angles(50f64.to_radians(), 270f64.to_radians()),
            size: [size, size],
            supersample: 2,
            fill: crate::render::DEFAULT_FILL,
        }),
        maps: None,
        ward_curvature_alpha: None,
        subsamples,
        progress: crate::progress::Progress::quiet(),
    };
    let t = Instant::now();
    let pic = Render::prepare(&req)?.run()?;
    Ok((pic, t.elapsed().as_secs_f64()))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Run the study in `scratch` (parameter files): `repeats` renders of each kind, alternating.
pub fn run(
    scratch: &Path,
    size: usize,
    repeats: usize,
    progress: &crate::progress::Progress,
) -> Result<RenderRun> {
    let adaptive = Subsamples::Adaptive {
        tolerance: ADAPTIVE_TOLERANCE,
    };
    let mut rows = Vec::new();
    for (k, (name, text)) in materials().into_iter().enumerate() {
        progress.line(&format!("bench render: {name}"));
        let path = scratch.join(format!("m{k}.toml"));
        std::fs::write(&path, &text).with_context(|| format!("writing {}", path.display()))?;
        let (mut ta, mut te) = (vec![], vec![]);
        let (mut pa, mut pe) = (None, None);
        for _ in 0..repeats {
            let (p, t) = once(&path, size, adaptive)?;
            ta.push(t);
            pa = Some(p);
            let (p, t) = once(&path, size, Subsamples::Every)?;
            te.push(t);
            pe = Some(p);
        }
        let (a, e) = (pa.expect("one repeat"), pe.expect("one repeat"));
        let exposure = auto_exposure(&e);
        let level = 0.8 / exposure;
        let max_diff = a
            .radiance
            .iter()
            .zip(&e.radiance)
            .flat_map(|(x, y)| (0..3).map(move |c| (x[c] as f64 - y[c] as f64).abs()))
            .fold(0.0, f64::max);
        let (ca, ce) = (srgb_rgba(&a, exposure, true), srgb_rgba(&e, exposure, true));
        let pixels = a.width * a.height;
        let covered = e.alpha.iter().filter(|&&c| c > 0.0).count().max(1);
        let mut max_codes = 0u8;
        let mut differ = 0usize;
        for (x, y) in ca.chunks(4).zip(ce.chunks(4)) {
            let d = (0..3).map(|c| x[c].abs_diff(y[c])).max().unwrap_or(0);
            max_codes = max_codes.max(d);
            differ += (d > 0) as usize;
        }
        rows.push(RenderRow {
            name,
            adaptive_s: median(ta),
            every_s: median(te),
            refined: a.shaded_every as f64 / covered as f64,
            max_rel_level: max_diff / level,
            max_codes,
            codes_differ: differ as f64 / pixels as f64,
        });
    }
    Ok(RenderRun {
        rows,
        size,
        repeats,
    })
}

/// Write OUT/render_speed.md and .csv.
pub fn write(out: &Path, run: &RenderRun, command: &str, total_s: f64) -> Result<()> {
    std::fs::create_dir_all(out)?;
    crate::bench::report::speed::write_csv(&out.join("render_speed.csv"), &run.rows)?;
    let slowest = run
        .rows
        .iter()
        .map(|r| r.adaptive_s)
        .fold(0.0, f64::max);
    let mut md = format!(
        "# Previews: `fibrefit render` per rung\n\n\
         Generated by `{command}` in {total_s:.0} s on this machine (2 cores; CSV: \
         `render_speed.csv`, times in seconds, shares as fractions). Each material on the default preview: a torus, the studio lights \
         and the fill, {0} x {0} pixels, supersample 2 (4 rays per pixel), through `fibrefit \
         render`'s own path; the median of {1} renders of each kind, the two kinds alternating. \
         **Adaptive** (the default): every ray is traced, but an interior pixel whose radiance is \
         smooth is shaded once at its centre, and the subsamples' mean estimated from it and the \
         neighbouring centres' second differences, where their third differences bound the \
         estimate within {2:e} of the picture's level, the 99.5th percentile of the lit pixels \
         that `--exposure auto` maps to 0.8 (nearer an edge: the centre's value itself, where \
         the second differences bound it within {5:e}). **Every**: every ray \
         shaded (`--every-subsample`, the exact box filter). The difference is between the two \
         pictures: the largest over pixels and channels, in units of the level, and in the \
         PNGs' 8-bit codes at the exact picture's auto exposure. Goal (issue 41): at most {3} s \
         for any rung.\n\n\
         Slowest material, adaptive: **{slowest:.2} s** ({4}).\n\n\
         | material | adaptive [s] | every [s] | speed-up | covered pixels shaded at every ray | largest difference / level | largest PNG difference [codes] | PNG pixels differing |\n\
         |---|---|---|---|---|---|---|---|\n",
        run.size,
        run.repeats,
        ADAPTIVE_TOLERANCE,
        GOAL_SECONDS,
        if slowest <= GOAL_SECONDS {
            "goal met"
        } else {
            "**goal missed**"
        },
        ADAPTIVE_TOLERANCE / crate::render::NARROW_SAFETY,
    );
    for r in &run.rows {
        let _ = writeln!(
            md,
            "| {} | {:.2} | {:.2} | {:.1}x | {:.1} % | {:.1e} | {} | {:.2} % |",
            r.name,
            r.adaptive_s,
            r.every_s,
            r.every_s / r.adaptive_s,
            100.0 * r.refined,
            r.max_rel_level,
            r.max_codes,
            100.0 * r.codes_differ
        );
    }
    std::fs::write(out.join("render_speed.md"), md)?;
    Ok(())
}
