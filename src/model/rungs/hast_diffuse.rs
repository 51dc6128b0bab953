//! `hast-diffuse` (seed 000, Hast, Wesslén & Seipel): diffuse light summed over the lit upper half
//! of a fibre, with no viewer and no neighbours. I_d = (kd / pi) Phi, f = I_d / (N.l).
//!
//! The seed's eq. (10), Phi = (1/pi)(l.n_max)(1 - n_min.b) with n_min = (l x n_max)/|l x n_max|,
//! is 0/0 when l is perpendicular to t, and because l x n_max = (l.t)(t x n_max) its n_min follows
//! sign(l.t) while b = N x t flips with t. Derivation of a stable form: the upper-half normals are
//! n(th) = N cos th + B sin th, th in [-pi/2, pi/2], and n.l = |l_p| cos(th - alpha_l). Integrating
//! over the lit part th in [alpha_l - pi/2, pi/2] (for alpha_l >= 0; mirror for < 0) gives
//! |l_p| (1 + cos alpha_l), so
//!
//! ```text
//! Phi = (|l_p| + N.l) / pi,    |l_p| = sqrt(1 - (l.t)^2),
//! ```
//!
//! finite everywhere and invariant under t -> -t. It equals eq. (10) wherever l.t > 0
//! (checked in the tests), because there n_min = t x n_max and n_min.b = -cos alpha_l.

use crate::model::parameter::{Ability::*, Param};
use crate::model::rung::{Cost, LobeAlbedo, LobeSampling, Rung, Sampling, ShaderSection};
use crate::model::{Basis, DirectionPair, ShadingModel, Vec3};
use std::f64::consts::FRAC_1_PI;

/// The rung.
pub static RUNG: Rung = Rung {
    name: "hast-diffuse",
    description: "light summed over the lit half of a fibre (Hast et al.)",
    abilities: &[FibreDiffuse, FibreDirection, DirectionSpread],
    build: |_| Box::new(HastDiffuse),
    sampling: Sampling {
        lobe: LobeSampling::None,
        diffuse_tube: 0.5,
        diffuse_cosine: FRAC_1_PI,
        lobe_albedo: LobeAlbedo::Normalised,
        cone_from: None,
    },
    shader: ShaderSection::Sections {
        sections: &["hast_diffuse"],
        body: "    return fibrefit_hast_diffuse(l, v);\n",
        material_rows: None,
    },
    cost: Cost::ClosedForm,
    auto_rank: Some(1),
    example: &[(Param::Kd, 0.5)],
    symmetries: &[],
    renderer: None,
    auto_fuzz: true,
};

#[derive(Clone, Copy, Debug, Default)]
pub struct HastDiffuse;

/// Phi of seed 000 in the stable form, for a light with fibre-frame components `l`.
pub fn phi(l: &crate::model::Local) -> f64 {
    if l.n <= 0.0 {
        return 0.0;
    }
    FRAC_1_PI * (l.projected_len() + l.n)
}

/// Seed 000's eq. (10) exactly as printed (for comparison only: undefined when l.t = 0).
pub fn phi_eq10(l: &Vec3, t: &Vec3, b: &Vec3) -> f64 {
    let proj = l - t * l.dot(t);
    let n_max = proj / proj.norm();
    let cross = l.cross(&n_max);
    let n_min = cross / cross.norm();
    FRAC_1_PI * l.dot(&n_max) * (1.0 - n_min.dot(b))
}

impl ShadingModel for HastDiffuse {
    fn rung(&self) -> &'static Rung {
        &RUNG
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        Basis {
            diffuse: FRAC_1_PI * phi(&pair.l) / pair.l.n,
            ..Basis::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::frame::{direction_from_angles, FibreFrame};

    #[test]
    fn stable_phi_equals_eq10_where_l_dot_t_positive() {
        for psi in [0.0f64, 0.4, -1.1] {
            let fr = FibreFrame::from_azimuth(psi);
            for th in [0.05f64, 0.4, 0.9, 1.4] {
                for ph in [-2.5f64, -1.0, 0.1, 0.5, 1.2, 2.9] {
                    let l = direction_from_angles(th, ph);
                    if l.dot(&fr.t) <= 1e-6 {
                        continue;
                    }
                    let want = phi_eq10(&l, &fr.t, &fr.b);
                    let got = phi(&fr.to_local(&l));
                    assert!(
                        (got - want).abs() < 1e-12,
                        "psi {psi} th {th} ph {ph}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn eq10_breaks_where_the_stable_form_does_not() {
        let fr = FibreFrame::from_azimuth(0.0);
        // l perpendicular to t: eq. (10) is 0/0
        let l = Vec3::new(0.0, 0.5f64.sin(), 0.5f64.cos());
        assert!(phi_eq10(&l, &fr.t, &fr.b).is_nan());
        assert!(phi(&fr.to_local(&l)).is_finite());
        // l.t < 0: eq. (10) differs from its value with t flipped; the stable form does not
        let l = direction_from_angles(0.6, 2.5);
        let f = fr.flipped();
        assert!((phi_eq10(&l, &fr.t, &fr.b) - phi_eq10(&l, &f.t, &f.b)).abs() > 1e-3);
        assert_eq!(phi(&fr.to_local(&l)), phi(&f.to_local(&l)));
    }
}
