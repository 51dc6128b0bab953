//! What a rung *is*, as one object: [`Rung`], declared by each rung's own file
//! (`model/rungs/`, as `pub static RUNG`). The registry (`model/rungs/mod.rs`) lists the rungs
//! and names them (`ModelId`).

use super::parameter::{Ability, Param};
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
}

impl Rung {
    /// Whether the rung has `ability`.
    pub fn has(&self, ability: Ability) -> bool {
        self.abilities.contains(&ability)
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

impl std::fmt::Debug for Rung {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Rung({})", self.name)
    }
}
