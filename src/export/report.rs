//! The fit report in the style of a lab notebook (after lmfit's fit_report): statistics, each
//! parameter as `value +/- stderr (pct) (init)`, and correlations above 0.1 sorted by size.

use super::atomic::{OutputId, Outputs, Sink};
use super::brdf_plots::{self, Brdf, Curve, HemispherePlot, SlicePlot};
use super::plots;
use crate::fit::parameters::PER_TEXEL;
use crate::fit::FitOutcome;
use std::fmt::Write;

/// The report of `outcome`: the rung `model` fitted to `data` with the metric chosen for the
/// reason `metric` (when one was given).
pub fn text(outcome: &FitOutcome, model: &str, data: &str, metric: Option<&str>) -> String {
    let s = &outcome.statistics;
    let mut t = String::new();
    let _ = writeln!(t, "[[Model]]\n    {model}\n    data: {data}");
    if let Some(why) = metric {
        let _ = writeln!(t, "    metric: {why}");
    }
    let _ = writeln!(t, "[[Fit Statistics]]");
    let _ = writeln!(t, "    # data points      = {}", s.n);
    let _ = writeln!(t, "    # variables        = {}", s.free_parameters);
    let _ = writeln!(
        t,
        "    # iterations       = {} (final start), {} model evaluations",
        outcome.iterations, outcome.evaluations
    );
    if s.sigmas_given {
        let _ = writeln!(t, "    chi-square         = {:.6e}", s.chi_square);
        let _ = writeln!(t, "    reduced chi-square = {:.6}", s.reduced_chi_square);
    } else {
        let _ = writeln!(
            t,
            "    sum of squares     = {:.6e}  (no sigmas: chi-square not defined)",
            s.chi_square
        );
        let _ = writeln!(t, "    residual variance  = {:.6e}", s.reduced_chi_square);
    }
    let _ = writeln!(t, "    RMSE               = {:.6e} 1/sr", s.rmse);
    let _ = writeln!(
        t,
        "    relative RMSE      = {:.4} %",
        100.0 * s.relative_rmse
    );
    let _ = writeln!(t, "    Akaike info crit   = {:.3}", s.aic);
    let _ = writeln!(t, "    Bayesian info crit = {:.3}", s.bic);
    let _ = writeln!(
        t,
        "    wall time          = {:.3} s",
        outcome.elapsed_seconds
    );
    let _ = writeln!(t, "[[Variables]]");
    for r in &outcome.records {
        for (c, v) in r.value.iter().enumerate() {
            let name = if r.value.len() == 1 {
                r.name.clone()
            } else {
                format!("{}[{}]", r.name, ["r", "g", "b"][c])
            };
            let line = if r.fixed && r.fixed_reason.as_deref() == Some(PER_TEXEL) {
                format!("per texel (recovered as a map; {v:.6} is its global start: see [[Maps]])")
            } else if r.fixed {
                match &r.fixed_reason {
                    Some(why) => format!("{v:.6} (fixed: {why})"),
                    None => format!("{v:.6} (fixed)"),
                }
            } else if let Some(why) = r.undetermined(c) {
                // not a measurement: the value is the one used, and why the data leave it open
                let used = match r.std_error[c] {
                    Some(e) => format!("{v:.6} +/- {e:.6}"),
                    None => format!("{v:.6}"),
                };
                format!(
                    "undetermined (value used: {used}; init = {:.6}): {why}",
                    r.init[c]
                )
            } else {
                match r.std_error[c] {
                    Some(e) => format!(
                        "{v:.6} +/- {e:.6} ({:.2}%) (init = {:.6})",
                        100.0 * e / v.abs().max(f64::MIN_POSITIVE),
                        r.init[c]
                    ),
                    None => format!("{v:.6} +/- not determined (init = {:.6})", r.init[c]),
                }
            };
            let grey = if r.grey {
                " [grey: one value fitted for r, g and b]"
            } else {
                ""
            };
            let _ = writeln!(t, "    {name:<20} {line}{grey}");
        }
    }
    if !outcome.correlations.is_empty() {
        let _ = writeln!(t, "[[Correlations]] (unreported correlations are < 0.100)");
        for (a, b, r) in &outcome.correlations {
            let _ = writeln!(t, "    C({a}, {b}) = {r:+.4}");
        }
    }
    if !outcome.starts.is_empty() {
        let _ = writeln!(
            t,
            "[[Starts]] (shape parameters after polishing on the subsample, cost)"
        );
        for (s, c) in &outcome.starts {
            let vals: Vec<String> = s.iter().map(|v| format!("{v:.4}")).collect();
            let _ = writeln!(t, "    [{}] cost {c:.6e}", vals.join(", "));
        }
    }
    let _ = write!(t, "{}", quality_text(&outcome.quality));
    if let Some(c) = &outcome.correction {
        for line in crate::fit::correction::text(c).lines() {
            let _ = writeln!(t, "    {line}");
        }
    }
    if !outcome.warnings.is_empty() {
        let _ = writeln!(t, "[[Warnings]]");
        for w in &outcome.warnings {
            let _ = writeln!(t, "    {w}");
        }
    }
    t
}

/// The [[Renderer materials]] section: each renderer's own material fitted to the same data
/// (a result's `renderer_materials`), its values and its error against the data.
pub fn renderer_materials_text(entries: &[serde_json::Value]) -> String {
    let mut t = String::new();
    if entries.is_empty() {
        return t;
    }
    let _ = writeln!(
        t,
        "[[Renderer materials]] (each renderer's own material fitted to the same data; export --blender, --materialx, --usd, --gltf use them)"
    );
    let num = |x: &serde_json::Value| x.as_f64().map_or(x.to_string(), |x| format!("{x:.4}"));
    for e in entries {
        let stats = &e["statistics"];
        let _ = write!(
            t,
            "    {:<11} {}: relative RMS error {:.1} % (in-sample)",
            e["model"].as_str().unwrap_or("?"),
            e["renderer"].as_str().unwrap_or("?"),
            100.0 * stats["relative_rmse"].as_f64().unwrap_or(f64::NAN)
        );
        if let Some(h) = e["heldout"]["cv_error"].as_f64() {
            let _ = write!(t, ", held-out error {h:.4}");
        }
        let _ = writeln!(t, "; fitted in {:.2} s", e["fit_seconds"].as_f64().unwrap_or(0.0));
        let values: Vec<String> = e["parameters"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(k, v)| {
                let v = &v["value"];
                let shown = match v.as_array() {
                    Some(a) => format!("[{}]", a.iter().map(num).collect::<Vec<_>>().join(", ")),
                    None => num(v),
                };
                format!("{k} {shown}")
            })
            .collect();
        let _ = writeln!(t, "        {}", values.join(", "));
    }
    t
}

/// The [[Quality]] section: noise verdict, distinct minima, residual bins.
pub fn quality_text(q: &crate::fit::quality::Quality) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "[[Quality]]");
    let _ = writeln!(t, "    verdict            = {}", q.verdict);
    let _ = writeln!(t, "    noise ({})  {}", q.noise.source, q.noise.note);
    if !q.undetermined.is_empty() {
        let n = q.undetermined.len();
        let names: Vec<String> = q.undetermined.iter().map(|u| format!("`{}`", u.label)).collect();
        let _ = writeln!(
            t,
            "    undetermined       = {n} value{} the data do not determine, used but not measured: {} (see [[Variables]])",
            if n == 1 { "" } else { "s" },
            names.join(", ")
        );
    }
    if q.minima.len() > 1 {
        let _ = writeln!(
            t,
            "    distinct minima within {} residual variances of the best (free shape parameters, cost, cost above the best in residual variances):",
            crate::fit::quality::AMBIGUOUS_DELTA
        );
        for m in &q.minima {
            let ps: Vec<String> = m
                .parameters
                .iter()
                .map(|(k, v)| format!("{k} {v:.4}"))
                .collect();
            let _ = writeln!(
                t,
                "      [{}] {:.6e} +{:.2}",
                ps.join(", "),
                m.cost,
                m.delta
            );
        }
    }
    if q.minima_beyond > 0 {
        let _ = writeln!(
            t,
            "    other minima found: {} more than {} residual variances above the best (ruled out by the data, not listed)",
            q.minima_beyond,
            crate::fit::quality::AMBIGUOUS_DELTA
        );
    }
    t += &crate::fit::quality::bins_text(&q.residual_bins);
    if let Some(f) = &q.floor {
        t += &crate::fit::floor::text(f);
    }
    t
}


/// What a fit report shows: the fit, the data it was fitted to, the report's text and the BRDFs
/// its pictures draw.
pub struct ReportContent<'a> {
    pub outcome: &'a FitOutcome,
    pub samples: &'a crate::load::samples::Samples,
    /// The fit report ([`text`]), the report's first section.
    pub text: &'a str,
    /// The fitted model.
    pub fitted: Brdf<'a>,
    /// The measured file evaluated at any directions, when the data is one.
    pub measured: Option<Brdf<'a>>,
}

/// Write `dir/report.md` with the fit report and its pictures: the fitted model as curves along
/// slices at fixed incidence (along and across the fibres) with the measured samples near each
/// slice, hemisphere maps of measured / fitted / residual for a few incidences (dense when the
/// data is a measured file, `measured`), a histogram of the relative residuals, and for image
/// captures a residual map per image.
pub fn write_dir(
    outs: &mut Outputs,
    files: &ReportFiles,
    report: &ReportContent,
) -> anyhow::Result<()> {
    let mut md = format!("# fibrefit fit report\n\n```text\n{}```\n\n", report.text);
    let psi_deg = report
        .outcome
        .set
        .shape_value(crate::fit::parameters::Param::Azimuth);
    md += &slices_section(outs, files.slices, report, psi_deg)?;
    md += &hemispheres_section(outs, files.hemispheres, report, psi_deg)?;
    md += &residuals_section(outs, files, report)?;
    outs.put(files.md, md.as_bytes())
}

/// The slices picture (`id`) and its section: the fitted curves (and the measured file's,
/// dashed), on a log axis when the data spans decades, with the samples near each slice.
fn slices_section(
    outs: &mut Outputs,
    id: OutputId,
    report: &ReportContent,
    psi_deg: f64,
) -> anyhow::Result<String> {
    let samples = report.samples;
    let ch = samples.channels;
    // measured data spanning decades reads best on a log axis
    let positive: Vec<f64> = samples
        .samples
        .iter()
        .map(|s| s.value[..ch].iter().sum::<f64>() / ch as f64)
        .filter(|v| *v > 0.0)
        .collect();
    let lo = positive.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = positive.iter().copied().fold(0.0f64, f64::max);
    let log_y = positive.len() == samples.samples.len() && hi > 30.0 * lo;
    let mut curves = Vec::new();
    if let Some(m) = report.measured {
        curves.push(Curve {
            name: "measured file".into(),
            brdf: m,
            dashed: true,
        });
    }
    curves.push(Curve {
        name: format!("fitted {}", report.outcome.set.rung),
        brdf: report.fitted,
        dashed: false,
    });
    let points = brdf_plots::slices(
        Sink::Staged(outs, id),
        &SlicePlot {
            title: "Slices at fixed incidence: fitted curves and measured samples",
            psi_deg,
            channels: ch,
            curves: &curves,
            samples: &samples.samples,
            log_y,
        },
    )?;
    let (points, per) = (points.drawn.points, points.drawn.note);
    Ok(format!(
        "## Slices\n\nThe fitted BRDF (1/sr, {per}{}) along the plane of the fibres (T-N, fibres at \
         {psi_deg:.1} deg) and across it (B-N) at incidence {} deg: the light on the negative side, the \
         view at a signed angle (+: the far side){}; dots: the {points} samples near a slice (theta_i \
         within {:.0} deg, both directions within {:.0} deg of the plane), their mean +-1 sd per 2 deg bin of theta_o; rings: the fit at those samples' own directions; shaded: the fit over their offsets from the plane (its curve is drawn in the plane, where no sample lies exactly).\n\n![slices](slices.png)\n\n",
        if log_y { ", log axis" } else { "" },
        brdf_plots::SLICE_THETAS.map(|t| format!("{t:.0}")).join(", "),
        if report.measured.is_some() {
            "; dashed: the measured file on the same directions"
        } else {
            ""
        },
        brdf_plots::NEAR_THETA_DEG,
        brdf_plots::NEAR_PLANE_COSINE.asin().to_degrees(),
    ))
}

/// The hemisphere maps picture (`id`) and its section.
fn hemispheres_section(
    outs: &mut Outputs,
    id: OutputId,
    report: &ReportContent,
    psi_deg: f64,
) -> anyhow::Result<String> {
    let near = brdf_plots::hemispheres(
        Sink::Staged(outs, id),
        &HemispherePlot {
            title: "Hemisphere maps: measured, fitted, residual",
            psi_deg,
            channels: report.samples.channels,
            fitted: report.fitted,
            measured: report.measured,
            samples: &report.samples.samples,
        },
    )?;
    // count what is drawn: a measured file's maps draw none of the samples
    let drawn = match (near.points, report.measured.is_some()) {
        (0, true) => "No samples drawn (the measured column is the file itself)".to_string(),
        (0, false) => "No samples lie near the lights shown".to_string(),
        (n, _) => format!("{n} samples drawn"),
    };
    Ok(format!(
        "## Hemisphere maps\n\nEvery view direction for a light (orthographic, seen from above). {} \
         {drawn}; residual colour bar +/-{:.2} %.\n\n![hemisphere maps](hemispheres.png)\n\n",
        near.note,
        near.colour_bars.last().map_or(0.0, |b| b.hi),
    ))
}

/// The residual histogram and, for image captures, a residual map per image (the image's size,
/// per channel, a colour bar in percent), with their sections; the reserved maps of images
/// without samples are given up.
fn residuals_section(
    outs: &mut Outputs,
    files: &ReportFiles,
    report: &ReportContent,
) -> anyhow::Result<String> {
    let (samples, outcome) = (report.samples, report.outcome);
    let ch = samples.channels;
    let rel: Vec<f64> = samples
        .samples
        .iter()
        .zip(&outcome.fitted)
        .flat_map(|(s, m)| (0..ch).map(move |c| (m[c] - s.value[c]) / s.value[c].abs().max(1e-12)))
        .collect();
    plots::histogram(
        Sink::Staged(outs, files.residuals),
        "Relative residuals (fitted - measured) / measured",
        "relative residual",
        &rel,
        60,
    )?;
    let mut md = String::from("## Residuals\n\n![residual histogram](residuals.png)\n\n");
    // residual maps for captures: the image's size, per channel, a colour bar in percent
    let images = plots::image_residuals(samples, &outcome.fitted);
    // reserved maps of images without samples are not written
    for (k, id) in &files.maps {
        if !images.contains_key(k) {
            outs.discard(*id);
        }
    }
    for (k, r) in &images {
        let Some(&id) = files.maps.get(k) else {
            anyhow::bail!("image {k}: no residual map was reserved for it");
        };
        let d = plots::residual_map(
            Sink::Staged(outs, id),
            &format!("Image {k}: relative residual per pixel"),
            r,
        )?;
        md += &format!("### Image {k}: relative residual per pixel ({} x {} px, {}; red: fitted above measured, blue: below, grey: no sample; colour bar +/-{:.2} %, the {:.0}th percentile of |residual|)\n\n![residual map {k}](residual_map_{k:03}.png)\n\n", r.width, r.height, d.panels.join(", "), d.colour_bars[0].hi, plots::RESIDUAL_PERCENTILE);
    }
    Ok(md)
}

/// The files of a fit report (`report.md`, its plots, a residual map per capture image),
/// reserved in the run's outputs before the work, so that none is an input or another output.
pub struct ReportFiles {
    dir: std::path::PathBuf,
    md: OutputId,
    slices: OutputId,
    hemispheres: OutputId,
    residuals: OutputId,
    /// `view.html`: the viewer page (`api::view::fit_page`).
    view: OutputId,
    maps: std::collections::BTreeMap<u32, OutputId>,
}

impl ReportFiles {
    /// Reserve the report in `dir` (created if missing); a capture's residual maps are added
    /// with [`ReportFiles::add_images`] once its images are known.
    pub fn reserve(outs: &mut Outputs, dir: &std::path::Path) -> anyhow::Result<Self> {
        outs.dir(dir, "--report")?;
        let mut file = |name: &str| outs.file(&dir.join(name), "--report");
        let (md, slices, hemispheres, residuals, view) = (
            file("report.md")?,
            file("slices.png")?,
            file("hemispheres.png")?,
            file("residuals.png")?,
            file("view.html")?,
        );
        Ok(Self {
            dir: dir.to_path_buf(),
            md,
            slices,
            hemispheres,
            residuals,
            view,
            maps: Default::default(),
        })
    }

    /// Reserve the residual maps of the capture images `images`.
    pub fn add_images(
        &mut self,
        outs: &mut Outputs,
        images: impl IntoIterator<Item = u32>,
    ) -> anyhow::Result<()> {
        for k in images {
            let path = self.dir.join(format!("residual_map_{k:03}.png"));
            self.maps.insert(k, outs.file(&path, "--report")?);
        }
        Ok(())
    }

    /// Write the viewer page `html` as `view.html`.
    pub fn put_view(&self, outs: &mut Outputs, html: &str) -> anyhow::Result<()> {
        outs.put(self.view, html.as_bytes())
    }

    /// Give the viewer page up (the old file stays as it was).
    pub fn discard_view(&self, outs: &mut Outputs) {
        outs.discard(self.view);
    }

    /// Give the report up (the old files stay as they were).
    pub fn discard(&self, outs: &mut Outputs) {
        for id in [self.md, self.slices, self.hemispheres, self.residuals, self.view]
            .into_iter()
            .chain(self.maps.values().copied())
        {
            outs.discard(id);
        }
    }
}
