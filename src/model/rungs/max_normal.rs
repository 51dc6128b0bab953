//! `max-normal` (Banks 1994; Heidrich & Seidel 1998): shade with the single brightest normal.
//!
//! I_d = (kd / pi) sqrt(1 - (l.t)^2),
//! I_s = ks max(0, sqrt(1 - (l.t)^2) sqrt(1 - (v.t)^2) - (l.t)(v.t))^e,
//! and f = I / (N.l). No hiding, shadowing or viewer in the diffuse term.

use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::numerics::lanes::on_widest_lanes;
use crate::model::numerics::lobe_quadrature::pow_positive;
use crate::model::{Basis, DirectionPair, ShadingModel};
use std::f64::consts::FRAC_1_PI;

/// The rung.
pub static RUNG: Rung = Rung {
    name: "max-normal",
    description: "the brightest normal of a fibre only (Banks; Heidrich-Seidel)",
    abilities: &[
        FibreDiffuse,
        SpecularLobe,
        Fresnel,
        FibreDirection,
        DirectionSpread,
    ],
    build: |a| Box::new(MaxNormal::new(a.exponent)),
    sampling: Sampling {
        lobe: LobeSampling::FibreCone,
        diffuse_tube: std::f64::consts::FRAC_PI_2,
        diffuse_cosine: 0.0,
        lobe_albedo: LobeAlbedo::Wallis,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["max_normal"],
        body: "    return fibrefit_max_normal(l, v, p.shape.x);\n",
        material_rows: None,
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(3),
    example: &[(Param::Kd, 0.3), (Param::Ks, 0.6), (Param::Exponent, 100.0)],
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

#[derive(Clone, Copy, Debug)]
pub struct MaxNormal {
    exponent: f64,
}

impl MaxNormal {
    pub fn new(exponent: f64) -> Self {
        Self { exponent }
    }
}

impl ShadingModel for MaxNormal {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let (l, v) = (&pair.l, &pair.v);
        let (d, s) = self.terms(l.t, l.b, l.n, v.t, v.b, v.n);
        Self::basis_of(pair, d, s)
    }

    /// Every pair's basis, eight pairs at a time in lanes on the widest vector instructions
    /// (a spread evaluates 16 turned pairs per value): the same terms as `basis`, bit for bit
    /// (the power is [`pow_positive`] in both, plain arithmetic).
    fn basis_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        assert_eq!(pairs.len(), out.len());
        on_widest_lanes(
            #[inline(always)]
            |_| {
                const L: usize = 8;
                let mut chunks = pairs.chunks_exact(L);
                let mut outs = out.chunks_exact_mut(L);
                for (chunk, o) in (&mut chunks).zip(&mut outs) {
                    // components into lanes, the terms lane by lane, the results back
                    let (mut lt, mut lb, mut ln) = ([0.0; L], [0.0; L], [0.0; L]);
                    let (mut vt, mut vb, mut vn) = ([0.0; L], [0.0; L], [0.0; L]);
                    for (j, p) in chunk.iter().enumerate() {
                        (lt[j], lb[j], ln[j]) = (p.l.t, p.l.b, p.l.n);
                        (vt[j], vb[j], vn[j]) = (p.v.t, p.v.b, p.v.n);
                    }
                    let (mut d, mut s) = ([0.0; L], [0.0; L]);
                    for j in 0..L {
                        (d[j], s[j]) = self.terms(lt[j], lb[j], ln[j], vt[j], vb[j], vn[j]);
                    }
                    for (j, (p, o)) in chunk.iter().zip(o.iter_mut()).enumerate() {
                        *o = Self::basis_of(p, d[j], s[j]);
                    }
                }
                for (p, o) in chunks.remainder().iter().zip(outs.into_remainder()) {
                    *o = self.basis(p);
                }
            },
        )
    }
}

impl MaxNormal {
    /// The diffuse and specular terms of a pair above the horizon from its components (finite
    /// placeholders below it, which callers discard): branch-free.
    #[inline(always)]
    fn terms(&self, lt: f64, lb: f64, ln: f64, vt: f64, vb: f64, vn: f64) -> (f64, f64) {
        // sqrt(1 - (w.t)^2) computed as |w_p|, exact even when w.t ~ 1.
        let (lp, vp) = ((lb * lb + ln * ln).sqrt(), (vb * vb + vn * vn).sqrt());
        let lobe = (lp * vp - lt * vt).max(0.0);
        // the divisor kept positive below the horizon, where the value is discarded
        let cos_l = ln.max(f64::MIN_POSITIVE);
        (
            FRAC_1_PI * lp / cos_l,
            pow_positive(lobe, self.exponent) / cos_l,
        )
    }

    /// The basis from the terms; zero at or below the horizon.
    #[inline(always)]
    fn basis_of(pair: &DirectionPair, diffuse: f64, specular: f64) -> Basis {
        if pair.above_horizon() {
            Basis {
                diffuse,
                specular,
                substrate: 0.0,
                fuzz: 0.0,
            }
        } else {
            Basis::default()
        }
    }
}
