//! `fibrefit bench sampling`: what the importance sampler of `model::sampling` buys.
//!
//! For each rung at exponent 1000 (ward: alpha 0.05 x 0.2) and a set of views, the directional
//! albedo a(v) = int f(l, v) (N.l) d omega estimated from one-sample weights: the per-sample
//! variance of the sampler's weight against that of pure cosine sampling (weight = pi f), at the
//! same sample count and from the same seeds, so the ratio is the factor fewer samples the
//! sampler needs for the same noise. Also: the fibre lobe's width swept around its default
//! (max-normal and poulin-fournier), the ratio at other exponents, and samples per second per
//! rung on one thread (with the model's evaluation, and the sampler alone). Everything but the
//! timings is deterministic (seeded, one seed per row).

use crate::model::frame::Local;
use crate::model::params::{ModelParams, RawParams};
use crate::model::rungs::Cost;
use crate::model::sampling::{Draw, Instance, Sample, Sampler, LOBE_WIDTH};
use crate::model::{self, lambert::Lambert, DirectionPair, ModelId};
use anyhow::{anyhow, Result};
use indicatif::ProgressBar;
use rayon::prelude::*;
use std::f64::consts::{PI, TAU};
use std::time::Instant;

/// One rung at one view: the two estimators' statistics.
#[derive(Clone, Debug, serde::Serialize)]
pub struct VarianceRow {
    pub rung: String,
    pub exponent: f64,
    /// Cauchy width of the fibre lobe in units of 1/sqrt(exponent).
    pub lobe_width: f64,
    pub theta_v_deg: f64,
    /// Azimuth of v from the fibre tangent T.
    pub phi_v_deg: f64,
    pub samples: usize,
    pub albedo_sampled: f64,
    pub albedo_cosine: f64,
    pub variance_sampled: f64,
    pub variance_cosine: f64,
    /// variance_cosine / variance_sampled.
    pub ratio: f64,
}

/// Cost per sample on one thread.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SpeedRow {
    pub rung: String,
    pub variant: String,
    /// `Sampler::sample` with the rung's own evaluation (what a renderer pays).
    pub samples_per_second: f64,
    /// The direction and its pdf alone (`sample` with a constant model).
    pub sampler_only_per_second: f64,
    /// The rung's evaluation alone (`basis`), for comparison.
    pub evals_per_second: f64,
    /// `Sampler::new` (the cross-section rungs tabulate their cone law there), milliseconds:
    /// the median of 5.
    pub construct_ms: f64,
    /// `Sampler::sample` with the evaluation on [`SPEED_THREADS`] threads at once (their
    /// samples summed over the same wall time): what 2 cores draw. Goal (issue 41): at least
    /// [`SAMPLES_GOAL`] for every rung.
    pub parallel_samples_per_second: f64,
    /// `Sampler::sample_many` in blocks of [`BATCH`] draws on [`SPEED_THREADS`] threads: what
    /// a renderer drawing a wavefront of samples (Mitsuba, `Material.sample` on arrays) gets.
    pub batched_samples_per_second: f64,
    /// How many instances the material mixes (spread nodes times histogram heights,
    /// [`crate::model::sampling::Instance`]); 1: the exact evaluation is one instance, and the
    /// instance columns are empty.
    pub instances: usize,
    /// `Sampler::sample_instance`, one instance drawn per sample (a third uniform), on
    /// [`SPEED_THREADS`] threads, as `parallel_samples_per_second`.
    pub instance_samples_per_second: Option<f64>,
    /// `Sampler::sample_many_instances` in blocks of [`BATCH`], as `batched_samples_per_second`.
    pub instance_batched_per_second: Option<f64>,
    /// The per-sample variance of the albedo estimate with one instance per sample over the
    /// exact sampler's, geometric mean over the views (exponent as the row's).
    pub instance_variance_ratio: Option<f64>,
    /// The largest difference over the views between the two estimates of the albedo, in
    /// standard errors of the difference (unbiased: |z| of a few at most).
    pub instance_albedo_z: Option<f64>,
}

/// Draws per block of the batched speed measure (as `Material.sample`'s blocks).
pub const BATCH: usize = 256;

/// Threads of the parallel speed measure (the 2 cores the goal is set on).
pub const SPEED_THREADS: usize = 2;
/// Samples per second (with the rung's evaluation) every rung should draw on 2 cores.
pub const SAMPLES_GOAL: f64 = 2e6;

pub struct SamplingRun {
    pub variance: Vec<VarianceRow>,
    pub widths: Vec<VarianceRow>,
    pub exponents: Vec<VarianceRow>,
    pub speed: Vec<SpeedRow>,
    pub quick: bool,
}

/// The views of the study: (theta_v, phi_v from T), degrees.
pub const VIEWS: [(f64, f64); 10] = [
    (0.0, 0.0),
    (30.0, 0.0),
    (30.0, 45.0),
    (30.0, 90.0),
    (60.0, 0.0),
    (60.0, 45.0),
    (60.0, 90.0),
    (80.0, 0.0),
    (80.0, 45.0),
    (80.0, 90.0),
];

/// The parameter text of `rung` at exponent `e`.
pub fn params_text(id: ModelId, e: f64) -> String {
    id.rung().example_text(Some(e))
}

pub fn params(id: ModelId, text: &str) -> Result<ModelParams> {
    let raw: RawParams = toml::from_str(text).map_err(|e| anyhow!("{e}"))?;
    Ok(ModelParams::from_raw(&raw, id)?.0)
}

/// A view at polar angle theta from N and azimuth phi from T (degrees), fibre frame.
pub fn view(theta_deg: f64, phi_deg: f64) -> Local {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    Local {
        t: st * cp,
        b: st * sp,
        n: ct,
    }
}

/// splitmix64 uniforms in [0, 1): the same stream on every machine and version.
pub struct Uniforms(u64);

impl Uniforms {
    pub fn new(seed: u64) -> Self {
        Uniforms(seed)
    }
    pub fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Mean and per-sample variance of `n` weights.
fn moments(n: usize, mut weight: impl FnMut() -> f64) -> (f64, f64) {
    // Welford: the weights of a sharp lobe span many orders of magnitude
    let (mut mean, mut m2) = (0.0, 0.0);
    for k in 1..=n {
        let w = weight();
        let d = w - mean;
        mean += d / k as f64;
        m2 += d * (w - mean);
    }
    (mean, m2 / n.max(2) as f64)
}

/// The variance study of one rung at one view.
pub fn variance_row(
    id: ModelId,
    p: &ModelParams,
    lobe_width: f64,
    v: (f64, f64),
    samples: usize,
    seed: u64,
) -> Result<VarianceRow> {
    let m = model::build(id, p)?;
    let sampler = Sampler::new(id, p).with_lobe_width(lobe_width);
    let a = p.albedos;
    let dir = view(v.0, v.1);
    let mut u = Uniforms::new(seed);
    let (albedo_sampled, variance_sampled) = moments(samples, || {
        sampler
            .sample(m.as_ref(), &a, None, &dir, [u.next(), u.next()])
            .map_or(0.0, |s| s.weight[0])
    });
    let mut u = Uniforms::new(seed ^ 0x5555_5555);
    let (albedo_cosine, variance_cosine) = moments(samples, || {
        let (r2, ph) = (u.next(), TAU * u.next());
        let r = r2.sqrt();
        let l = Local {
            t: r * ph.cos(),
            b: r * ph.sin(),
            n: (1.0 - r2).sqrt(),
        };
        if !(l.n > 0.0) {
            return 0.0;
        }
        // weight f (N.l) / ((N.l) / pi)
        PI * m.basis(&DirectionPair { l, v: dir }).brdf(&a, 0)
    });
    Ok(VarianceRow {
        rung: id.to_string(),
        exponent: p.exponent,
        lobe_width,
        theta_v_deg: v.0,
        phi_v_deg: v.1,
        samples,
        albedo_sampled,
        albedo_cosine,
        variance_sampled,
        variance_cosine,
        ratio: variance_cosine / variance_sampled,
    })
}

/// Samples per rung and view of the study (cost-limited for the slow rungs).
fn samples_for(id: ModelId, quick: bool) -> usize {
    let n = match id.rung().cost {
        Cost::HeightHistogram => 40_000,
        _ => 400_000,
    };
    if quick {
        n / 10
    } else {
        n
    }
}

/// `run(seed)` on [`SPEED_THREADS`] threads at once (seeds 17, 18, ...), each returning its
/// (count, seconds): their counts summed over the longest wall time.
fn on_speed_threads(run: impl Fn(u64) -> (usize, f64) + Sync) -> f64 {
    let run = &run;
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..SPEED_THREADS)
            .map(|k| scope.spawn(move || run(17 + k as u64)))
            .collect();
        let done: Vec<(usize, f64)> = handles
            .into_iter()
            .map(|h| h.join().expect("a speed thread"))
            .collect();
        let count: usize = done.iter().map(|d| d.0).sum();
        count as f64 / done.iter().map(|d| d.1).fold(0.0, f64::max)
    })
}

/// Samples per second of `sampler` (with `m`'s evaluation on this thread and on
/// [`SPEED_THREADS`] threads, and with a constant model) and `m`'s evaluations per second, over
/// the study's views.
fn speed_row(
    id: ModelId,
    variant: &str,
    p: &ModelParams,
    heights: Option<(f64, f64)>,
    budget: f64,
    quick: bool,
) -> Result<SpeedRow> {
    let m = model::build(id, p)?;
    // the median of 5 constructions (one alone varied 2-5x between runs)
    let mut made = Vec::new();
    let mut construct = [0.0; 5];
    for c in &mut construct {
        let t = Instant::now();
        made.push(Sampler::new(id, p));
        *c = 1e3 * t.elapsed().as_secs_f64();
    }
    construct.sort_by(f64::total_cmp);
    let construct_ms = construct[2];
    let sampler = made.pop().expect("a sampler");
    let a = p.albedos;
    let views: Vec<Local> = VIEWS.iter().map(|&(t, f)| view(t, f)).collect();
    // run until `budget` seconds have passed, in rounds over the views; the count
    let run = |seed: u64, f: &dyn Fn(&Local, [f64; 2], f64) -> f64| {
        let mut u = Uniforms::new(seed);
        let (mut count, mut sink) = (0usize, 0.0);
        let t = Instant::now();
        while t.elapsed().as_secs_f64() < budget || count == 0 {
            for v in &views {
                sink += f(v, [u.next(), u.next()], u.next());
                count += 1;
            }
        }
        std::hint::black_box(sink);
        (count, t.elapsed().as_secs_f64())
    };
    let time = |f: &dyn Fn(&Local, [f64; 2], f64) -> f64| {
        let (count, seconds) = run(17, f);
        count as f64 / seconds
    };
    // a texel's height per draw where the variant has a map (heights over their range)
    let height = |r: f64| heights.map(|(lo, hi)| lo + (hi - lo) * r);
    let with_eval = |v: &Local, u: [f64; 2], r: f64| {
        sampler
            .sample(m.as_ref(), &a, height(r), v, u)
            .map_or(0.0, |s| s.weight[0])
    };
    let parallel_samples_per_second = on_speed_threads(|seed| run(seed, &with_eval));
    // the same draws in blocks (`sample_many`: the rung evaluated at a block at once), as a
    // wavefront renderer or `Material.sample` on arrays asks for them, on SPEED_THREADS threads
    // blocks of BATCH draws (uniforms u0, u1, then r for the height and the instance), each
    // drawn at once by `draw_block`, until `budget` seconds have passed: (count, seconds)
    let in_blocks = |seed: u64, draw_block: &dyn Fn(&[Draw], &[f64], &mut [Option<Sample>])| {
        let mut u = Uniforms::new(seed);
        let (mut draws, mut rs) = (Vec::with_capacity(BATCH), Vec::with_capacity(BATCH));
        let mut out = vec![None; BATCH];
        let (mut count, mut sink) = (0usize, 0.0);
        let t = Instant::now();
        while t.elapsed().as_secs_f64() < budget || count == 0 {
            draws.clear();
            rs.clear();
            for k in 0..BATCH {
                let u2 = [u.next(), u.next()];
                let r = u.next();
                draws.push(Draw {
                    albedos: a,
                    height: height(r),
                    v: views[k % views.len()],
                    u: u2,
                });
                rs.push(r);
            }
            draw_block(&draws, &rs, &mut out);
            sink += out.iter().flatten().map(|s| s.weight[0]).sum::<f64>();
            count += BATCH;
        }
        std::hint::black_box(sink);
        (count, t.elapsed().as_secs_f64())
    };
    let batched = |seed: u64| {
        in_blocks(seed, &|draws, _, out| {
            sampler.sample_many(m.as_ref(), draws, out)
        })
    };
    let batched_samples_per_second = on_speed_threads(batched);
    let samples_per_second = time(&with_eval);
    let sampler_only_per_second = time(&|v, u, _| {
        sampler
            .sample(&Lambert, &a, None, v, u)
            .map_or(0.0, |s| s.pdf)
    });
    let evals_per_second = time(&|v, u, _| {
        let z = u[0].max(1e-3);
        let r = (1.0 - z * z).sqrt();
        let l = Local {
            t: r * (TAU * u[1]).cos(),
            b: r * (TAU * u[1]).sin(),
            n: z,
        };
        m.basis(&DirectionPair { l, v: *v }).specular
    });
    let instances = sampler.instances_given(heights.is_some());
    let (mut instance_samples_per_second, mut instance_batched_per_second) = (None, None);
    let (mut instance_variance_ratio, mut instance_albedo_z) = (None, None);
    if instances > 1 {
        let aligned = model::build_instance(id, p)?;
        let aligned = aligned.as_ref();
        let with_instance = |v: &Local, u: [f64; 2], r: f64| {
            let inst = sampler.instance(r, height(r));
            sampler
                .sample_instance(aligned, &a, &inst, v, u)
                .map_or(0.0, |s| s.weight[0])
        };
        instance_samples_per_second = Some(on_speed_threads(|seed| run(seed, &with_instance)));
        let batched = |seed: u64| {
            in_blocks(seed, &|draws, rs, out| {
                let insts: Vec<Instance> = draws
                    .iter()
                    .zip(rs)
                    .map(|(d, &r)| sampler.instance(r, d.height))
                    .collect();
                sampler.sample_many_instances(aligned, draws, &insts, out)
            })
        };
        instance_batched_per_second = Some(on_speed_threads(batched));
        // the price in variance, and a check of the mean, view by view (the exact sampler's
        // draws are the cost: a tenth of the variance study's)
        let n = (samples_for(id, quick) / 10).max(2_000);
        let (mut log_ratio, mut z_max) = (0.0, 0.0f64);
        for (k, v) in views.iter().enumerate() {
            let mut u = Uniforms::new(100 + k as u64);
            let (exact, var_exact) = moments(n, || {
                sampler
                    .sample(m.as_ref(), &a, height(u.next()), v, [u.next(), u.next()])
                    .map_or(0.0, |s| s.weight[0])
            });
            let mut u = Uniforms::new(200 + k as u64);
            let (mean, var) = moments(n, || {
                let r = u.next();
                with_instance(v, [u.next(), u.next()], r)
            });
            log_ratio += (var / var_exact).ln();
            z_max = z_max.max((mean - exact).abs() / ((var + var_exact) / n as f64).sqrt());
        }
        instance_variance_ratio = Some((log_ratio / views.len() as f64).exp());
        instance_albedo_z = Some(z_max);
    }
    Ok(SpeedRow {
        rung: id.to_string(),
        variant: variant.to_string(),
        samples_per_second,
        sampler_only_per_second,
        evals_per_second,
        construct_ms,
        parallel_samples_per_second,
        batched_samples_per_second,
        instances,
        instance_samples_per_second,
        instance_batched_per_second,
        instance_variance_ratio,
        instance_albedo_z,
    })
}

/// The whole study. `quick`: a tenth of the samples and shorter timings.
pub fn run(quick: bool, bar: &ProgressBar) -> Result<SamplingRun> {
    let e = 1000.0;
    let jobs = variance_jobs(e);
    bar.set_length((jobs.len() + 2 * 5 * 3 + 2 * 4 * 3 + 11) as u64);
    let variance = run_jobs(&jobs, quick, bar)?;
    let (width_jobs, exponent_jobs) = sweep_jobs(e);
    let widths = run_jobs(&width_jobs, quick, bar)?;
    let exponents = run_jobs(&exponent_jobs, quick, bar)?;
    let speed = speed_rows(e, quick, bar)?;
    Ok(SamplingRun {
        variance,
        widths,
        exponents,
        speed,
        quick,
    })
}

/// One row of a variance study: a rung at an exponent, a lobe width and a view, with its seed.
#[derive(Clone, Copy)]
struct Job {
    id: ModelId,
    exponent: f64,
    lobe_width: f64,
    view: (f64, f64),
    seed: u64,
}

/// The variance table's rows: every rung x every view at exponent `e` and the default lobe
/// width, one seed per row.
fn variance_jobs(e: f64) -> Vec<Job> {
    ModelId::ALL
        .iter()
        .enumerate()
        .flat_map(|(i, &id)| {
            VIEWS.iter().enumerate().map(move |(j, &v)| Job {
                id,
                exponent: e,
                lobe_width: LOBE_WIDTH,
                view: v,
                seed: 1000 + 100 * i as u64 + j as u64,
            })
        })
        // the reference's values cost ~10 ms each, too many for a cosine estimate that must
        // hit a 1/sqrt(1000) lobe often enough; its sampler is varying-topology's (same table,
        // same lobe) and its model is varying-topology's to the quadrature error
        .filter(|job| job.id.rung().cost != Cost::Adaptive)
        .collect()
}

/// The sweeps of max-normal and poulin-fournier at three views: the lobe width around its
/// default (at exponent `e`), and the exponent at the default width.
fn sweep_jobs(e: f64) -> (Vec<Job>, Vec<Job>) {
    let width_views = [(30.0, 0.0), (60.0, 45.0), (80.0, 0.0)];
    let mut width_jobs = Vec::new();
    let mut exponent_jobs = Vec::new();
    for (i, id) in [ModelId::MaxNormal, ModelId::PoulinFournier]
        .into_iter()
        .enumerate()
    {
        for (k, c) in [0.25, 0.5, LOBE_WIDTH, 1.0, 2.0].into_iter().enumerate() {
            for (j, &v) in width_views.iter().enumerate() {
                width_jobs.push(Job {
                    id,
                    exponent: e,
                    lobe_width: c,
                    view: v,
                    seed: 5000 + 100 * i as u64 + 10 * k as u64 + j as u64,
                });
            }
        }
        for (k, ex) in [10.0, 100.0, 1000.0, 10000.0].into_iter().enumerate() {
            for (j, &v) in width_views.iter().enumerate() {
                exponent_jobs.push(Job {
                    id,
                    exponent: ex,
                    lobe_width: LOBE_WIDTH,
                    view: v,
                    seed: 7000 + 100 * i as u64 + 10 * k as u64 + j as u64,
                });
            }
        }
    }
    (width_jobs, exponent_jobs)
}

/// The variance rows of `jobs`, in parallel.
fn run_jobs(jobs: &[Job], quick: bool, bar: &ProgressBar) -> Result<Vec<VarianceRow>> {
    jobs.par_iter()
        .map(|job| {
            let id = job.id;
            let p = params(id, &params_text(id, job.exponent))?;
            let row = variance_row(
                id,
                &p,
                job.lobe_width,
                job.view,
                samples_for(id, quick),
                job.seed,
            );
            bar.inc(1);
            row
        })
        .collect::<Result<Vec<_>>>()
}

/// The speed table's variants with optional components: (rung, variant, parameter lines added
/// to the rung's example). `cargo bench --bench sampling` times the same ones.
pub const SPEED_VARIANTS: [(ModelId, &str, &str); 7] = [
    (ModelId::MaxNormal, "spread 180", "azimuth_spread_deg = 180\n"),
    (ModelId::PoulinFournier, "spread 180", "azimuth_spread_deg = 180\n"),
    (ModelId::PoulinFournier, "spread 20", "azimuth_spread_deg = 20\n"),
    (
        ModelId::PoulinFournier,
        "fuzz + fresnel",
        "fuzz = 0.5\nfuzz_depth = 0.3\nfresnel_ior = 1.5\n",
    ),
    (
        ModelId::PoulinFournier,
        "spread 180 + fuzz (felt)",
        "azimuth_spread_deg = 180\nfuzz = 0.5\nfuzz_depth = 0.3\n",
    ),
    (ModelId::VaryingTopology, HEIGHT_PER_DRAW, ""),
    (
        ModelId::VaryingTopology,
        "spread 30 + fuzz",
        "azimuth_spread_deg = 30\nfuzz = 0.5\nfuzz_depth = 0.3\n",
    ),
];

/// The variant drawn at a height per sample, as a per-texel height map does.
pub const HEIGHT_PER_DRAW: &str = "a height per draw (maps)";

/// Samples per second of every rung at exponent `e`, then of variants with the optional
/// components: one thread, one rung after another.
fn speed_rows(e: f64, quick: bool, bar: &ProgressBar) -> Result<Vec<SpeedRow>> {
    let budget = if quick { 0.05 } else { 0.5 };
    let mut speed = Vec::new();
    for id in ModelId::ALL {
        let budget = if id.rung().cost == Cost::Adaptive {
            budget * 4.0
        } else {
            budget
        };
        speed.push(speed_row(
            id,
            "-",
            &params(id, &params_text(id, e))?,
            None,
            budget,
            quick,
        )?);
        bar.inc(1);
    }
    for &(id, variant, extra) in &SPEED_VARIANTS {
        let text = params_text(id, e) + extra;
        let p = params(id, &text)?;
        // a per-texel height map: every draw at its own height over the whole range
        let top = crate::model::topology::max_height(p.spacing);
        let heights = (variant == HEIGHT_PER_DRAW).then_some((0.0, top));
        speed.push(speed_row(id, variant, &p, heights, budget, quick)?);
        bar.inc(1);
    }
    Ok(speed)
}

/// Whether the sampler's weight is constant in `r` (zero variance up to rounding).
pub fn is_exact(r: &VarianceRow) -> bool {
    r.variance_sampled <= 1e-24 * r.albedo_sampled * r.albedo_sampled
}

/// One rung's summary over its views.
pub struct Summary {
    pub rung: String,
    pub views: usize,
    /// Every view's weight constant (the ratios are then infinite or undefined).
    pub exact: bool,
    pub least: f64,
    pub geometric_mean: f64,
}

/// Per rung: the views, the least and the geometric-mean variance ratio of `rows`.
pub fn summary(rows: &[VarianceRow]) -> Vec<Summary> {
    let mut out = Vec::new();
    for id in ModelId::ALL {
        let rs: Vec<&VarianceRow> = rows.iter().filter(|r| r.rung == id.as_str()).collect();
        if rs.is_empty() {
            continue;
        }
        let least = rs.iter().map(|r| r.ratio).fold(f64::INFINITY, f64::min);
        let geometric_mean = (rs.iter().map(|r| r.ratio.ln()).sum::<f64>() / rs.len() as f64).exp();
        out.push(Summary {
            rung: id.to_string(),
            views: rs.len(),
            exact: rs.iter().all(|r| is_exact(r)),
            least,
            geometric_mean,
        });
    }
    out
}
