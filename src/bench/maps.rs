//! `fibrefit bench maps`: the accuracy of per-texel map recovery on synthetic captures whose
//! maps are known (32 x 32 texels, varying-topology at d = 2, H from a topology map in
//! [0.3, 1.5], psi from -30 to 40 deg across the swatch, 1 % noise): RMS error of H and psi
//! against the truth and against the reported standard errors, and the coverage (texels whose
//! truth lies within 3 standard errors), as the light/view set shrinks, for a set that leaves H
//! undetermined, and near the normal (48 x 48, every light and view within 15 deg), where the
//! globals trade off with the maps.

use crate::fit::config::FitConfig;
use crate::fit::maps::{self, TexelMaps};
use crate::load::capture_store::CaptureStore;
use crate::model::topology::TopologyMap;
use anyhow::Result;
use indicatif::ProgressBar;
use std::path::Path;
use std::time::Instant;

/// (light theta, phi; camera theta, phi) in degrees of every image the cases draw from.
pub const EIGHT_IMAGES: [[f64; 4]; 8] = [
    [30.0, 110.0, 0.0, 0.0],
    [60.0, 100.0, 30.0, 290.0],
    [45.0, 20.0, 45.0, 200.0],
    [70.0, 300.0, 20.0, 110.0],
    [50.0, 180.0, 50.0, 0.0],
    [20.0, 200.0, 60.0, 20.0],
    [65.0, 240.0, 40.0, 60.0],
    [40.0, 330.0, 55.0, 150.0],
];

/// Near-normal light and view only (every one within 15 deg of the normal): the height barely
/// changes what a camera sees, and the globals trade off with the maps.
pub const NEAR_NORMAL_IMAGES: [[f64; 4]; 6] = [
    [5.0, 0.0, 0.0, 0.0],
    [15.0, 90.0, 10.0, 270.0],
    [15.0, 180.0, 10.0, 0.0],
    [15.0, 270.0, 10.0, 90.0],
    [12.0, 45.0, 12.0, 225.0],
    [12.0, 135.0, 12.0, 315.0],
];

pub struct Case {
    pub name: &'static str,
    pub what: &'static str,
    pub images: Vec<[f64; 4]>,
    /// Texels per side.
    pub size: usize,
}

pub fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "8 images",
            what: "lights 20-70 deg from 8 azimuths, views 0-60 deg",
            images: EIGHT_IMAGES.to_vec(),
            size: SIZE,
        },
        Case {
            name: "6 images",
            what: "the first 6 of those",
            images: EIGHT_IMAGES[..6].to_vec(),
            size: SIZE,
        },
        Case {
            name: "4 images",
            what: "the first 4",
            images: EIGHT_IMAGES[..4].to_vec(),
            size: SIZE,
        },
        Case {
            name: "3 images",
            what: "the first 3",
            images: EIGHT_IMAGES[..3].to_vec(),
            size: SIZE,
        },
        Case {
            name: "near normal",
            what: "6 images, every light and view within 15 deg of the normal, 48 x 48 texels",
            images: NEAR_NORMAL_IMAGES.to_vec(),
            size: 48,
        },
    ]
}

/// Texels per side of the cases but the near-normal one (and of the figure).
pub const SIZE: usize = 32;

/// The synth config of a `size` x `size` capture from `images` ((light theta, phi; camera theta,
/// phi) in degrees), its maps known (tests/maps_errors.rs uses it too).
pub fn synth_config(images: &[[f64; 4]], size: usize) -> String {
    let mut s = format!(
        "model = \"varying-topology\"\n[params]\nkd = 0.4\nks = 0.3\nexponent = 40\nspacing = 2.0\n\
         height = 0.9\nmap_scale = 0.6\nfibre_azimuth_deg = 0\n[topology_map]\nwidth = {size}\nheight = {size}\nseed = 3\n\
         [capture]\nwidth = {size}\nheight = {size}\nsize_mm = [20.0, 20.0]\nformat = \"exr\"\n\
         tangent = {{ from_deg = -30, to_deg = 40 }}\n"
    );
    for im in images {
        s += &format!(
            "[[capture.images]]\nlight = {{ type = \"directional\", theta_deg = {}, phi_deg = {}, irradiance = 1.0 }}\n\
             camera = {{ type = \"orthographic\", theta_deg = {}, phi_deg = {} }}\n",
            im[0], im[1], im[2], im[3]
        );
    }
    s + "[noise]\nrelative = 0.01\nseed = 5\n"
}

/// The maps fit of the cases (H and psi per texel; kd, ks, the exponent global).
pub const FIT: &str = "model = \"varying-topology\"\nmetric = \"linear\"\nseed = 1\n[parameters]\n\
    kd = { value = 0.5 }\nks = { value = 0.2 }\nexponent = { value = 20, min = 1, max = 1000 }\n\
    spacing = { value = 2.0, vary = false }\nheight = { value = 0.8 }\nfibre_azimuth_deg = { value = 0 }\n\
    [maps]\nheight = true\nfibre_azimuth = true\nrounds = 25\n";

#[derive(Clone, Debug, serde::Serialize)]
pub struct MapRow {
    pub case: String,
    pub images: usize,
    /// Texels per side.
    pub size: usize,
    pub rms_error_height: f64,
    pub rms_error_psi_deg: f64,
    /// RMS of error / standard error (1 for honest errors).
    pub rms_z_height: f64,
    pub rms_z_psi: f64,
    pub median_abs_z_height: f64,
    pub median_abs_z_psi: f64,
    /// Fraction of texels within 3 standard errors of the truth.
    pub within_3se_height: f64,
    pub within_3se_psi: f64,
    /// Median standard error of H (fibre radii).
    pub median_std_error_height: f64,
    /// The tool's warnings about undetermined or ambiguous texels, " | "-separated.
    pub warnings: String,
    pub seconds: f64,
}

/// The truth and the recovered maps of the standard case, for the side-by-side figure.
pub struct Pictures {
    pub true_height: Vec<f64>,
    pub height: Vec<f64>,
    pub true_psi: Vec<f64>,
    pub psi: Vec<f64>,
    pub z_height: Vec<f64>,
}

pub(crate) fn stats(err: &[f64], z: &[f64]) -> (f64, f64, f64, f64) {
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let mut a: Vec<f64> = z.iter().map(|x| x.abs()).collect();
    a.sort_by(f64::total_cmp);
    let within = a.iter().filter(|x| **x <= 3.0).count() as f64 / a.len() as f64;
    (rms(err), rms(z), a[a.len() / 2], within)
}

/// `blind.toml` beside a synthetic capture's `capture.toml`: the capture without its topology
/// and tangent maps (what map recovery recovers); returns its path.
pub fn write_blind(capture_dir: &Path) -> Result<std::path::PathBuf> {
    let text = std::fs::read_to_string(capture_dir.join("capture.toml"))?;
    let blind: String = text
        .lines()
        .filter(|l| !l.starts_with("tangent_map") && !l.starts_with("topology_map"))
        .map(|l| format!("{l}\n"))
        .collect();
    let path = capture_dir.join("blind.toml");
    std::fs::write(&path, blind)?;
    Ok(path)
}

/// A case's row, its recovered maps and the true (H, psi) of each texel.
pub type Measured = (MapRow, TexelMaps, Vec<(f64, f64)>);

/// Render `case` into `scratch`, recover its maps and compare them with the truth.
pub fn measure(case: &Case, scratch: &Path) -> Result<Measured> {
    let dir = scratch.join(case.name.replace(' ', "_"));
    std::fs::create_dir_all(&dir)?;
    std::fs::write(
        dir.join("synth.toml"),
        synth_config(&case.images, case.size),
    )?;
    crate::synth::run(&dir.join("synth.toml"), &dir.join("d"), &crate::progress::Progress::quiet())?;
    let store = CaptureStore::load(&write_blind(&dir.join("d"))?, Default::default())?;
    let cfg: FitConfig = toml::from_str(FIT)?;
    let t = Instant::now();
    let o = maps::recover(&store, &cfg, &cfg.maps, &crate::progress::Progress::quiet())?;
    let seconds = t.elapsed().as_secs_f64();
    let topo = TopologyMap::load(&dir.join("d/topology.png"))?;
    let tan = TopologyMap::load_as(&dir.join("d/tangent.png"), "tangent map")?;
    let mut truths = Vec::new();
    let (mut eh, mut ep, mut zh, mut zp, mut seh) = (vec![], vec![], vec![], vec![], vec![]);
    for (k, &(x, y)) in o.maps.texels.iter().enumerate() {
        let (x, y) = (x as usize, y as usize);
        let th = 0.9 + 0.6 * (2.0 * topo.texel(x, y) - 1.0);
        let tp = -90.0 + 180.0 * tan.texel(x, y);
        truths.push((th, tp));
        let v = &o.maps.values[k];
        let e = &o.maps.std_errors[k];
        let dh = v.height - th;
        let dp = crate::fit::wrap_azimuth(v.psi - tp);
        eh.push(dh);
        ep.push(dp);
        zh.push(dh / e.height);
        zp.push(dp / e.psi);
        seh.push(e.height);
    }
    seh.sort_by(f64::total_cmp);
    let (rh, rzh, mzh, wh) = stats(&eh, &zh);
    let (rp, rzp, mzp, wp) = stats(&ep, &zp);
    let mut warnings = o.warnings.clone();
    warnings.retain(|w| {
        w.contains("undetermined") || w.contains("another minimum") || w.contains("trade off")
    });
    // what the quality checks of the global fit found
    warnings.extend(
        o.global
            .quality
            .warnings
            .iter()
            .filter(|w| w.contains("does not fit within the noise"))
            .cloned(),
    );
    Ok((
        MapRow {
            case: case.name.into(),
            images: case.images.len(),
            size: case.size,
            rms_error_height: rh,
            rms_error_psi_deg: rp,
            rms_z_height: rzh,
            rms_z_psi: rzp,
            median_abs_z_height: mzh,
            median_abs_z_psi: mzp,
            within_3se_height: wh,
            within_3se_psi: wp,
            median_std_error_height: seh[seh.len() / 2],
            warnings: warnings.join(" | "),
            seconds,
        },
        o.maps,
        truths,
    ))
}

pub fn run(scratch: &Path, bar: &ProgressBar) -> Result<(Vec<MapRow>, Pictures)> {
    let mut rows = Vec::new();
    let mut pictures = None;
    for case in cases() {
        bar.set_message(format!("maps: {}", case.name));
        let (row, maps, truths) = measure(&case, scratch)?;
        if pictures.is_none() && case.size == SIZE {
            let n = SIZE * SIZE;
            let mut p = Pictures {
                true_height: vec![f64::NAN; n],
                height: vec![f64::NAN; n],
                true_psi: vec![f64::NAN; n],
                psi: vec![f64::NAN; n],
                z_height: vec![f64::NAN; n],
            };
            for (k, &(x, y)) in maps.texels.iter().enumerate() {
                let i = y as usize * SIZE + x as usize;
                p.true_height[i] = truths[k].0;
                p.height[i] = maps.values[k].height;
                p.true_psi[i] = truths[k].1;
                p.psi[i] = maps.values[k].psi;
                p.z_height[i] = (maps.values[k].height - truths[k].0) / maps.std_errors[k].height;
            }
            pictures = Some(p);
        }
        rows.push(row);
        bar.inc(1);
    }
    Ok((rows, pictures.expect("at least one case")))
}
