//! Forward models: the fibre shading ladder of MODEL.md §3, cheap to exact, behind one trait.
//!
//! Every model is linear in its albedos, so a model returns a [`Basis`]: the BRDF (1/sr) per unit
//! albedo of each linear component. The caller combines it with grey or RGB albedos; the fitter
//! can solve those exactly (separable least squares).

pub mod azimuth_spread;
pub mod correction;
pub mod cross_section;
pub mod frame;
pub mod fresnel;
pub mod fuzz;
pub mod numerics;
pub mod parameter;
pub mod params;
pub mod rung;
pub mod rungs;
pub mod sampling;
pub mod topology;

pub use frame::{DirectionPair, FibreFrame, Local, Vec3};
pub use parameter::{Ability, Param};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use params::{Albedo, ModelParams};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the tests and benchmarks
pub use rungs::{
    gltf, hast_diffuse, lambert, max_normal, poulin_fournier, reference, varying_topology, ward,
    AlignedInputs, ModelId, Rung,
};

/// BRDF (1/sr) per unit albedo of each linear component.
///
/// `diffuse` multiplies `kd` (Ward: `rho_d`), `specular` multiplies `ks` (Ward: `rho_s`),
/// `substrate` multiplies `substrate_albedo` and `fuzz` the fuzz layer's weight `fuzz`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Basis {
    pub diffuse: f64,
    pub specular: f64,
    pub substrate: f64,
    pub fuzz: f64,
}

impl Basis {
    pub fn scaled(self, w: f64) -> Basis {
        Basis {
            diffuse: self.diffuse * w,
            specular: self.specular * w,
            substrate: self.substrate * w,
            fuzz: self.fuzz * w,
        }
    }

    /// The BRDF for one colour channel of `albedos`.
    pub fn brdf(&self, albedos: &Albedos, channel: usize) -> f64 {
        self.diffuse * albedos.diffuse[channel]
            + self.specular * albedos.specular[channel]
            + self.substrate * albedos.substrate[channel]
            + self.fuzz * albedos.fuzz[channel]
    }

    pub fn is_finite(&self) -> bool {
        self.diffuse.is_finite()
            && self.specular.is_finite()
            && self.substrate.is_finite()
            && self.fuzz.is_finite()
    }
}

impl std::ops::Add for Basis {
    type Output = Basis;
    fn add(self, o: Basis) -> Basis {
        Basis {
            diffuse: self.diffuse + o.diffuse,
            specular: self.specular + o.specular,
            substrate: self.substrate + o.substrate,
            fuzz: self.fuzz + o.fuzz,
        }
    }
}

/// Albedos of the linear components, per channel (grey models repeat one value).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Albedos {
    pub diffuse: [f64; 3],
    pub specular: [f64; 3],
    pub substrate: [f64; 3],
    /// Weight of the fuzz layer (0 without one).
    pub fuzz: [f64; 3],
    /// Whether any albedo was given per channel.
    pub rgb: bool,
}

impl Albedos {
    pub fn grey(diffuse: f64, specular: f64, substrate: f64) -> Self {
        Self {
            diffuse: [diffuse; 3],
            specular: [specular; 3],
            substrate: [substrate; 3],
            fuzz: [0.0; 3],
            rgb: false,
        }
    }

    pub fn channels(&self) -> usize {
        if self.rgb {
            3
        } else {
            1
        }
    }
}

/// One rung of the ladder. Implementations check their ranges at construction so evaluation is
/// cheap and never produces NaN.
pub trait ShadingModel: Send + Sync {
    /// The rung this model is (its registry entry).
    fn rung(&self) -> &'static Rung;

    /// The rung's id.
    fn id(&self) -> ModelId {
        ModelId::of(self.rung())
    }

    /// The basis for a pair with both directions strictly above the horizon.
    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis;

    /// This model with its lobe's roughness and anisotropy replaced (one texel of a roughness
    /// or anisotropy map), everything else as it is; `None` for rungs without such a lobe (the
    /// renderers' materials have one: [`LobeRole`]). Cheap: what the lobe does not touch
    /// (tables, layers) is kept.
    fn with_lobe(&self, _lobe: Lobe) -> Option<Box<dyn ShadingModel>> {
        None
    }

    /// The basis with the fibre topology fixed at one height H (one texel), for models that have
    /// a topology; `None` otherwise.
    fn basis_at_height_above_horizon(&self, _pair: &DirectionPair, _height: f64) -> Option<Basis> {
        None
    }

    /// The basis; zero when either direction is at or below the horizon (MODEL.md §1).
    fn basis(&self, pair: &DirectionPair) -> Basis {
        if pair.above_horizon() {
            self.basis_above_horizon(pair)
        } else {
            Basis::default()
        }
    }

    /// [`ShadingModel::basis`] of every pair, into `out` (same length). Equal to calling
    /// `basis` pair by pair; rungs that gain from seeing many pairs at once (the cross-section
    /// rungs batch their specular quadrature) override it. Evaluate data through this.
    fn basis_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        assert_eq!(pairs.len(), out.len());
        for (p, o) in pairs.iter().zip(out.iter_mut()) {
            *o = self.basis(p);
        }
    }

    /// The basis at one height (see [`ShadingModel::basis_at_height_above_horizon`]).
    fn basis_at_height(&self, pair: &DirectionPair, height: f64) -> Option<Basis> {
        if !self.rung().has(crate::model::Ability::Topology) {
            None
        } else if pair.above_horizon() {
            self.basis_at_height_above_horizon(pair, height)
        } else {
            Some(Basis::default())
        }
    }

    /// [`ShadingModel::basis_at_height`] of every pair at one height, into `out` (same
    /// length); `false`, `out` untouched, for models without a topology. Equal to calling it
    /// pair by pair, bit for bit; the cross-section rungs batch the pairs (one texel seen in
    /// many images is one pattern and many pairs).
    fn basis_many_at_height(
        &self,
        pairs: &[DirectionPair],
        height: f64,
        out: &mut [Basis],
    ) -> bool {
        assert_eq!(pairs.len(), out.len());
        if !self.rung().has(crate::model::Ability::Topology) {
            return false;
        }
        for (p, o) in pairs.iter().zip(out.iter_mut()) {
            *o = self.basis_at_height(p, height).unwrap_or_default();
        }
        true
    }

    /// [`ShadingModel::basis_at_height`] of each pair at its own height (`heights`, same
    /// length), into `out`; `false`, `out` untouched, for models without a topology. Equal to
    /// calling it pair by pair, bit for bit; the cross-section rungs batch the pairs (a
    /// sampler's draws, each at its texel's height).
    fn basis_many_at_each_height(
        &self,
        pairs: &[DirectionPair],
        heights: &[f64],
        out: &mut [Basis],
    ) -> bool {
        assert_eq!(pairs.len(), out.len());
        assert_eq!(pairs.len(), heights.len());
        if !self.rung().has(crate::model::Ability::Topology) {
            return false;
        }
        for ((p, &h), o) in pairs.iter().zip(heights).zip(out.iter_mut()) {
            *o = self.basis_at_height(p, h).unwrap_or_default();
        }
        true
    }
}

/// A lobe's per-texel shape ([`ShadingModel::with_lobe`]): GGX roughness and anisotropy, in
/// the units of the rung's own parameters of those [`LobeRole`]s (`gltf`: `roughness`,
/// `anisotropy_strength`; `principled`: `roughness`, `anisotropic`; `openpbr`:
/// `specular_roughness`, `specular_roughness_anisotropy`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    pub roughness: f64,
    pub anisotropy: f64,
}

/// The two values of a lobe a texel map can carry ([`Lobe`]): each rung with such a lobe names
/// them its own way ([`crate::model::ModelId::lobe_param`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeRole {
    /// The GGX roughness r (alpha = r^2): `gltf`'s and `principled`'s `roughness`, `openpbr`'s
    /// `specular_roughness`.
    Roughness,
    /// The anisotropy: `gltf`'s `anisotropy_strength`, `principled`'s `anisotropic`,
    /// `openpbr`'s `specular_roughness_anisotropy`.
    Anisotropy,
}

impl LobeRole {
    /// Both roles, roughness first.
    pub const BOTH: [LobeRole; 2] = [LobeRole::Roughness, LobeRole::Anisotropy];
}

/// A BRDF per channel (1/sr) as a function of the swatch-frame directions (l, v); `None` where
/// it is not defined (outside a measured file's range). Fitted models and measured files alike.
pub type BrdfFn = Box<dyn Fn(&Vec3, &Vec3) -> Option<[f64; 3]> + Sync>;

/// A change to a rung's basis made pair by pair: the Fresnel factor on the lobe, the fuzz layer.
pub trait BasisTransform: Send + Sync {
    fn apply(&self, pair: &DirectionPair, b: Basis) -> Basis;
}

/// A rung with a [`BasisTransform`] on its basis (zero at and below the horizon, as every rung).
pub struct Transformed<T> {
    inner: Box<dyn ShadingModel>,
    transform: T,
}

impl<T: BasisTransform> Transformed<T> {
    pub fn with(inner: Box<dyn ShadingModel>, transform: T) -> Self {
        Self { inner, transform }
    }

    /// The transform on the inner rung's bases `out` of `pairs` (zero below the horizon).
    fn apply_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        for (p, o) in pairs.iter().zip(out.iter_mut()) {
            *o = if p.above_horizon() {
                self.transform.apply(p, *o)
            } else {
                Basis::default()
            };
        }
    }
}

impl<T: BasisTransform + Clone + 'static> ShadingModel for Transformed<T> {
    fn rung(&self) -> &'static Rung {
        self.inner.rung()
    }

    fn with_lobe(&self, lobe: Lobe) -> Option<Box<dyn ShadingModel>> {
        let inner = self.inner.with_lobe(lobe)?;
        Some(Box::new(Transformed::with(inner, self.transform.clone())))
    }

    fn basis_above_horizon(&self, pair: &DirectionPair) -> Basis {
        self.transform.apply(pair, self.inner.basis(pair))
    }

    fn basis_at_height_above_horizon(&self, pair: &DirectionPair, height: f64) -> Option<Basis> {
        self.inner
            .basis_at_height(pair, height)
            .map(|b| self.transform.apply(pair, b))
    }

    fn basis_many(&self, pairs: &[DirectionPair], out: &mut [Basis]) {
        self.inner.basis_many(pairs, out);
        self.apply_many(pairs, out);
    }

    fn basis_many_at_height(
        &self,
        pairs: &[DirectionPair],
        height: f64,
        out: &mut [Basis],
    ) -> bool {
        if !self.inner.basis_many_at_height(pairs, height, out) {
            return false;
        }
        self.apply_many(pairs, out);
        true
    }

    fn basis_many_at_each_height(
        &self,
        pairs: &[DirectionPair],
        heights: &[f64],
        out: &mut [Basis],
    ) -> bool {
        if !self.inner.basis_many_at_each_height(pairs, heights, out) {
            return false;
        }
        self.apply_many(pairs, out);
        true
    }
}

/// [`ShadingModel::basis_at_height`] of each pair at its own height, into `out`: the pairs of
/// equal heights batched through [`ShadingModel::basis_many_at_height`] (a capture's texel is
/// seen in many images; 8- and 16-bit maps repeat heights). Equal to pair by pair, bit for bit.
/// For models without a topology, the plain basis.
pub fn bases_at_heights(
    m: &dyn ShadingModel,
    pairs: &[DirectionPair],
    heights: &[f64],
    out: &mut [Basis],
) {
    assert_eq!(pairs.len(), heights.len());
    assert_eq!(pairs.len(), out.len());
    if !m.rung().has(crate::model::Ability::Topology) {
        m.basis_many(pairs, out);
        return;
    }
    let mut order: Vec<usize> = (0..pairs.len()).collect();
    order.sort_by_key(|&i| heights[i].to_bits());
    let (mut run_pairs, mut run_out) = (Vec::new(), Vec::new());
    for run in order.chunk_by(|&a, &b| heights[a].to_bits() == heights[b].to_bits()) {
        run_pairs.clear();
        run_pairs.extend(run.iter().map(|&i| pairs[i]));
        run_out.clear();
        run_out.resize(run.len(), Basis::default());
        m.basis_many_at_height(&run_pairs, heights[run[0]], &mut run_out);
        for (&i, b) in run.iter().zip(&run_out) {
            out[i] = *b;
        }
    }
}

/// Shaded intensity I = f (N.l) (MODEL.md §1), zero below the horizon.
pub fn intensity(brdf: f64, pair: &DirectionPair) -> f64 {
    if pair.above_horizon() {
        brdf * pair.l.n
    } else {
        0.0
    }
}

/// BRDF per channel of a model at one direction pair given in degrees (theta_i, phi_i, theta_o,
/// phi_o), fibres at azimuth `psi` (radians); spot-averaged.
pub fn brdf_at_degrees(
    m: &dyn ShadingModel,
    albedos: &Albedos,
    psi: f64,
    d: [f64; 4],
    channels: usize,
) -> Vec<f64> {
    let l = frame::direction_from_angles(d[0].to_radians(), d[1].to_radians());
    let v = frame::direction_from_angles(d[2].to_radians(), d[3].to_radians());
    let b = m.basis(&DirectionPair::new(
        &frame::FibreFrame::from_azimuth(psi),
        &l,
        &v,
    ));
    (0..channels).map(|c| b.brdf(albedos, c)).collect()
}

/// Build the model `id` from validated parameters (averaged over the fibre-direction spread
/// when it is not 0, under a fuzz layer when its depth is not 0).
pub fn build(id: ModelId, p: &ModelParams) -> anyhow::Result<Box<dyn ShadingModel>> {
    Ok(with_fuzz(
        with_spread(
            with_fresnel(build_aligned(id, p), p.fresnel_ior),
            p.azimuth_spread_deg,
            p.azimuth_nodes,
            p.fibre_azimuth,
        ),
        p.fuzz_depth,
        p.fuzz_asymmetry,
    ))
}

/// The model one [`sampling::Instance`] at a time: [`build`] without the fibre-direction spread
/// (the instance turns the pair itself; the Fresnel factor and the fuzz layer are kept: both
/// depend on the pair only through angles a turn about N keeps). The `reference` integrates its
/// spread adaptively and has no instances: [`build`] itself.
pub fn build_instance(id: ModelId, p: &ModelParams) -> anyhow::Result<Box<dyn ShadingModel>> {
    if id.rung().cost == rung::Cost::Adaptive {
        return build(id, p);
    }
    Ok(with_fuzz(
        with_fresnel(build_aligned(id, p), p.fresnel_ior),
        p.fuzz_depth,
        p.fuzz_asymmetry,
    ))
}

/// `m` under a fuzz layer of optical depth `depth` and phase asymmetry `g` (any rung; `depth` 0:
/// `m` itself).
pub fn with_fuzz(m: Box<dyn ShadingModel>, depth: f64, g: f64) -> Box<dyn ShadingModel> {
    if depth > 0.0 {
        Box::new(fuzz::FuzzLayer::new(m, depth, g))
    } else {
        m
    }
}

/// `m` with a Fresnel factor on its specular lobe (rungs with a lobe; `ior` 0: `m` itself).
pub fn with_fresnel(m: Box<dyn ShadingModel>, ior: f64) -> Box<dyn ShadingModel> {
    if ior > 0.0 && m.rung().has(Ability::Fresnel) {
        Box::new(fresnel::FresnelLobe::new(m, ior))
    } else {
        m
    }
}

/// `m` averaged over a fibre-direction spread of `spread_deg` (rungs that take one; 0: `m`
/// itself).
pub fn with_spread(
    m: Box<dyn ShadingModel>,
    spread_deg: f64,
    nodes: usize,
    psi: f64,
) -> Box<dyn ShadingModel> {
    if spread_deg > 0.0 && m.rung().has(Ability::DirectionSpread) {
        Box::new(azimuth_spread::AzimuthSpread::new(
            m, spread_deg, nodes, psi,
        ))
    } else {
        m
    }
}

/// The aligned rung `id` (no spread, Fresnel factor or fuzz layer) from validated parameters.
pub fn build_aligned(id: ModelId, p: &ModelParams) -> Box<dyn ShadingModel> {
    (id.rung().build)(&AlignedInputs {
        exponent: p.exponent,
        spacing: p.spacing,
        alpha_x: p.alpha_x,
        alpha_y: p.alpha_y,
        quadrature_order: p.quadrature_order,
        histogram_bins: p.histogram_bins,
        topology: &p.topology,
        gltf: p.gltf,
        principled: p.principled,
        openpbr: p.openpbr,
    })
}
