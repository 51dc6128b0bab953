//! Importance sampling of every rung (issue 21 item 2): a light direction l drawn for a view v
//! with a density close to the shaded intensity f(l, v) (N.l), and the exact density of the draw.
//!
//! First step: every rung draws from the cosine-weighted hemisphere, pdf(l) = (N.l) / pi. The
//! fibre lobes follow.

use super::frame::Local;
use super::params::ModelParams;
use super::{Albedos, DirectionPair, ModelId, ShadingModel};
use std::f64::consts::{FRAC_1_PI, TAU};

/// The importance sampler of one rung with its parameters.
#[derive(Clone, Debug)]
pub struct Sampler {
    id: ModelId,
}

/// One sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub l: Local,
    pub pdf: f64,
    pub weight: [f64; 3],
}

impl Sampler {
    /// The sampler of rung `id` with validated parameters `p` (exponent, alpha_x/alpha_y, spread,
    /// nodes, fuzz...).
    pub fn new(id: ModelId, _p: &ModelParams) -> Sampler {
        Sampler { id }
    }

    /// The rung this sampler was made for.
    pub fn id(&self) -> ModelId {
        self.id
    }

    /// Sample l for the view v (fibre frame) with mixture weights from `albedos`, two uniforms u
    /// in [0,1)^2. weight[c] = f_c(l, v) * l.n / pdf, with f from `model` (at `height` when Some,
    /// via basis_at_height). None when v is at/below the horizon or the sampled l is (the pdf
    /// then integrates to < 1 — allowed).
    pub fn sample(
        &self,
        model: &dyn ShadingModel,
        albedos: &Albedos,
        height: Option<f64>,
        v: &Local,
        u: [f64; 2],
    ) -> Option<Sample> {
        if !(v.n > 0.0) {
            return None;
        }
        let l = cosine_direction(u);
        if !(l.n > 0.0) {
            return None;
        }
        let pdf = self.pdf(albedos, v, &l);
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        let pair = DirectionPair { l, v: *v };
        let basis = match height {
            Some(h) => model
                .basis_at_height(&pair, h)
                .unwrap_or_else(|| model.basis(&pair)),
            None => model.basis(&pair),
        };
        let mut weight = [0.0; 3];
        for (c, w) in weight.iter_mut().enumerate() {
            *w = basis.brdf(albedos, c) * l.n / pdf;
        }
        Some(Sample { l, pdf, weight })
    }

    /// The exact density (1/sr, solid angle) of `sample` producing l given v (0 below the
    /// horizon).
    pub fn pdf(&self, _albedos: &Albedos, v: &Local, l: &Local) -> f64 {
        if !(v.n > 0.0 && l.n > 0.0) {
            return 0.0;
        }
        l.n * FRAC_1_PI
    }
}

/// Cosine-weighted hemisphere direction from two uniforms (Malley: a uniform disk point lifted).
fn cosine_direction(u: [f64; 2]) -> Local {
    let r2 = u[0];
    let r = r2.sqrt();
    let (s, c) = (TAU * u[1]).sin_cos();
    Local {
        t: r * c,
        b: r * s,
        n: (1.0 - r2).max(0.0).sqrt(),
    }
}
