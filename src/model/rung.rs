//! What a rung *is*, as one object: [`Rung`], declared by each rung's own file
//! (`model/rungs/`, as `pub static RUNG`). The registry (`model/rungs/mod.rs`) lists the rungs
//! and names them (`ModelId`).

use super::parameter::{Ability, Param, Scale};
use super::topology::Topology;
use super::ShadingModel;

/// What a rung is built from: the shape parameters and knobs of the aligned rung (no spread,
/// Fresnel factor or fuzz layer: `model::build` adds those over any rung).
#[derive(Clone, Debug)]
pub struct AlignedInputs<'a> {
    pub exponent: f64,
    /// Fibre spacing d, fibre radii.
    pub spacing: f64,
    pub alpha_x: f64,
    pub alpha_y: f64,
    pub quadrature_order: usize,
    pub histogram_bins: usize,
    pub topology: &'a Topology,
    /// The `gltf` rung's material (the table's defaults for the other rungs).
    pub gltf: super::params::GltfShape,
    /// The `principled` rung's material (the table's defaults for the other rungs).
    pub principled: super::params::PrincipledShape,
    /// The `openpbr` rung's material (the table's defaults for the other rungs).
    pub openpbr: super::params::OpenPbrShape,
}

/// How the importance sampler's lobe technique proposes directions for a rung.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeSampling {
    /// No lobe (diffuse rungs).
    None,
    /// Ward's lobe, sampled exactly.
    Ward,
    /// A Cauchy lobe about the fibre's mirror cone (width from the exponent).
    FibreCone,
    /// The anisotropic GGX lobe of the `gltf` rung: its visible normals, sampled exactly
    /// (Heitz 2018).
    Ggx,
}

/// How the sampler estimates the lobe's directional albedo (its mixture weight).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeAlbedo {
    /// A normalised lobe: 1.
    Normalised,
    /// cos^e about the mirror cone on one normal: pi W(e) cos(theta_r) (the Wallis integral).
    Wallis,
    /// From the rung's tabulated cone of lobe intensities.
    ConeTable,
}

/// The sampler's knowledge of a rung.
#[derive(Clone, Copy, Debug)]
pub struct Sampling {
    pub lobe: LobeSampling,
    /// Directional albedo per unit kd of the diffuse term sent to the tube technique and to
    /// the cosine technique.
    pub diffuse_tube: f64,
    pub diffuse_cosine: f64,
    pub lobe_albedo: LobeAlbedo,
    /// The rung whose aligned form tabulates the cone (the reference through
    /// varying-topology, which is it to the quadrature error); `None`: no table.
    pub cone_from: Option<&'static Rung>,
}

/// The rung's part of the exported shader (`export/shader/fibrefit.wgsl`).
#[derive(Clone, Copy, Debug)]
pub enum ShaderSection {
    /// The master's sections it needs (after `common`) and the body of `fibrefit_rung`.
    Sections {
        sections: &'static [&'static str],
        body: &'static str,
        /// The rows of `FibrefitParams::material` it bakes (a renderer material's values and
        /// its tables at them); `None`: one row of zeros.
        material_rows: Option<fn(&crate::model::ModelParams) -> Vec<[f64; 4]>>,
    },
    /// No shader, and why.
    None(&'static str),
}

/// How a rung's cost grows (benchmarks size their work by it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cost {
    /// A closed form.
    ClosedForm,
    /// A quadrature over the fibre's lobe.
    Quadrature,
    /// A quadrature per bin of a height histogram.
    HeightHistogram,
    /// Adaptive integration to 1e-9 (the yardstick).
    Adaptive,
}

/// A symmetry of a rung's parameters beyond the periodic ones of the parameter table: the
/// parameter sets it maps onto each other describe one BRDF, so a fit's minima are one solution
/// when their [`Rung::canonicalise`]d values agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Symmetry {
    /// The lobe's roughness along the fibres and across them swapped, with the fibre azimuth
    /// turned by 90 degrees (T -> B, B -> -T), is the same lobe. Canonical: `along >= across`.
    SwapAxes {
        /// The roughness along the fibres (T).
        along: Param,
        /// The roughness across the fibres (B).
        across: Param,
    },
}

impl Symmetry {
    /// Map `values` to this symmetry's canonical representative; a no-op unless every parameter
    /// it moves is among `values` (a held parameter makes the image a different solution).
    fn canonicalise(self, values: &mut [(Param, f64)]) {
        match self {
            Symmetry::SwapAxes { along, across } => {
                let find = |p: Param| values.iter().position(|v| v.0 == p);
                let (Some(a), Some(b), Some(z)) = (find(along), find(across), find(Param::Azimuth))
                else {
                    return;
                };
                if values[a].1 < values[b].1 {
                    let t = values[a].1;
                    values[a].1 = values[b].1;
                    values[b].1 = t;
                    values[z].1 += 90.0;
                }
            }
        }
    }
}

/// One rung of the ladder, declared in its own file.
pub struct Rung {
    /// The id as the CLI and JSON spell it.
    pub name: &'static str,
    /// What it accounts for, one line (for `--help` and reports).
    pub description: &'static str,
    /// What it can do; the parameters it reads follow (`ModelId::parameters`).
    pub abilities: &'static [Ability],
    /// The aligned rung from its shape parameters and knobs.
    pub build: fn(&AlignedInputs) -> Box<dyn ShadingModel>,
    pub sampling: Sampling,
    pub shader: ShaderSection,
    pub cost: Cost,
    /// Its place among the candidates `--model auto` tries by default, simplest first (the
    /// one-standard-error rule prefers the earlier); `None`: not a default candidate.
    pub auto_rank: Option<u8>,
    /// A typical parameter set (benchmarks, tests), values by parameter.
    pub example: &'static [(Param, f64)],
    /// The symmetries of its parameters beyond the table's periodic ones (the fibre azimuth's
    /// 180 degrees, T -> -T, holds for every rung): [`Rung::canonicalise`].
    pub symmetries: &'static [Symmetry],
    /// The renderer whose own material this rung is (an export carries its fit exactly, without
    /// the fuzz layer), in words; `--model auto` shows the best such candidate beside its choice.
    pub renderer: Option<&'static str>,
    /// Whether `--model auto` also tries it with the fuzz layer (`selection.fuzz`).
    pub auto_fuzz: bool,
}

impl Rung {
    /// Whether the rung has `ability`.
    pub fn has(&self, ability: Ability) -> bool {
        self.abilities.contains(&ability)
    }

    /// Map `values` (a parameter set's free values, or all of its values) to the canonical
    /// representative of their symmetry class: the rung's [`Symmetry`]s first (each only when
    /// every parameter it moves is among `values`), then every periodic parameter wrapped into
    /// its period centred on 0 (the fibre azimuth into [-90, 90)). Two minima whose canonical
    /// values agree are one solution.
    pub fn canonicalise(&self, values: &mut [(Param, f64)]) {
        for s in self.symmetries {
            s.canonicalise(values);
        }
        wrap_periodic(values);
    }

    /// The example as a parameter file's text, its exponent (when it has one) replaced by `e`.
    pub fn example_text(&self, exponent: Option<f64>) -> String {
        self.example
            .iter()
            .map(|&(p, v)| {
                let v = match exponent {
                    Some(e) if p == Param::Exponent => e,
                    _ => v,
                };
                format!("{} = {v}\n", p.name())
            })
            .collect()
    }
}

/// Every periodic parameter of `values` (the parameter table's `Scale::Periodic`) wrapped into
/// its period centred on 0: the fibre azimuth into [-90, 90).
pub fn wrap_periodic(values: &mut [(Param, f64)]) {
    for (p, v) in values.iter_mut() {
        if let Scale::Periodic(period) = p.info().scale {
            *v = (*v + 0.5 * period).rem_euclid(period) - 0.5 * period;
        }
    }
}

impl std::fmt::Debug for Rung {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Rung({})", self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonicalise_swaps_wards_axes_and_wraps_the_azimuth() {
        let ward = &crate::model::rungs::ward::RUNG;
        // the two minima: one lobe with its axes swapped
        let mut a = [
            (Param::AlphaX, 0.3516),
            (Param::AlphaY, 0.0805),
            (Param::Azimuth, -0.12),
        ];
        let mut b = [
            (Param::AlphaX, 0.0805),
            (Param::AlphaY, 0.3516),
            (Param::Azimuth, 89.88),
        ];
        ward.canonicalise(&mut a);
        ward.canonicalise(&mut b);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.0, y.0);
            assert!((x.1 - y.1).abs() < 1e-12, "{a:?} vs {b:?}");
        }
        assert!((a[2].1 + 0.12).abs() < 1e-12);
        // the azimuth's period (T -> -T), for every rung: into [-90, 90)
        let pf = &crate::model::rungs::poulin_fournier::RUNG;
        for (v, want) in [(100.0, -80.0), (-100.0, 80.0), (90.0, -90.0), (270.0, -90.0), (15.0, 15.0)] {
            let mut x = [(Param::Exponent, 30.0), (Param::Azimuth, v)];
            pf.canonicalise(&mut x);
            assert!((x[1].1 - want).abs() < 1e-12, "{v}: {x:?}");
            assert_eq!(x[0].1, 30.0);
        }
        // a held azimuth (absent from the free values): the swap is a different solution
        let mut held = [(Param::AlphaX, 0.08), (Param::AlphaY, 0.35)];
        ward.canonicalise(&mut held);
        assert_eq!(held, [(Param::AlphaX, 0.08), (Param::AlphaY, 0.35)]);
    }
}
