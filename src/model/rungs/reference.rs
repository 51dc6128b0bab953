//! `reference`: MODEL.md §2 evaluated to 1e-9 relative — the truth the other rungs are measured
//! against. Same exact arcs as the fast rungs, but every integral (diffuse included) by globally
//! adaptive Gauss–Kronrod with breakpoints at the lobe's zeros and peak, and the height
//! distribution integrated exactly (uniform: adaptive in H plus the clamped end masses; maps:
//! every distinct texel value, or 4096 bin means beyond that).

use crate::model::cross_section::{Fibre, Pattern, SectionPair};
use crate::model::numerics::quadrature::adaptive_gk15_vec;
use crate::model::parameter::Ability::*;
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::topology::{elevation_from_height, HeightLaw, Topology};
use crate::model::{Basis, DirectionPair, ShadingModel};
use std::f64::consts::{FRAC_1_PI, PI};

/// The rung.
pub static RUNG: Rung = Rung {
    name: "reference",
    description: "the exact geometry, to 1e-9 relative: the yardstick",
    abilities: &[
        FibreDiffuse,
        SpecularLobe,
        Fresnel,
        CrossSection,
        crate::model::Ability::Topology,
        FibreDirection,
        DirectionSpread,
    ],
    build: |a| Box::new(Reference::new(a.spacing, a.exponent, a.topology.clone())),
    sampling: Sampling {
        lobe: LobeSampling::FibreCone,
        diffuse_tube: 0.0,
        diffuse_cosine: 1.0,
        lobe_albedo: LobeAlbedo::ConeTable,
        cone_from: Some(&crate::model::rungs::varying_topology::RUNG),
    },
    shader: ShaderSection::None(
        "model `reference` has no shader: it integrates adaptively to 1e-8 and is the \
         yardstick, not a rung to render with; fit or export `varying-topology` (the same \
         parameters; reports/speed_accuracy.md gives its error against the reference per \
         quadrature order)",
    ),
    cost: Cost::Adaptive,
    auto_rank: None,
    example: crate::model::varying_topology::EXAMPLE,
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

/// Relative tolerance of each inner integral (the model promise is 1e-9).
const REL_TOL: f64 = 1e-12;

#[derive(Clone, Debug)]
pub struct Reference {
    spacing: f64,
    exponent: f64,
    law: HeightLaw,
}

impl Reference {
    pub fn new(spacing: f64, exponent: f64, topology: Topology) -> Self {
        let law = topology.exact_law(spacing);
        Self {
            spacing,
            exponent,
            law,
        }
    }

    fn pattern_at(&self, height: f64) -> Pattern {
        Pattern::new(self.spacing, elevation_from_height(height, self.spacing))
    }

    /// The basis for one pattern, every integral adaptive.
    pub fn pattern_basis(&self, pattern: &Pattern, sp: &SectionPair) -> Basis {
        let denom = pattern.period * sp.cos_alpha_product();
        if !(denom > 0.0) {
            return Basis::default();
        }
        let (al, av) = (sp.l.alpha, sp.v.alpha);
        let e = self.exponent;
        // Breakpoints: where r.v crosses zero (the lobe's kinks) and at its peak, plus a few
        // lobe widths either side so the adaptive rule finds sharp lobes at once.
        let centre = 0.5 * (al + av);
        let mut lobe_breaks = vec![centre];
        if let Some((w0, w1)) = sp.lobe_window(0.0) {
            lobe_breaks.extend([w0, w1]);
            let k = sp.l.len * sp.v.len;
            let peak = sp.mirror_cosine(centre);
            if peak > 0.0 && k > 0.0 {
                let width = (peak / (4.0 * k * e)).sqrt();
                for j in [2.0, 6.0, 20.0] {
                    lobe_breaks.extend([centre - j * width, centre + j * width]);
                }
            }
        }
        let (mut diffuse, mut specular) = (0.0, 0.0);
        for fibre in [Fibre::Even, Fibre::Odd] {
            for &(a, b) in sp.seen_and_lit(pattern, fibre).as_slice() {
                let mut breaks: Vec<f64> = lobe_breaks
                    .iter()
                    .copied()
                    .filter(|&t| t > a && t < b)
                    .collect();
                breaks.extend([a, b]);
                breaks.sort_unstable_by(f64::total_cmp);
                let r = adaptive_gk15_vec(&breaks, REL_TOL, 1e-300, |th| {
                    let cc = (th - al).cos() * (th - av).cos();
                    let rv = sp.mirror_cosine(th);
                    [cc, if rv > 0.0 { rv.powf(e) * cc } else { 0.0 }]
                });
                diffuse += r.value[0];
                specular += r.value[1];
            }
        }
        Basis {
            diffuse: FRAC_1_PI * diffuse / denom,
            specular: (e + 2.0) / (2.0 * PI) * specular / denom,
            substrate: FRAC_1_PI * pattern.substrate_fraction(&sp.l, &sp.v),
            fuzz: 0.0,
        }
    }
}

fn to_array(b: Basis) -> [f64; 3] {
    [b.diffuse, b.specular, b.substrate]
}

impl ShadingModel for Reference {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        let sp = SectionPair::new(&pair.l, &pair.v);
        match &self.law {
            HeightLaw::Point(h) => self.pattern_basis(&self.pattern_at(*h), &sp),
            HeightLaw::Discrete(nodes) => nodes.iter().fold(Basis::default(), |acc, (h, w)| {
                acc + (self.pattern_basis(&self.pattern_at(*h), &sp).scaled(*w))
            }),
            HeightLaw::Uniform { lo, hi, h_max } => {
                let width = hi - lo;
                let below = ((0.0 - lo) / width).clamp(0.0, 1.0);
                let above = ((hi - h_max) / width).clamp(0.0, 1.0);
                let (a, b) = (lo.max(0.0), hi.min(*h_max));
                let mut total = Basis::default();
                if below > 0.0 {
                    total = total + (self.pattern_basis(&self.pattern_at(0.0), &sp).scaled(below));
                }
                if above > 0.0 {
                    total = total
                        + (self
                            .pattern_basis(&self.pattern_at(*h_max), &sp)
                            .scaled(above));
                }
                if b > a {
                    let r = adaptive_gk15_vec(&[a, b], 1e-10, 1e-300, |h| {
                        to_array(self.pattern_basis(&self.pattern_at(h), &sp))
                    });
                    let [d, s, u] = r.value;
                    total = total
                        + (Basis {
                            diffuse: d,
                            specular: s,
                            substrate: u,
                            fuzz: 0.0,
                        }
                        .scaled(1.0 / width));
                }
                total
            }
        }
    }

    fn basis_at_height_above_horizon(&self, pair: &DirectionPair, height: f64) -> Option<Basis> {
        Some(self.pattern_basis(
            &self.pattern_at(height),
            &SectionPair::new(&pair.l, &pair.v),
        ))
    }
}
