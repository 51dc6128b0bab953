//! `fibrefit bench`: measure the speed–accuracy trade and write a report.

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, Args)]
#[command(after_help = "\
STUDIES (each writes its tables, CSV and plots into OUT and says the command that made them):
  speed        (the default) every rung's and knob's cost and error against `reference`:
               OUT/speed_accuracy.md, _forward.csv, _fit.csv, pareto.png, fit_time_vs_error.png;
               the fit level uses ROOT/data_synthetic/silk and ROOT/configs/fit_silk.toml
  robustness   how often the default fit finds the global minimum (OUT/fit_robustness.*)
  felt FILE    every rung on a real measured felt (OUT/felt.*)
  maps         per-texel map recovery on synthetic captures (OUT/maps_accuracy.*)
  camera [N]   captures at camera resolution, 8 images x N x N (OUT/camera_resolution.*)
  photos       `calibrate` on 12 synthetic photos of 12 Mpx, JPEG and RAW: time and memory (OUT/photo_speed.*)
  shader       the exported shader's cost per rung on this machine's GPU driver (OUT/shader_cost.*)
  sampling     the importance sampler against cosine sampling (OUT/sampling.*)
  selection FILE  `--model auto` on sparse subsets of a felt and on synthetic fabrics
               (OUT/selection.*)
  real FILE... [--curet DIR]  real fabrics against their floor, what their data allow
               (OUT/real_fabrics.*)
  renderers [FILE...]  each renderer's route (exact model, Blender's principled, glTF, Ward, the
               old glTF conversion) against the data (OUT/renderers.*)
`fibrefit bench STUDY --help` gives each study's options.")]
pub struct BenchArgs {
    /// The study (default: speed)
    #[command(subcommand)]
    pub study: Option<Study>,
    /// Fewer directions, repeats, fractions and orders: finishes in well under a minute
    #[arg(long, global = true)]
    pub quick: bool,
    /// Output directory
    #[arg(long, value_name = "DIR", default_value = "reports", global = true)]
    pub out: PathBuf,
    /// Repository root holding data_synthetic/ and configs/
    #[arg(long, value_name = "DIR", default_value = ".", global = true)]
    pub root: PathBuf,
    /// No progress bar
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// The options of the studies before they were subcommands (`--robustness`, `--felt FILE`,
    /// ...): still accepted, not shown
    #[command(flatten)]
    pub legacy: Legacy,
}

/// One study of `fibrefit bench`.
#[derive(Debug, Clone, Subcommand)]
pub enum Study {
    /// Every rung's and knob's cost and error against `reference` (the default)
    Speed,
    /// The fit robustness study (hard synthetic truths x noise seeds, random starts): writes
    /// OUT/fit_robustness.md, .csv and .png
    Robustness(RobustnessArgs),
    /// The real-felt comparison on a measured file (every rung, aligned and with the
    /// fibre-direction spread, linear and log metric): writes OUT/felt.md, .csv and .png
    Felt(FeltArgs),
    /// The per-texel map recovery study (synthetic captures with known maps, shrinking
    /// light/view sets): writes OUT/maps_accuracy.md, .csv and .png
    Maps,
    /// Captures at camera resolution (a synthetic RGB capture of 8 images x N x N pixels; the
    /// global fit and maps + globals run as `fibrefit fit` child processes, their wall time, CPU
    /// time and peak memory measured): writes OUT/camera_resolution.md and .csv
    Camera {
        /// Image size N (pixels per side)
        #[arg(value_name = "N", default_value_t = 1024)]
        size: usize,
        /// Further sizes at which map recovery with pinhole cameras and point lights is timed
        /// against orthographic cameras, side by side (N itself always is)
        #[arg(long, value_name = "N,...", value_delimiter = ',', default_values_t = [160, 512])]
        ratio_sizes: Vec<usize>,
    },
    /// The photo route's speed and memory: `fibrefit calibrate` on synthetic JPEG photos of
    /// the board (a child process; wall time, CPU time, peak memory): writes OUT/photo_speed.md
    /// and .csv
    Photos {
        /// Photos
        #[arg(long, default_value_t = 12)]
        count: usize,
        /// Pixels across each photo (4:3; 4000 = 12 Mpx)
        #[arg(long, default_value_t = 4000)]
        width: u32,
    },
    /// Previews per rung: `fibrefit render` of a 512 x 512 torus with supersample 2, adaptive
    /// shading against every subsample shaded, side by side (median wall time, the pictures'
    /// difference): writes OUT/render_speed.md and .csv
    Render,
    /// The exported shader's cost per rung (evaluations per second on this machine's GPU
    /// driver against the Rust model on the CPU, SPIR-V instruction counts): writes
    /// OUT/shader_cost.md and .csv
    Shader,
    /// The importance sampler's variance against cosine sampling per rung and view (exponent
    /// 1000, the lobe width swept, other exponents) and its samples per second: writes
    /// OUT/sampling.md and .csv
    Sampling,
    /// `--model auto` on sparse subsets of a measured felt (--sizes) and on synthetic fabrics
    /// with known truth (--synth-sizes): every candidate's cross-validated error, the choice,
    /// the run's wall time: writes OUT/selection.md and .csv
    Selection(SelectionArgs),
    /// Real fabrics against what their data allow: each file (and each sample of a CUReT
    /// folder) fitted with `--model auto --metric log`, every candidate's held-out error, the
    /// floor and the chosen model's ratio to it, where its excess lies, the better simple fit
    /// (lambert, ward), the time: writes OUT/real_fabrics.md, .csv and the first measured
    /// file's residual hemisphere maps
    Real(RealArgs),
    /// Each route a renderer takes against the data: `--model auto --metric log` on each file
    /// (default: the shipped felt, silk and brushed sets), the choice (exact: Mitsuba plugin,
    /// shader), principled (Blender), openpbr (MaterialX / USD), gltf, ward held out, the old glTF conversion of the
    /// choice on every sample, each renderer rung's fit time: writes OUT/renderers.md and .csv
    Renderers(RenderersArgs),
}

#[derive(Debug, Clone, Args)]
pub struct RenderersArgs {
    /// Measurements (measured .bsdf/MERL files, goniometric tables) [default: ROOT's
    /// tests/data/rgl/acrylic_felt_green_rgb.bsdf, data_synthetic/silk/gonio.csv and
    /// data_synthetic/brushed/gonio.csv]
    #[arg(value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Direction pairs drawn from each measured file
    #[arg(long, value_name = "N", default_value_t = 3000)]
    pub directions: usize,
}

#[derive(Debug, Clone, Args)]
pub struct RealArgs {
    /// Real measurements fibrefit reads (measured .bsdf/MERL files, goniometric tables)
    #[arg(value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// A CUReT folder (table.txt and abrdf_subset.dat): each of its samples is a data set
    #[arg(long, value_name = "DIR")]
    pub curet: Option<PathBuf>,
    /// Direction pairs drawn from each measured file
    #[arg(long, value_name = "N", default_value_t = 3000)]
    pub directions: usize,
}

#[derive(Debug, Clone, Args)]
pub struct RobustnessArgs {
    /// Noise seeds per case
    #[arg(long, value_name = "N", default_value_t = 20)]
    pub seeds: u64,
    /// Goniometric samples per dataset
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub samples: usize,
    /// Only these cases (comma-separated names)
    #[arg(long, value_name = "NAMES", value_delimiter = ',')]
    pub cases: Vec<String>,
}

#[derive(Debug, Clone, Args)]
pub struct FeltArgs {
    /// The measured felt (.bsdf)
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Direction pairs drawn from it
    #[arg(long, value_name = "N", default_value_t = 3000)]
    pub directions: usize,
}

#[derive(Debug, Clone, Args)]
pub struct SelectionArgs {
    /// The measured felt (.bsdf)
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Felt direction pairs (comma-separated)
    #[arg(long, value_name = "N,..", value_delimiter = ',', default_values_t = [200, 500, 3000])]
    pub sizes: Vec<usize>,
    /// Samples of the synthetic fabrics (comma-separated; none: skip them)
    #[arg(long, value_name = "N,..", value_delimiter = ',', default_values_t = [200, 500, 3000])]
    pub synth_sizes: Vec<usize>,
    /// Also measure every candidate at the config's knobs (the slow path), side by side with
    /// the default coarse ranking
    #[arg(long)]
    pub slow: bool,
}

/// The studies' options as flags of `bench` itself (before the subcommands), hidden.
#[derive(Debug, Default, Args)]
pub struct Legacy {
    #[arg(long, hide = true)]
    pub robustness: bool,
    #[arg(long, value_name = "N", default_value_t = 20, hide = true)]
    pub seeds: u64,
    #[arg(long, value_name = "N", default_value_t = 1000, hide = true)]
    pub samples: usize,
    #[arg(long, value_name = "FILE", hide = true)]
    pub felt: Option<PathBuf>,
    #[arg(long, value_name = "N", default_value_t = 3000, hide = true)]
    pub directions: usize,
    #[arg(long, hide = true)]
    pub maps: bool,
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "1024", hide = true)]
    pub camera: Option<usize>,
    #[arg(long, hide = true)]
    pub shader: bool,
    #[arg(long, hide = true)]
    pub sampling: bool,
    #[arg(long, value_name = "FILE", hide = true)]
    pub selection: Option<PathBuf>,
    #[arg(long, value_name = "N,..", value_delimiter = ',', default_values_t = [200, 500, 3000], hide = true)]
    pub sizes: Vec<usize>,
    #[arg(long, value_name = "N,..", value_delimiter = ',', default_values_t = [200, 500, 3000], hide = true)]
    pub synth_sizes: Vec<usize>,
    #[arg(long, hide = true)]
    pub slow: bool,
    #[arg(long, value_name = "NAMES", value_delimiter = ',', hide = true)]
    pub cases: Vec<String>,
}

impl Legacy {
    /// The study the legacy flags ask for (speed when none).
    fn study(&self) -> Study {
        if self.robustness {
            Study::Robustness(RobustnessArgs {
                seeds: self.seeds,
                samples: self.samples,
                cases: self.cases.clone(),
            })
        } else if self.sampling {
            Study::Sampling
        } else if let Some(size) = self.camera {
            Study::Camera {
                size,
                ratio_sizes: vec![160, 512],
            }
        } else if self.shader {
            Study::Shader
        } else if self.maps {
            Study::Maps
        } else if let Some(file) = &self.selection {
            Study::Selection(SelectionArgs {
                file: file.clone(),
                sizes: self.sizes.clone(),
                synth_sizes: self.synth_sizes.clone(),
                slow: self.slow,
            })
        } else if let Some(file) = &self.felt {
            Study::Felt(FeltArgs {
                file: file.clone(),
                directions: self.directions,
            })
        } else {
            Study::Speed
        }
    }
}

fn robustness(args: &BenchArgs, r: &RobustnessArgs) -> Result<()> {
    use crate::bench::robustness::{self as study, StudySize, CASES};
    let cases: Vec<study::Case> = CASES
        .iter()
        .filter(|c| r.cases.is_empty() || r.cases.iter().any(|n| n == c.name))
        .copied()
        .collect();
    if cases.is_empty() {
        let names: Vec<&str> = CASES.iter().map(|c| c.name).collect();
        bail!("--cases: no such case; the cases are {}", names.join(", "));
    }
    let size = StudySize {
        samples: r.samples,
        seeds: r.seeds,
    };
    let t = Instant::now();
    let bar = crate::progress::Progress::new(args.quiet).bar(cases.len() as u64 * r.seeds, "robustness");
    let scratch = tempfile::tempdir()?;
    let runs = study::run(&cases, size, scratch.path(), &bar)?;
    bar.finish_and_clear();
    let mut command = format!(
        "fibrefit bench robustness --seeds {} --samples {}",
        r.seeds, r.samples
    );
    if !r.cases.is_empty() {
        command += &format!(" --cases {}", r.cases.join(","));
    }
    crate::bench::report::robustness::write(
        &args.out,
        &runs,
        size,
        &command,
        t.elapsed().as_secs_f64(),
    )?;
    if !args.quiet {
        for (name, n, ok, med, worst) in study::summary(&runs) {
            eprintln!("{name:<12} {ok:>3}/{n:<3} median {med:.2} s, worst excess {worst:.2} sd");
        }
        eprintln!("wrote {}", args.out.join("fit_robustness.md").display());
    }
    Ok(())
}

fn sampling(args: &BenchArgs) -> Result<()> {
    let t = Instant::now();
    let bar = crate::progress::Progress::new(args.quiet).bar(1, "sampling");
    let run = crate::bench::sampling::run(args.quick, &bar)?;
    bar.finish_and_clear();
    let command = if args.quick {
        "fibrefit bench sampling --quick"
    } else {
        "fibrefit bench sampling"
    };
    crate::bench::report::sampling::write(&args.out, &run, command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        for r in crate::bench::sampling::summary(&run.variance) {
            if r.exact {
                eprintln!(
                    "{:<17} {:>2} views: exact (a constant weight)",
                    r.rung, r.views
                );
            } else {
                eprintln!(
                    "{:<17} {:>2} views: variance ratio against cosine sampling least {:.2}, \
                     geometric mean {:.2}",
                    r.rung, r.views, r.least, r.geometric_mean
                );
            }
        }
        eprintln!("wrote {}", args.out.join("sampling.md").display());
    }
    Ok(())
}

pub fn run(args: &BenchArgs) -> Result<()> {
    let study = args.study.clone().unwrap_or_else(|| args.legacy.study());
    match study {
        Study::Speed => speed(args),
        Study::Robustness(r) => robustness(args, &r),
        Study::Sampling => sampling(args),
        Study::Camera { size, ratio_sizes } => camera(args, size, &ratio_sizes),
        Study::Shader => shader(args),
        Study::Photos { count, width } => photos(args, count, width),
        Study::Render => render(args),
        Study::Maps => maps(args),
        Study::Selection(sel) => selection(args, &sel),
        Study::Felt(f) => felt(args, &f),
        Study::Real(r) => real(args, &r),
        Study::Renderers(r) => renderers(args, &r),
    }
}

fn camera(args: &BenchArgs, size: usize, ratio_sizes: &[usize]) -> Result<()> {
    if let Some(s) = std::iter::once(&size).chain(ratio_sizes).find(|&&s| s < 8) {
        bail!("bench camera: size {s}: the capture needs at least 8 x 8 pixels");
    }
    let t = Instant::now();
    let bar = crate::progress::Progress::new(args.quiet).bar(3, "camera");
    let scratch = tempfile::tempdir()?;
    let exe = std::env::current_exe()?;
    let mut run = crate::bench::camera::run(&exe, scratch.path(), size, &bar)?;
    for &n in ratio_sizes.iter().filter(|&&n| n != size) {
        bar.set_message(format!("camera: pinhole against orthographic at {n} x {n}"));
        run.ratios
            .push(crate::bench::camera::size_ratio(&exe, scratch.path(), n)?);
    }
    bar.finish_and_clear();
    let command = match (size, ratio_sizes) {
        (1024, [160, 512]) => "fibrefit bench camera".to_string(),
        (n, [160, 512]) => format!("fibrefit bench camera {n}"),
        (n, r) => format!(
            "fibrefit bench camera {n} --ratio-sizes {}",
            r.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(",")
        ),
    };
    crate::bench::report::camera::write(&args.out, &run, &command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        for r in &run.rows {
            eprintln!(
                "{}: {:.1} s wall, {:.1} s CPU, {:.0} MB peak ({})",
                r.job,
                r.wall_seconds,
                r.cpu_seconds,
                r.peak_mb,
                if r.met { "goal met" } else { "GOAL MISSED" }
            );
        }
        eprintln!("wrote {}", args.out.join("camera_resolution.md").display());
    }
    Ok(())
}

fn render(args: &BenchArgs) -> Result<()> {
    let (size, repeats) = if args.quick { (128, 1) } else { (512, 3) };
    let t = Instant::now();
    let progress = crate::progress::Progress::new(args.quiet);
    let scratch = tempfile::tempdir()?;
    let run = crate::bench::render::run(scratch.path(), size, repeats, &progress)?;
    let command = match args.quick {
        true => "fibrefit bench render --quick",
        false => "fibrefit bench render",
    };
    crate::bench::render::write(&args.out, &run, command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        for r in &run.rows {
            eprintln!(
                "{}: {:.2} s adaptive, {:.2} s every subsample; largest difference {:.1e} of the level, {} PNG codes",
                r.name, r.adaptive_s, r.every_s, r.max_rel_level, r.max_codes
            );
        }
        eprintln!("wrote {}", args.out.join("render_speed.md").display());
    }
    Ok(())
}

fn photos(args: &BenchArgs, count: usize, width: u32) -> Result<()> {
    let (count, width) = if args.quick { (4, 1600) } else { (count, width) };
    if !(3..=64).contains(&count) || !(400..=12000).contains(&width) {
        bail!("bench photos --count {count} --width {width}: expected 3 to 64 photos, 400 to 12000 px");
    }
    let t = Instant::now();
    let progress = crate::progress::Progress::new(args.quiet);
    let scratch = tempfile::tempdir()?;
    let exe = std::env::current_exe()?;
    let runs = crate::bench::photos::run(&exe, scratch.path(), count, width, &progress)?;
    let command = match (args.quick, count, width) {
        (true, ..) => "fibrefit bench photos --quick".to_string(),
        (false, 12, 4000) => "fibrefit bench photos".to_string(),
        _ => format!("fibrefit bench photos --count {count} --width {width}"),
    };
    crate::bench::photos::write(&args.out, &runs, &command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        for run in &runs {
            eprintln!(
                "calibrate, {count} {} photos of {}x{}: {:.1} s wall, {:.1} s CPU, {:.0} MB peak",
                run.format,
                run.size_px[0],
                run.size_px[1],
                run.cost.wall_seconds,
                run.cost.cpu_seconds,
                run.cost.peak_mb,
            );
        }
        eprintln!("wrote {}", args.out.join("photo_speed.md").display());
    }
    Ok(())
}

fn shader(args: &BenchArgs) -> Result<()> {
    let t = Instant::now();
    let bar = crate::progress::Progress::new(args.quiet).bar(crate::bench::shader::RUNGS.len() as u64,
        "shader");
    let (pairs, min_pairs, repeats) = if args.quick {
        (4096, 256, 3)
    } else {
        (262_144, 2048, 5)
    };
    let run = crate::bench::shader::run(pairs, min_pairs, repeats, &bar)?;
    bar.finish_and_clear();
    let command = if args.quick {
        "fibrefit bench shader --quick"
    } else {
        "fibrefit bench shader"
    };
    crate::bench::report::shader::write(&args.out, &run, command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        for r in &run.rows {
            eprintln!(
                "{}: shader {:.3e} evals/s, Rust {:.3e} (all threads): ratio {:.2}",
                r.rung,
                r.gpu_evals_per_second,
                r.cpu_all_threads_evals_per_second,
                r.ratio_gpu_to_cpu
            );
        }
        eprintln!("wrote {}", args.out.join("shader_cost.md").display());
    }
    Ok(())
}

fn maps(args: &BenchArgs) -> Result<()> {
    let t = Instant::now();
    let bar = crate::progress::Progress::new(args.quiet).bar(crate::bench::maps::cases().len() as u64, "maps");
    let scratch = tempfile::tempdir()?;
    let (rows, pictures) = crate::bench::maps::run(scratch.path(), &bar)?;
    bar.finish_and_clear();
    crate::bench::report::maps::write(
        &args.out,
        &rows,
        &pictures,
        "fibrefit bench maps",
        t.elapsed().as_secs_f64(),
    )?;
    if !args.quiet {
        eprintln!("wrote {}", args.out.join("maps_accuracy.md").display());
    }
    Ok(())
}

fn selection(args: &BenchArgs, sel: &SelectionArgs) -> Result<()> {
    let file = &sel.file;
    let t = Instant::now();
    let synth: Vec<usize> = sel.synth_sizes.iter().copied().filter(|&n| n > 0).collect();
    let rows = crate::bench::selection::run(
        Some(file),
        &sel.sizes,
        &synth,
        sel.slow,
        &crate::progress::Progress::new(args.quiet),
    )?;
    let list = |v: &[usize]| {
        v.iter()
            .map(|n| n.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    let command = format!(
        "fibrefit bench selection {} --sizes {} --synth-sizes {}{}",
        file.display(),
        list(&sel.sizes),
        match synth.is_empty() {
            true => "0".to_string(),
            false => list(&synth),
        },
        if sel.slow { " --slow" } else { "" }
    );
    crate::bench::report::selection::write(&args.out, &rows, &command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        for r in &rows {
            eprintln!(
                "{} {} ({}): chose {} in {:.1} s",
                r.data, r.samples, r.path, r.chosen, r.seconds
            );
        }
        eprintln!("wrote {}", args.out.join("selection.md").display());
    }
    Ok(())
}

fn felt(args: &BenchArgs, f: &FeltArgs) -> Result<()> {
    let file = &f.file;
    let t = Instant::now();
    let bar = crate::progress::Progress::new(args.quiet).bar(crate::bench::felt::fit_count(), "felt");
    let run = crate::bench::felt::run(file, f.directions, &bar)?;
    bar.finish_and_clear();
    let command = format!(
        "fibrefit bench felt {} --directions {}",
        file.display(),
        f.directions
    );
    let measured = crate::load::measured_brdf(file)?;
    crate::bench::report::felt::write(
        &args.out,
        &run,
        measured.as_deref(),
        &command,
        t.elapsed().as_secs_f64(),
    )?;
    if !args.quiet {
        eprintln!("wrote {}", args.out.join("felt.md").display());
    }
    Ok(())
}

fn real(args: &BenchArgs, r: &RealArgs) -> Result<()> {
    if r.files.is_empty() && r.curet.is_none() {
        bail!("bench real: give at least one FILE or --curet DIR");
    }
    let t = Instant::now();
    let run = crate::bench::real::run(
        &r.files,
        r.curet.as_deref(),
        r.directions,
        &crate::progress::Progress::new(args.quiet),
    )?;
    let mut command = String::from("fibrefit bench real");
    for f in &r.files {
        command += &format!(" {}", f.display());
    }
    if let Some(d) = &r.curet {
        command += &format!(" --curet {}", d.display());
    }
    command += &format!(" --directions {}", r.directions);
    let measured = match &run.drawn {
        Some((i, ..)) => crate::load::measured_brdf(&run.rows[*i].source)?,
        None => None,
    };
    crate::bench::report::real::write(
        &args.out,
        &run,
        measured.as_deref(),
        &command,
        t.elapsed().as_secs_f64(),
    )?;
    if !args.quiet {
        eprintln!("wrote {}", args.out.join("real_fabrics.md").display());
    }
    Ok(())
}

fn renderers(args: &BenchArgs, r: &RenderersArgs) -> Result<()> {
    let t = Instant::now();
    let files = match r.files.is_empty() {
        true => crate::bench::renderers::default_files(&args.root),
        false => r.files.clone(),
    };
    let rows = crate::bench::renderers::run(
        &files,
        r.directions,
        &crate::progress::Progress::new(args.quiet),
    )?;
    let mut command = String::from("fibrefit bench renderers");
    for f in &r.files {
        command += &format!(" {}", f.display());
    }
    command += &format!(" --directions {}", r.directions);
    crate::bench::report::renderers::write(&args.out, &rows, &command, t.elapsed().as_secs_f64())?;
    if !args.quiet {
        eprintln!("wrote {}", args.out.join("renderers.md").display());
    }
    Ok(())
}

fn speed(args: &BenchArgs) -> Result<()> {
    if !args.root.join("data_synthetic/silk/capture.toml").exists() {
        bail!(
            "{}: no data_synthetic/silk/capture.toml here; run from the repository root or pass --root",
            args.root.display()
        );
    }
    let t = Instant::now();
    let fits = if args.quick { 4 } else { 9 };
    let bar = crate::progress::Progress::new(args.quiet).bar((crate::bench::SETS.len() * 3 + fits) as u64,
        "bench");
    let forward = crate::bench::forward(args.quick, &bar)?;
    let fit = crate::bench::fit_level(&args.root, args.quick, &bar)?;
    bar.finish_and_clear();
    crate::bench::report::speed::write(
        &args.out,
        &forward,
        &fit,
        args.quick,
        t.elapsed().as_secs_f64(),
    )?;
    if !args.quiet {
        eprintln!(
            "wrote {} in {:.1} s",
            args.out.join("speed_accuracy.md").display(),
            t.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
