//! Where a model's held-out error exceeds the floor: regions of the sphere of directions named
//! as a user would ("grazing forward scattering"), and half-vector angle bins, each with the
//! model's and the floor's error, the model's bias, and its share of the excess.

use crate::load::samples::Sample;
use serde::Serialize;

/// One held-out sample: the model's and the floor's squared error (mean over channels, in the
/// metric) and the model's value.
pub struct Row<'a> {
    /// The sample.
    pub sample: &'a Sample,
    /// The model's squared error.
    pub model: f64,
    /// The floor's squared error.
    pub floor: f64,
    /// The model's value.
    pub value: [f64; 3],
}

/// A region (or bin) of held-out samples.
#[derive(Clone, Debug, Serialize)]
pub struct Region {
    /// The region in words ("grazing forward scattering", "half-vector 70-80 deg").
    pub name: String,
    /// Held-out samples in it.
    pub n: usize,
    /// The model's RMS error there (metric).
    pub model_error: f64,
    /// The floor's RMS error there.
    pub floor_error: f64,
    /// The model's bias: its geometric mean ratio to the data, minus 1, in percent (the log
    /// floor of the held-out data added to both).
    pub bias_percent: f64,
    /// The region's share of the model's excess squared error over the floor (sum over the
    /// regions with an excess: 1).
    pub excess_share: f64,
}

/// At least this many samples for a region to be named in words.
const NAMED_MIN: usize = 10;
/// A region is named when it holds at least this share of the excess.
const NAMED_SHARE: f64 = 0.15;

/// The elevation class of a pair: by the larger of theta_i and theta_o.
fn elevation(s: &Sample) -> &'static str {
    let t = s.l.z.min(s.v.z).clamp(-1.0, 1.0).acos().to_degrees();
    match t {
        t if t < 30.0 => "near-normal",
        t if t < 60.0 => "oblique",
        _ => "grazing",
    }
}

/// The scattering side of a pair: by |phi_i - phi_o| (folded into [0, 180] deg).
fn side(s: &Sample) -> &'static str {
    let d = (s.l.y.atan2(s.l.x) - s.v.y.atan2(s.v.x)).to_degrees().abs() % 360.0;
    let d = if d > 180.0 { 360.0 - d } else { d };
    match d {
        d if d < 60.0 => "backscattering",
        d if d <= 120.0 => "side scattering",
        _ => "forward scattering",
    }
}

/// The half-vector angle from the normal, degrees.
fn half_vector(s: &Sample) -> f64 {
    let h = s.l + s.v;
    (h.z / h.norm().max(1e-300)).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Sums of one region.
#[derive(Default, Clone)]
struct Sums {
    n: usize,
    model: f64,
    floor: f64,
    log_ratio: f64,
    terms: usize,
}

/// The regions (elevation x scattering side, in reading order) and the half-vector bins of
/// `rows` (`ch` channels).
pub fn regions(rows: &[Row], ch: usize) -> (Vec<Region>, Vec<Region>) {
    let values: Vec<[f64; 3]> = rows.iter().map(|r| r.sample.value).collect();
    let eps = [0, 1, 2].map(|c| crate::fit::problem::log_floor(&values, c));
    let elevations = ["near-normal", "oblique", "grazing"];
    let sides = ["backscattering", "side scattering", "forward scattering"];
    let mut cells = vec![Sums::default(); 9];
    let mut bins = vec![Sums::default(); 9];
    for r in rows {
        let e = elevations.iter().position(|&x| x == elevation(r.sample));
        let s = sides.iter().position(|&x| x == side(r.sample));
        let b = ((half_vector(r.sample) / 10.0) as usize).min(8);
        for sums in [&mut cells[e.unwrap_or(0) * 3 + s.unwrap_or(0)], &mut bins[b]] {
            sums.n += 1;
            sums.model += r.model;
            sums.floor += r.floor;
            for c in 0..ch {
                let y = r.sample.value[c].max(0.0) + eps[c];
                sums.log_ratio += ((r.value[c].max(0.0) + eps[c]) / y).ln();
                sums.terms += 1;
            }
        }
    }
    let names: Vec<String> = elevations
        .iter()
        .flat_map(|e| sides.iter().map(move |s| format!("{e} {s}")))
        .collect();
    let bin_names: Vec<String> = (0..9)
        .map(|k| format!("half-vector {}-{} deg", 10 * k, 10 * k + 10))
        .collect();
    (finish(&cells, &names), finish(&bins, &bin_names))
}

/// The regions of `sums` named `names` (empty ones left out).
fn finish(sums: &[Sums], names: &[String]) -> Vec<Region> {
    let excess: f64 = sums.iter().map(|s| (s.model - s.floor).max(0.0)).sum();
    sums.iter()
        .zip(names)
        .filter(|(s, _)| s.n > 0)
        .map(|(s, name)| Region {
            name: name.clone(),
            n: s.n,
            model_error: (s.model / s.n as f64).sqrt(),
            floor_error: (s.floor / s.n as f64).sqrt(),
            bias_percent: 100.0 * ((s.log_ratio / s.terms.max(1) as f64).exp() - 1.0),
            excess_share: (s.model - s.floor).max(0.0) / excess.max(f64::MIN_POSITIVE),
        })
        .collect()
}

/// A region's headline: "the model is 25 % low at grazing forward scattering".
fn headline(r: &Region) -> String {
    let bias = match r.bias_percent {
        b if b <= -5.0 => format!("the model is {:.0} % low", -b),
        b if b >= 5.0 => format!("the model is {b:.0} % high"),
        b => format!("the model errs both ways (mean bias {b:+.0} %)"),
    };
    format!("{bias} at {}", r.name)
}

/// One region in words: "the model is 25 % low at grazing forward scattering (41 % of the
/// excess; 0.310 against the floor's 0.060, 120 samples)".
fn region_words(r: &Region) -> String {
    format!(
        "{} ({:.0} % of the excess error; {:.3} against the floor's {:.3}, {} samples)",
        headline(r),
        100.0 * r.excess_share,
        r.model_error,
        r.floor_error,
        r.n
    )
}

/// The (at most `k`) regions of `rs` named in words: at least [`NAMED_MIN`] samples and
/// [`NAMED_SHARE`] of the excess, the largest share first.
fn pick(rs: &[Region], k: usize) -> Vec<Region> {
    let mut v: Vec<Region> = rs
        .iter()
        .filter(|r| r.n >= NAMED_MIN && r.excess_share >= NAMED_SHARE)
        .cloned()
        .collect();
    v.sort_by(|a, b| b.excess_share.total_cmp(&a.excess_share));
    v.truncate(k);
    v
}

/// The region holding most of the excess, in a few words (for a verdict), or `None`.
pub fn short(regions: &[Region]) -> Option<String> {
    pick(regions, 1).first().map(headline)
}

/// Where the excess concentrates, in words: the (at most two) regions holding at least
/// [`NAMED_SHARE`] of it, and the worst half-vector bin.
pub fn words(regions: &[Region], bins: &[Region]) -> String {
    let named = pick(regions, 2);
    if named.is_empty() {
        return "no region of directions stands out: the excess over the floor is spread evenly"
            .into();
    }
    let mut t = named
        .iter()
        .map(region_words)
        .collect::<Vec<_>>()
        .join("; ");
    if let Some(b) = pick(bins, 1).first() {
        t += &format!(
            "; by half-vector angle from the normal, most at {} ({:.0} % of the excess, bias {:+.0} %)",
            b.name.trim_start_matches("half-vector "),
            100.0 * b.excess_share,
            b.bias_percent
        );
    }
    t
}
