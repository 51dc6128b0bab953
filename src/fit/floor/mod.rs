//! Know the floor: what the data themselves allow a model to reach on samples it did not see.
//!
//! - **The predictor.** A local linear fit (tricube weights, a touch of ridge, clamped to the
//!   neighbours' range) of the [`NEIGHBOURS`] nearest training samples' values (logs for the
//!   log metric), found by a kd-tree ([`knn`]) in azimuthal equidistant charts of the
//!   directions; nothing global is fitted. The chart is the material's own symmetric
//!   coordinates, whichever predicts the training samples best left-one-out: isotropic
//!   (theta_i, theta_o, |phi_i - phi_o|), that with each sample's reciprocal, the direction pair
//!   as measured, or the pair with its images under reciprocity and T -> -T (fibres; no fibre
//!   direction needed). Measured against weighted means of 8 neighbours on the felt and CUReT
//!   (docs/figures.md): about half their error. Each squared error is divided by 1 + the sum of
//!   the prediction's smoother weights' squares (the share of its neighbours' noise a prediction
//!   carries): the floor is noise plus what interpolating between the measured directions
//!   loses, not the predictor's own noise.
//! - **The same split.** The floor is the predictor's held-out error on the very folds (or the
//!   one split) the model's held-out error was measured on, trained on what the model's fits
//!   were trained on, in the fit's metric (the training part's log floors), as the RMS over
//!   held-out samples of the mean squared residual over channels (the `cv_error` of `--model
//!   auto`). At most [`MAX_HELDOUT`] held-out samples are predicted, from at most [`MAX_TRAIN`]
//!   training samples per fold (seeded subsamples).
//! - **Pairs.** Where the data hold reciprocal pairs (l, v) and (v, l), or repeated direction
//!   pairs, each pair's disagreement gives the noise (and, for reciprocal pairs, the data's own
//!   departure from reciprocity) as the error a perfect model would make.
//! - **The verdict.** A model whose held-out error is within [`WITHIN`] times the floor is
//!   "within 1.2x of what the data allow"; beyond, it "misses structure the data hold", and
//!   where the excess concentrates is said in words ([`regions`]).
//! - **Reciprocity.** A material is reciprocal, f(l, v) = f(v, l); measurements need not be (a
//!   gonioreflectometer's light and view responses differ; a measured file's incidence slices
//!   are measured one by one). Where the chosen chart is not reciprocal and the model is
//!   beyond [`WITHIN`] times the floor, the same predictor is measured again among the
//!   reciprocal charts ([`ReciprocalFloor`]): what any BRDF can reach. Above
//!   [`NOT_RECIPROCAL`] times the floor the data are not reciprocal, and a model within
//!   [`WITHIN`] times that floor (but not the data's own) is "within 1.2x of what a material
//!   can reach", not a model that misses structure.

pub mod judge;
pub mod knn;
pub mod regions;

use super::config::Metric;
use super::problem::{log_floor, metric_residual, residual_scale};
use super::selection::{rms_and_se, HeldOut, Split};
use crate::load::samples::{Sample, Samples};
use anyhow::{bail, Result};
pub use knn::Method;
use knn::{Coordinates, Point, Predictor};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::Serialize;

/// Neighbours per prediction.
pub const NEIGHBOURS: usize = 12;
/// How the neighbours' values combine (docs/figures.md measures the choices).
pub const METHOD: Method = Method::LocalLinear;
/// A model within this many times the floor fits as well as the data allow.
pub const WITHIN: f64 = 1.2;
/// At most this many held-out samples are predicted (a seeded subsample of more).
pub const MAX_HELDOUT: usize = 20_000;
/// At most this many training samples choose the coordinates (left-one-out).
const MAX_CHOICE: usize = 2_000;
/// At most this many training samples per fold train the predictor (a seeded subsample of
/// more: a capture's millions of pixels cost memory, not precision).
pub const MAX_TRAIN: usize = 200_000;
/// Two direction pairs closer than this (chord of the six-vector) are the same pair.
const PAIR_CHORD: f64 = 1e-3;

/// The floor: the nonparametric predictor's held-out error.
#[derive(Clone, Debug, Serialize)]
pub struct Floor {
    /// RMS over held-out samples of the mean squared residual over channels, in `metric`, each
    /// divided by 1 + the sum of the prediction's smoother weights' squares (the predictor's
    /// own share of the noise: its prediction averages its neighbours' noise): the error of a
    /// predictor that knew the truth where the data are dense, noise plus what interpolating
    /// between the measured directions loses.
    pub error: f64,
    /// Its standard error.
    pub standard_error: f64,
    /// The predictor's own held-out error: `error` with the predictor's share of the noise in
    /// (each sample's squared error times 1 + the sum of its smoother weights' squares).
    pub predictor_error: f64,
    /// The metric (the fit's).
    pub metric: String,
    /// The predictor, in words.
    pub predictor: String,
    /// The embedding chosen (on the first fold).
    pub coordinates: Coordinates,
    /// Held-out samples predicted.
    pub heldout_samples: usize,
    /// The folds or split, in words.
    pub validation: String,
    /// The noise from reciprocal pairs (l, v) and (v, l), when the data hold at least 5.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reciprocal_pairs: Option<PairNoise>,
    /// The noise from repeated direction pairs, when the data hold at least 5.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub repeated_directions: Option<PairNoise>,
}

/// The noise pairs of samples imply: the RMS (in the metric) of a perfect model's error,
/// sqrt(mean squared pair difference / 2).
#[derive(Clone, Debug, Serialize)]
pub struct PairNoise {
    /// Samples with a partner.
    pub pairs: usize,
    /// The error a perfect model would make, in the metric.
    pub noise: f64,
}

/// A floor with its per-sample results: (sample index, squared error) in held-out order.
pub struct FloorRun {
    /// The floor.
    pub floor: Floor,
    /// Per predicted sample: its index and mean squared residual over channels.
    pub tested: Vec<(usize, f64)>,
}

/// How values are averaged and judged: the metric, its log floors and the channels.
#[derive(Clone, Copy, Debug)]
struct Space {
    metric: Metric,
    eps: [f64; 3],
    ch: usize,
}

impl Space {
    /// The space of `metric` with the log floors `eps`, or those of `train`.
    fn of(metric: Metric, train: &[&Sample], ch: usize, eps: Option<[f64; 3]>) -> Self {
        let eps = eps.unwrap_or_else(|| {
            let values: Vec<[f64; 3]> = train.iter().map(|s| s.value).collect();
            [0, 1, 2].map(|c| log_floor(&values, c))
        });
        Self { metric, eps, ch }
    }

    /// The value averaged: ln(y + eps) for the log metric, y otherwise.
    fn to(&self, s: &Sample) -> [f64; 3] {
        match self.metric {
            Metric::Log => std::array::from_fn(|c| (s.value[c].max(0.0) + self.eps[c]).ln()),
            _ => s.value,
        }
    }

    /// A prediction averaged in this space back in the data's units.
    fn back(&self, p: [f64; 3]) -> [f64; 3] {
        match self.metric {
            Metric::Log => std::array::from_fn(|c| (p[c].exp() - self.eps[c]).max(0.0)),
            _ => p,
        }
    }

    /// The mean over channels of the squared residual of `m` predicted for `s`.
    fn error(&self, s: &Sample, m: &[f64; 3]) -> f64 {
        let scale = residual_scale(self.metric, s);
        (0..self.ch)
            .map(|c| metric_residual(self.metric, scale[c], self.eps[c], s, c, m[c]).powi(2))
            .sum::<f64>()
            / self.ch as f64
    }
}

/// The predictor's settings: neighbours, how their values combine, and the coordinates
/// (`None`: chosen left-one-out). The floor uses [`Choice::default`]; the others are for
/// studies (`examples/floor_study.rs`).
#[derive(Clone, Copy, Debug)]
pub struct Choice {
    /// Neighbours per prediction.
    pub k: usize,
    /// How the neighbours' values combine.
    pub method: Method,
    /// The embedding; `None`: the one that predicts the training samples better left-one-out.
    pub coordinates: Option<Coordinates>,
    /// Choose among the reciprocal embeddings only ([`knn::RECIPROCAL`]; with `coordinates`
    /// `None`): the floor of what a material, a reciprocal BRDF, can reach.
    pub reciprocal: bool,
}

impl Default for Choice {
    fn default() -> Self {
        Self {
            k: NEIGHBOURS,
            method: METHOD,
            coordinates: None,
            reciprocal: false,
        }
    }
}

/// The predictor of `train` in `coordinates`.
fn predictor(train: &[&Sample], space: &Space, coordinates: Coordinates, c: &Choice) -> Predictor {
    let points: Vec<(Point, usize)> = train
        .iter()
        .enumerate()
        .flat_map(|(i, s)| coordinates.images(s).into_iter().map(move |p| (p, i)))
        .collect();
    let values = train.iter().map(|s| space.to(s)).collect();
    Predictor::new(points, values, c.k, c.method, coordinates)
}

/// The predictor of `train` in the coordinates of `c`, or those that predict up to
/// [`MAX_CHOICE`] of its samples (seeded) better left-one-out.
fn chosen_predictor(train: &[&Sample], space: &Space, seed: u64, c: &Choice) -> Predictor {
    let mut idx: Vec<usize> = (0..train.len()).collect();
    idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed ^ 0xf100));
    idx.truncate(MAX_CHOICE);
    let candidates = match (c.coordinates, c.reciprocal) {
        (Some(x), _) => vec![x],
        (None, true) => knn::RECIPROCAL.to_vec(),
        (None, false) => knn::ALL.to_vec(),
    };
    let mut best: Option<(f64, Predictor)> = None;
    for coordinates in candidates {
        let p = predictor(train, space, coordinates, c);
        let errors: Vec<f64> = idx
            .par_iter()
            .map(|&i| {
                let q = coordinates.point(train[i]);
                space.error(train[i], &space.back(p.predict(&q, Some(i)).0))
            })
            .collect();
        let e = errors.iter().sum::<f64>();
        if best.as_ref().is_none_or(|b| e < b.0) {
            best = Some((e, p));
        }
    }
    best.expect("two candidates").1
}

/// The held-out samples predicted: every one, or a seeded subsample of [`MAX_HELDOUT`] (in
/// held-out order), per split.
fn held_out(splits: &[Split], seed: u64) -> Vec<Vec<usize>> {
    let total: usize = splits.iter().map(|s| s.test.len()).sum();
    if total <= MAX_HELDOUT {
        return splits.iter().map(|s| s.test.clone()).collect();
    }
    let mut keys: Vec<usize> = (0..total).collect();
    keys.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed ^ 0xf1005));
    let mut keep = vec![false; total];
    for &k in &keys[..MAX_HELDOUT] {
        keep[k] = true;
    }
    let mut k = 0;
    splits
        .iter()
        .map(|s| {
            s.test
                .iter()
                .filter(|_| {
                    k += 1;
                    keep[k - 1]
                })
                .copied()
                .collect()
        })
        .collect()
}

/// What [`floor_on`] measures on: the splits, the metric, log floors for every split (`None`:
/// each split's training part's), the seed and the validation in words.
#[derive(Clone)]
pub struct FloorRequest<'a> {
    /// The folds or split (the model's).
    pub splits: &'a [Split],
    /// The fit's metric.
    pub metric: Metric,
    /// The log floors of every split (`None`: each training part's).
    pub eps: Option<[f64; 3]>,
    /// Seeds the subsamples.
    pub seed: u64,
    /// The folds or split, in words.
    pub validation: String,
    /// The predictor's settings.
    pub choice: Choice,
}

/// The floor of `samples` on the splits of `req`.
pub fn floor_on(samples: &Samples, req: &FloorRequest) -> Result<FloorRun> {
    let ch = samples.channels;
    let tests = held_out(req.splits, req.seed);
    let mut tested = Vec::new();
    let mut coordinates = None;
    for (split, test) in req.splits.iter().zip(&tests) {
        if split.train.len() < req.choice.k + 1 {
            bail!(
                "the floor needs more than {} training samples; a fold has {}",
                req.choice.k,
                split.train.len()
            );
        }
        let mut train_idx = split.train.clone();
        if train_idx.len() > MAX_TRAIN {
            train_idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(req.seed ^ 0x7a1));
            train_idx.truncate(MAX_TRAIN);
            train_idx.sort_unstable();
        }
        let train: Vec<&Sample> = train_idx.iter().map(|&i| &samples.samples[i]).collect();
        let space = Space::of(req.metric, &train, ch, req.eps);
        let p = chosen_predictor(&train, &space, req.seed, &req.choice);
        coordinates.get_or_insert(p.coordinates);
        // each prediction's error, and that error with the predictor's own share of the
        // noise taken out (e^2 / (1 + sum of its weights' squares)): what a model that knew the
        // truth where the data are dense would make
        let errors: Vec<(f64, f64)> = test
            .par_iter()
            .map(|&i| {
                let s = &samples.samples[i];
                let (value, leverage) = p.predict(&p.coordinates.point(s), None);
                let e = space.error(s, &space.back(value));
                (e, e / (1.0 + leverage))
            })
            .collect();
        tested.extend(test.iter().copied().zip(errors));
    }
    let raw: Vec<f64> = tested.iter().map(|x| x.1 .0).collect();
    let tested: Vec<(usize, f64)> = tested.into_iter().map(|(i, e)| (i, e.1)).collect();
    let errors: Vec<f64> = tested.iter().map(|x| x.1).collect();
    if errors.is_empty() || errors.iter().chain(&raw).any(|e| !e.is_finite()) {
        bail!("the floor's predictions are not finite");
    }
    let (error, standard_error) = rms_and_se(&errors);
    let predictor_error = rms_and_se(&raw).0;
    let all: Vec<&Sample> = samples.samples.iter().collect();
    let space = Space::of(req.metric, &all, ch, req.eps);
    let coordinates = coordinates.unwrap_or(Coordinates::Directions);
    Ok(FloorRun {
        floor: Floor {
            error,
            standard_error,
            predictor_error,
            metric: crate::fit::selection::metric_name(req.metric).into(),
            predictor: format!(
                "{} of the data themselves{} over {} nearest neighbours (kd-tree; nothing fitted)",
                req.choice.method.text(),
                match req.metric {
                    Metric::Log => " (log values)",
                    _ => "",
                },
                req.choice.k
            ),
            coordinates,
            heldout_samples: errors.len(),
            validation: req.validation.clone(),
            reciprocal_pairs: pair_noise(&all, &space, true, req.seed),
            repeated_directions: pair_noise(&all, &space, false, req.seed),
        },
        tested,
    })
}

/// The noise pairs of `samples` imply: reciprocal pairs (`reciprocal`: (l, v) and (v, l)) or
/// repeated direction pairs, each sample of up to [`MAX_HELDOUT`] (seeded) with its nearest
/// partner within [`PAIR_CHORD`]; `None` with fewer than 5.
fn pair_noise(samples: &[&Sample], space: &Space, reciprocal: bool, seed: u64) -> Option<PairNoise> {
    // unit vectors (the fibres' frame where the samples give one): pairs match to PAIR_CHORD
    let points: Vec<Point> = samples
        .iter()
        .map(|s| {
            let (sa, ca) = s.fibre_azimuth.unwrap_or(0.0).sin_cos();
            let r = |w: &crate::model::frame::Vec3| [ca * w.x + sa * w.y, -sa * w.x + ca * w.y, w.z];
            let (l, v) = (r(&s.l), r(&s.v));
            [l[0], l[1], l[2], v[0], v[1], v[2]]
        })
        .collect();
    let tree = knn::KdTree::new(&points);
    let mut idx: Vec<usize> = (0..samples.len()).collect();
    if idx.len() > MAX_HELDOUT {
        idx.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed ^ 0xba1));
        idx.truncate(MAX_HELDOUT);
        idx.sort_unstable();
    }
    let errors: Vec<f64> = idx
        .par_iter()
        .filter_map(|&i| {
            let p = points[i];
            let q = match reciprocal {
                true => [p[3], p[4], p[5], p[0], p[1], p[2]],
                false => p,
            };
            // a sample at l = v is its own reciprocal: never its own partner
            let (_, j) = tree
                .nearest(&q, 2)
                .into_iter()
                .find(|&(d2, j)| j != i && d2 < PAIR_CHORD * PAIR_CHORD)?;
            Some(space.error(samples[i], &samples[j].value))
        })
        .collect();
    (errors.len() >= 5).then(|| PairNoise {
        pairs: errors.len(),
        noise: (errors.iter().sum::<f64>() / errors.len() as f64 / 2.0).sqrt(),
    })
}

/// Below this ratio the model predicts so much better than the interpolant that the floor
/// says more about the directions' spacing than about the data's noise.
pub const BEATS_THE_PREDICTOR: f64 = 0.5;

/// A model's held-out error against the floor of the same samples.
#[derive(Clone, Debug, Serialize)]
pub struct FloorCheck {
    /// The model's held-out error (RMS in the metric).
    pub heldout_error: f64,
    /// Its standard error.
    pub heldout_standard_error: f64,
    /// The floor ([`Floor::error`]).
    pub floor: f64,
    /// heldout_error / floor.
    pub ratio: f64,
    /// [`WITHIN`]: the ratio a model that fits as well as the data allow stays under.
    pub limit: f64,
    /// ratio <= limit.
    pub within: bool,
    /// "within 1.2x of what the data allow" or "misses structure the data hold: " and the
    /// region holding most of the excess ("the model is 25 % low at grazing forward
    /// scattering").
    pub verdict: String,
    /// Where the model's excess over the floor concentrates, in words.
    #[serde(rename = "where")]
    pub where_text: String,
    /// The regions of the sphere of directions (elevation and scattering side), with the
    /// model's and the floor's error in each ([`regions`]).
    pub regions: Vec<regions::Region>,
    /// The same by half-vector angle from the normal, 10 deg bins.
    pub half_vector_bins: Vec<regions::Region>,
    /// How the floor was measured.
    pub estimate: Floor,
    /// Where the floor's predictor is not reciprocal and the model is beyond [`WITHIN`] times
    /// the floor: the same predictor among the reciprocal embeddings, what any material (a
    /// reciprocal BRDF) can reach on these data.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reciprocal: Option<ReciprocalFloor>,
}

/// The floor of a reciprocal predictor (each training sample also standing for its pair with
/// light and view swapped): data that are not reciprocal (a measurement's light and view
/// responses differ) hold structure no material can follow, so a BRDF cannot come closer than
/// this.
#[derive(Clone, Debug, Serialize)]
pub struct ReciprocalFloor {
    /// Its held-out error ([`Floor::error`]).
    pub floor: f64,
    /// Its standard error.
    pub standard_error: f64,
    /// The reciprocal embedding chosen.
    pub coordinates: Coordinates,
    /// This floor over the data's own: how far the data are from reciprocal (near 1: they
    /// are).
    pub over_floor: f64,
    /// The model's held-out error over this floor (the material's, where given).
    pub ratio: f64,
    /// The material's held-out error where the model of the measurement carries an
    /// instrument's light/view imbalance the material leaves out (`fit::correction`): what is
    /// judged against this floor.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material_error: Option<f64>,
    /// ratio <= [`WITHIN`]: as close as a material can come.
    pub within: bool,
}

/// Above this many times the data's own floor, a reciprocal predictor's says the data are not
/// reciprocal (below it, the two differ by about their standard errors).
pub const NOT_RECIPROCAL: f64 = 1.2;

impl ReciprocalFloor {
    /// Whether it says the data are not reciprocal ([`NOT_RECIPROCAL`]).
    pub fn data_not_reciprocal(&self) -> bool {
        self.over_floor > NOT_RECIPROCAL
    }
}

/// The floor of `req` among the reciprocal embeddings when `floor`'s predictor is not one and
/// the model's error `error` is beyond [`WITHIN`] times `floor` (where the verdict can change;
/// within, it costs a second predictor for nothing: 1.3x the wall time of a capture's global
/// fit). `None` otherwise, or when it cannot be measured.
fn reciprocal_floor(samples: &Samples, req: &FloorRequest, floor: &Floor, error: f64) -> Option<Floor> {
    let within = error <= WITHIN * floor.error;
    if within || floor.coordinates.is_reciprocal() || req.choice.coordinates.is_some() {
        return None;
    }
    let choice = Choice {
        reciprocal: true,
        ..req.choice
    };
    let req = FloorRequest {
        choice,
        ..req.clone()
    };
    floor_on(samples, &req).ok().map(|r| r.floor)
}

/// The model's held-out errors `model` against the floor on the same splits (each training
/// part's log floors, as the model's fold fits were judged).
pub fn check(samples: &Samples, metric: Metric, model: &HeldOut, seed: u64) -> Result<FloorCheck> {
    Ok(Measured::run(samples, metric, model, seed)?.check(samples, model))
}

/// The floor measured on a model's splits, to judge that model and another on the same splits
/// (a corrected one) without measuring it again.
pub struct Measured {
    run: FloorRun,
    req_metric: Metric,
    seed: u64,
    validation: String,
    /// The reciprocal floor once measured (`None` inside: measured, none to give).
    reciprocal: std::cell::OnceCell<Option<Floor>>,
}

impl Measured {
    /// Measure the floor on `model`'s splits.
    pub fn run(samples: &Samples, metric: Metric, model: &HeldOut, seed: u64) -> Result<Self> {
        let req = FloorRequest {
            splits: &model.splits,
            metric,
            eps: None,
            seed,
            validation: model.validation.clone(),
            choice: Choice::default(),
        };
        Ok(Self {
            run: floor_on(samples, &req)?,
            req_metric: metric,
            seed,
            validation: model.validation.clone(),
            reciprocal: std::cell::OnceCell::new(),
        })
    }

    /// The reciprocal floor's estimate, where a check measured one (a model beyond [`WITHIN`]
    /// the floor on data whose floor chart is not reciprocal).
    pub fn reciprocal(&self) -> Option<&Floor> {
        self.reciprocal.get().and_then(Option::as_ref)
    }

    /// The check of `model` (on the splits the floor was measured on): where its excess lies,
    /// and the reciprocal floor where it is beyond [`WITHIN`] the floor (measured once).
    pub fn check(&self, samples: &Samples, model: &HeldOut) -> FloorCheck {
        self.check_with(samples, model, None)
    }

    /// [`Measured::check`] of a model of the measurement whose material alone (an instrument's
    /// terms aside) has the held-out error `material`: that is what the reciprocal floor judges.
    pub fn check_with(&self, samples: &Samples, model: &HeldOut, material: Option<f64>) -> FloorCheck {
        let run = &self.run;
        let mut per_sample = vec![None; samples.samples.len()];
        let tests = model.splits.iter().flat_map(|s| s.test.iter());
        for ((&i, e), m) in tests.zip(&model.errors).zip(&model.values) {
            per_sample[i] = Some((*e, *m));
        }
        let rows: Vec<regions::Row> = run
            .tested
            .iter()
            .filter_map(|&(i, floor)| {
                per_sample[i].map(|(model, value)| regions::Row {
                    sample: &samples.samples[i],
                    model,
                    floor,
                    value,
                })
            })
            .collect();
        let (regs, bins) = regions::regions(&rows, samples.channels);
        let beyond = model.error > WITHIN * run.floor.error;
        let reciprocal = match (beyond, self.reciprocal.get()) {
            (false, _) => None,
            (true, Some(r)) => r.clone(),
            (true, None) => {
                let req = FloorRequest {
                    splits: &model.splits,
                    metric: self.req_metric,
                    eps: None,
                    seed: self.seed,
                    validation: self.validation.clone(),
                    choice: Choice::default(),
                };
                let r = reciprocal_floor(samples, &req, &run.floor, model.error);
                self.reciprocal.get_or_init(|| r).clone()
            }
        };
        compare(
            model.error,
            model.standard_error,
            run.floor.clone(),
            reciprocal,
            regs,
            bins,
            material,
        )
    }
}

/// The check of a model error `error` (standard error `se`) against `floor` (and `reciprocal`,
/// a reciprocal predictor's floor where `floor`'s is not one, against which the material's
/// error `material` is judged where given, else `error`).
pub fn compare(
    error: f64,
    se: f64,
    floor: Floor,
    reciprocal: Option<Floor>,
    regions: Vec<regions::Region>,
    half_vector_bins: Vec<regions::Region>,
    material: Option<f64>,
) -> FloorCheck {
    let ratio = error / floor.error.max(f64::MIN_POSITIVE);
    let within = ratio <= WITHIN;
    let reciprocal = reciprocal.map(|r| {
        let ratio = material.unwrap_or(error) / r.error.max(f64::MIN_POSITIVE);
        ReciprocalFloor {
            floor: r.error,
            standard_error: r.standard_error,
            coordinates: r.coordinates,
            over_floor: r.error / floor.error.max(f64::MIN_POSITIVE),
            ratio,
            material_error: material,
            within: ratio <= WITHIN,
        }
    });
    let where_text = regions::words(&regions, &half_vector_bins);
    let not_reciprocal = reciprocal.as_ref().filter(|r| r.data_not_reciprocal());
    let verdict = match (within, not_reciprocal) {
        (true, _) => format!("within {WITHIN}x of what the data allow"),
        (false, Some(r)) if r.within => format!(
            "within {WITHIN}x of what a material can reach: the data are not reciprocal (a \
             reciprocal predictor's floor is {:.2}x theirs), and no BRDF follows that",
            r.over_floor
        ),
        (false, _) => format!(
            "misses structure the data hold: {}",
            regions::short(&regions).unwrap_or_else(|| format!(
                "held-out error {ratio:.1}x the floor, spread over every region"
            ))
        ),
    };
    FloorCheck {
        heldout_error: error,
        heldout_standard_error: se,
        floor: floor.error,
        ratio,
        limit: WITHIN,
        within,
        verdict,
        where_text,
        regions,
        half_vector_bins,
        estimate: floor,
        reciprocal,
    }
}

/// The floor of data a result is scored on: the predictor cross-validated on `samples` as a
/// named rung's fit would be (seeded folds, or one split), with the log floors `eps` of all of
/// them, against the model's error `error` on every sample (RMS in `metric`).
pub fn of_scored(samples: &Samples, metric: Metric, eps: [f64; 3], error: f64) -> Result<FloorCheck> {
    let sel = crate::fit::config::Selection::default();
    let (splits, validation) = super::selection::splits_for(samples.samples.len(), &sel, 0)?;
    let req = FloorRequest {
        splits: &splits,
        metric,
        eps: Some(eps),
        seed: 0,
        validation,
        choice: Choice::default(),
    };
    let run = floor_on(samples, &req)?;
    let reciprocal = reciprocal_floor(samples, &req, &run.floor, error);
    Ok(compare(error, f64::NAN, run.floor, reciprocal, vec![], vec![], None))
}

/// The floor lines of the report's [[Quality]] (and of `fibrefit score`): the model's held-out error, the floor, their ratio, where the
/// excess concentrates, the pairs' noise, and the regions' table.
pub fn text(f: &FloorCheck) -> String {
    use std::fmt::Write;
    let e = &f.estimate;
    let mut t = String::new();
    let _ = match f.heldout_standard_error.is_finite() {
        true => writeln!(
            t,
            "    held-out error     = {:.4} +/- {:.4} ({} metric, {})",
            f.heldout_error, f.heldout_standard_error, e.metric, e.validation
        ),
        // a scored result: its error on every sample scored
        false => writeln!(
            t,
            "    model's error      = {:.4} ({} metric, every sample scored; the floor: {})",
            f.heldout_error, e.metric, e.validation
        ),
    };
    let _ = writeln!(
        t,
        "    floor              = {:.4} +/- {:.4} (the predictor's own error {:.4}; {}, {} coordinates, {} held-out samples: what the data themselves allow)",
        f.floor,
        e.standard_error,
        e.predictor_error,
        e.predictor,
        e.coordinates.text(),
        e.heldout_samples
    );
    let _ = writeln!(
        t,
        "    ratio              = {:.2} ({} {}x{})",
        f.ratio,
        if f.within { "within" } else { "beyond" },
        f.limit,
        // far below 1 the predictor, not the data, sets the floor: the directions are too
        // sparse for interpolating them to follow what the model follows
        if f.ratio < BEATS_THE_PREDICTOR {
            "; the model predicts far better than interpolating the data can, so here the \
             floor bounds the predictor, not the model: judge the fit by the noise"
        } else {
            ""
        }
    );
    if let Some(r) = &f.reciprocal {
        let _ = writeln!(
            t,
            "    reciprocal floor   = {:.4} +/- {:.4} ({:.2}x the floor; ratio {:.2}: the same predictor, each training sample also at its reciprocal pair, {} coordinates: what a material, a reciprocal BRDF, can reach{})",
            r.floor,
            r.standard_error,
            r.over_floor,
            r.ratio,
            r.coordinates.text(),
            if r.data_not_reciprocal() {
                "; the data are not reciprocal"
            } else {
                ""
            }
        );
    }
    let _ = writeln!(t, "    where              = {}", f.where_text);
    for (name, p) in [
        ("reciprocal pairs", &e.reciprocal_pairs),
        ("repeated pairs", &e.repeated_directions),
    ] {
        if let Some(p) = p {
            let _ = writeln!(
                t,
                "    {name:<18} = noise {:.4} ({} samples with a partner: the error a perfect model would make)",
                p.noise, p.pairs
            );
        }
    }
    if !f.regions.is_empty() {
        t += "    held-out error by region (model, floor, model's bias, share of the excess):\n";
        for r in f.regions.iter().chain(&f.half_vector_bins) {
            let _ = writeln!(
                t,
                "      {:<36} n {:>6}  model {:.4}  floor {:.4}  bias {:+6.1} %  excess {:>5.1} %",
                r.name,
                r.n,
                r.model_error,
                r.floor_error,
                r.bias_percent,
                100.0 * r.excess_share
            );
        }
    }
    t
}
