//! A fitted material as a renderer sees it: the BRDF, an importance sampler and its pdf at
//! directions in the swatch frame, with the result's per-texel maps looked up at texture
//! coordinates. The Python package's `fibrefit.Material` and its Mitsuba 3 plugin call this;
//! the shading itself is `render::Material` (the same code `fibrefit render` shades with) and
//! the sampler `model::sampling`.
//!
//! Frames: the swatch frame of the CLI's angles (z the macro normal, x the swatch's x axis,
//! the fibres at `fibre_azimuth_deg` from x towards y); `l` points towards the light, `v`
//! towards the viewer, both away from the surface. Texture coordinates (u, v) in [0, 1] span
//! the maps with v up the image (row 0 of a map at v = 1), as `render`'s swatch.

use crate::load::capture::Subsample;
use crate::load::capture_store::CaptureStore;
use crate::load::image_io::LinearImage;
use crate::load::texel_maps::TexelMapsIn;
use crate::model::frame::{Local, Vec3};
use crate::model::params::ModelParams;
use crate::model::sampling::{Draw, Instance, Sampler};
use crate::model::{self, ModelId, ShadingModel};
use crate::render::objects::Hit;
use crate::render::{Material as Shading, ShadingPoint};
use anyhow::{anyhow, bail, Result};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Rows per block of [`Material::sample_many`]: enough for the rung's lanes, few enough that
/// two threads share a million rows evenly.
const SAMPLE_BLOCK: usize = 256;

/// How far from unit length a given direction may be (it is normalised).
pub const UNIT_TOLERANCE: f64 = 1e-3;

/// What `eval` reads at each texel ([`Material::texel_fields`]), row by row from the top row.
#[derive(Clone, Debug)]
pub struct TexelFields {
    /// Texels per row, and rows.
    pub width: usize,
    /// Rows of texels.
    pub rows: usize,
    /// The fibres' height H (fibre radii) where the texel fixes one; NaN: the spot's height
    /// distribution (rungs without a topology: NaN everywhere).
    pub height: Vec<f64>,
    /// The fibres' diffuse albedo per channel (a grey result repeats its value).
    pub kd: Vec<[f64; 3]>,
    /// The specular lobe's weight per channel.
    pub ks: Vec<[f64; 3]>,
    /// The substrate's albedo per channel (kd where it is tied to it).
    pub substrate: Vec<[f64; 3]>,
    /// The texel's fibre azimuth minus the result's (radians), turning T towards B = N x T.
    pub azimuth_offset: Vec<f64>,
}

/// A loaded material (see the module docs).
pub struct Material {
    /// The rung of the result.
    pub model: ModelId,
    /// Its parameters (albedos linear, angles in radians, lengths in fibre radii).
    pub params: ModelParams,
    /// 3 for RGB results, 1 for grey.
    pub channels: usize,
    /// The result (or parameter) file it came from, and the maps directory used.
    pub source: PathBuf,
    /// The per-texel maps directory used, if any.
    pub maps_dir: Option<PathBuf>,
    /// The result's values its data did not determine (at a bound, held, flat cost): used as
    /// given, not measurements (each also among the loading's warnings).
    pub undetermined: Vec<crate::api::Undetermined>,
    shading: Box<dyn ShadingModel>,
    sampler: Sampler,
    /// The model one instance at a time ([`crate::model::build_instance`]), where the material
    /// mixes several (a spread, a height histogram).
    instance_model: Option<Box<dyn ShadingModel>>,
    texel_maps: Option<TexelMapsIn>,
}

/// One sampled direction in the swatch frame: `l`, `weight` = f cos(theta_l) / pdf per
/// channel, `pdf` in 1/sr. A failed sample (the view or the sampled direction at or below the
/// horizon) is `l` = 0, weight 0, pdf 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sampled {
    /// The sampled light direction (unit, swatch frame), or 0 when the sample failed.
    pub l: [f64; 3],
    /// f cos(theta_l) / pdf per channel (dimensionless).
    pub weight: [f64; 3],
    /// The sample's density, 1/sr.
    pub pdf: f64,
}

impl Material {
    /// The material of a result JSON (or a parameter file), with the maps in `maps` or, when
    /// `None`, those the result names (beside it); warnings about ignored parameters and maps
    /// not found are returned, not printed.
    pub fn load(result: &Path, maps: Option<&Path>) -> Result<(Self, Vec<String>)> {
        let raw = crate::export::result_json::read_params(result)?;
        let maps = match maps {
            Some(d) => Some(d.to_path_buf()),
            None => {
                crate::api::render::maps_dir(None, result, &crate::progress::Progress::quiet())?
            }
        };
        let (mut m, mut warnings) = Self::from_raw(raw, result, maps)?;
        m.set_undetermined(
            crate::export::result_json::undetermined_of(result),
            &mut warnings,
        );
        if m.texel_maps.is_none() {
            if let Ok(Some((named, looked))) = crate::api::render::named_maps_dir(result) {
                warnings.push(format!(
                    "{}: the material has no maps (pass maps=DIR)",
                    crate::api::render::missing_maps(result, &named, &looked)
                ));
            }
        }
        Ok((m, warnings))
    }

    /// The material of a result held in memory (`fibrefit.fit`'s), labelled `source`, with
    /// the maps in `maps`.
    pub fn from_result(
        result: &serde_json::Value,
        source: &Path,
        maps: Option<PathBuf>,
    ) -> Result<(Self, Vec<String>)> {
        let raw = crate::export::result_json::params_of_result(result)
            .map_err(|e| anyhow!("{}: {e:#}", source.display()))?;
        let (mut m, mut warnings) = Self::from_raw(raw, source, maps)?;
        m.set_undetermined(
            crate::export::result_json::undetermined_in(result),
            &mut warnings,
        );
        Ok((m, warnings))
    }

    /// Record the result's undetermined values, each with a warning.
    fn set_undetermined(
        &mut self,
        list: Vec<crate::api::Undetermined>,
        warnings: &mut Vec<String>,
    ) {
        for u in &list {
            warnings.push(format!(
                "{}: {}; used as given, not a measurement",
                self.source.display(),
                crate::fit::determined::warning(u)
            ));
        }
        self.undetermined = list;
    }

    fn from_raw(
        raw: crate::model::params::RawParams,
        result: &Path,
        maps_dir: Option<PathBuf>,
    ) -> Result<(Self, Vec<String>)> {
        let id_text = raw.model.clone().ok_or_else(|| {
            anyhow!(
                "{}: names no `model`; a fitted result or a parameter file with `model` is needed",
                result.display()
            )
        })?;
        let id: ModelId = id_text
            .parse()
            .map_err(|e: String| anyhow!("{}: {e}", result.display()))?;
        let (params, mut warnings) =
            ModelParams::from_raw(&raw, id).map_err(|e| anyhow!("{}: {e:#}", result.display()))?;
        for w in &mut warnings {
            *w = format!("{}: {w}", result.display());
        }
        let texel_maps = match &maps_dir {
            Some(d) => {
                let m = TexelMapsIn::load(d, None).map_err(|e| anyhow!("maps: {e:#}"))?;
                m.lobe_for(id, d).map_err(|e| anyhow!("maps: {e:#}"))?;
                Some(m)
            }
            None => None,
        };
        let shading = model::build(id, &params)?;
        let sampler = Sampler::new(id, &params);
        let instance_model = match sampler.instances() > 1 {
            true => Some(model::build_instance(id, &params)?),
            false => None,
        };
        Ok((
            Self {
                model: id,
                channels: params.albedos.channels(),
                params,
                source: result.to_path_buf(),
                maps_dir,
                undetermined: Vec::new(),
                shading,
                sampler,
                instance_model,
                texel_maps,
            },
            warnings,
        ))
    }

    /// The material with the per-texel fields of the capture TOML `capture` (its fibre
    /// azimuth from a tangent or azimuth map, its height map) where the result's own maps have
    /// none: what the fit of that capture saw at each pixel, so that the capture can be
    /// rendered as it was fitted.
    pub fn with_capture(mut self, capture: &Path) -> Result<Self> {
        let fields = CaptureStore::load(capture, Subsample::default())?.swatch_fields();
        if fields.psi_deg.is_none() && fields.height.is_none() {
            return Ok(self);
        }
        let size = fields
            .psi_deg
            .as_ref()
            .or(fields.height.as_ref())
            .map(|m| (m.width, m.height))
            .expect("one field");
        let mut maps = self.texel_maps.take().unwrap_or(TexelMapsIn {
            height: None,
            psi: None,
            kd: None,
            ks: None,
            roughness: None,
            anisotropy: None,
            lobe_params: vec![],
            width: size.0,
            rows: size.1,
        });
        if (maps.width, maps.rows) != size {
            bail!(
                "{}: its fields are {}x{} but the result's maps are {}x{}; they must be registered to one grid",
                capture.display(),
                size.0,
                size.1,
                maps.width,
                maps.rows
            );
        }
        if maps.psi.is_none() {
            maps.psi = fields.psi_deg;
        }
        if maps.height.is_none() && self.model.has_topology() {
            maps.height = fields.height;
        }
        self.texel_maps = Some(maps);
        Ok(self)
    }

    /// Whether per-texel maps are looked up at `uv`.
    pub fn has_maps(&self) -> bool {
        self.texel_maps.is_some()
    }

    /// (width, height) of the maps in texels.
    pub fn maps_size(&self) -> Option<(usize, usize)> {
        self.texel_maps.as_ref().map(|m| (m.width, m.rows))
    }

    /// What `eval` reads at each texel of the result's per-texel maps or topology map, so that a
    /// renderer can look it up itself: [`TexelFields`] on the maps' grid (a texel x =
    /// floor(u W), y = floor((1 - v) H), clamped; row 0 the top row), made by shading each
    /// texel's centre as `eval` does. `None` without maps or topology map, and where a texel's
    /// values are not fields of this kind: lobe maps (roughness, anisotropy: the renderers'
    /// materials rebuild their tables per texel), or a topology map on another grid than the
    /// maps'.
    pub fn texel_fields(&self) -> Option<TexelFields> {
        let topology = self.params.topology.map.as_deref();
        let (width, rows) = match (&self.texel_maps, topology) {
            (Some(m), _) if m.roughness.is_some() || m.anisotropy.is_some() => return None,
            (Some(m), Some(t)) if m.height.is_none() && self.model.has_topology() => {
                if (t.width, t.height) != (m.width, m.rows) {
                    return None;
                }
                (m.width, m.rows)
            }
            (Some(m), _) => (m.width, m.rows),
            (None, Some(t)) if self.model.has_topology() => (t.width, t.height),
            (None, _) => return None,
        };
        let shading = self.shading();
        let psi = self.params.fibre_azimuth;
        let channel = |c: usize| c.min(self.channels - 1);
        let mut f = TexelFields {
            width,
            rows,
            height: Vec::with_capacity(width * rows),
            kd: Vec::with_capacity(width * rows),
            ks: Vec::with_capacity(width * rows),
            substrate: Vec::with_capacity(width * rows),
            azimuth_offset: Vec::with_capacity(width * rows),
        };
        for y in 0..rows {
            for x in 0..width {
                let uv = [
                    (x as f64 + 0.5) / width as f64,
                    1.0 - (y as f64 + 0.5) / rows as f64,
                ];
                let sp = self.point(&shading, Some(uv));
                let a = &sp.albedos;
                f.height.push(sp.height.unwrap_or(f64::NAN));
                f.kd.push(std::array::from_fn(|c| a.diffuse[channel(c)]));
                f.ks.push(std::array::from_fn(|c| a.specular[channel(c)]));
                f.substrate
                    .push(std::array::from_fn(|c| a.substrate[channel(c)]));
                f.azimuth_offset.push(sp.t.y.atan2(sp.t.x) - psi);
            }
        }
        Some(f)
    }

    fn shading(&self) -> Shading<'_> {
        let p = &self.params;
        Shading {
            model: self.shading.as_ref(),
            albedos: p.albedos,
            channels: self.channels,
            spacing: p.spacing,
            height: p.topology.height,
            map_scale: p.topology.map_scale,
            topology_map: p.topology.map.as_deref(),
            texel_maps: self.texel_maps.as_ref(),
            fibre_azimuth_deg: p.fibre_azimuth.to_degrees(),
            ward_curvature: None,
            lobe: p.lobe(self.model),
            correction: p.correction.as_ref(),
        }
    }

    /// The shading point of the flat swatch at texture coordinates `uv` (`None`: the global
    /// parameters, no map lookup).
    fn point(&self, shading: &Shading, uv: Option<[f64; 2]>) -> ShadingPoint {
        let psi = self.params.fibre_azimuth;
        let hit = Hit {
            t: 0.0,
            position: Vec3::zeros(),
            normal: Vec3::z(),
            tangent: Vec3::new(psi.cos(), psi.sin(), 0.0),
            uv: uv.unwrap_or([0.5; 2]),
            height: None,
            curvature: None,
        };
        match uv {
            Some(_) => shading.point(&hit),
            None => Shading {
                texel_maps: None,
                topology_map: None,
                ..*shading
            }
            .point(&hit),
        }
    }

    /// The BRDF per channel (1/sr) for the light `l` and view `v` (unit, swatch frame); zero
    /// when either is at or below the horizon.
    pub fn eval(&self, l: &Vec3, v: &Vec3, uv: Option<[f64; 2]>) -> [f64; 3] {
        self.eval_instance(l, v, uv, None)
    }

    /// How many instances the material mixes (`model::sampling::Instance`: a
    /// fibre-direction spread's nodes times a height histogram's heights); 1 where its exact
    /// evaluation is one. Where a texel has its own height (a map), only its spread node is
    /// drawn.
    pub fn instances(&self) -> usize {
        self.sampler.instances()
    }

    /// The instance the uniform `instance` picks at the point `sp` (`None`: the material
    /// itself, or a material of one instance).
    fn instance_at(&self, sp: &ShadingPoint, instance: Option<f64>) -> Option<Instance> {
        self.instance_model.as_ref()?;
        instance.map(|u| self.sampler.instance(u, sp.height))
    }

    /// [`Material::eval`] of one instance of the material, the one the uniform `instance` in
    /// [0, 1) picks (`None`: the material itself): the same uniform picks the same instance in
    /// [`Material::pdf_instance`] and [`Material::sample_instance`], and the mean over uniform
    /// `instance` is [`Material::eval`] exactly.
    pub fn eval_instance(
        &self,
        l: &Vec3,
        v: &Vec3,
        uv: Option<[f64; 2]>,
        instance: Option<f64>,
    ) -> [f64; 3] {
        let shading = self.shading();
        let sp = self.point(&shading, uv);
        let (Some(inst), Some(m)) = (self.instance_at(&sp, instance), &self.instance_model) else {
            return shading.brdf(&sp, l, v);
        };
        let pair = model::DirectionPair {
            l: local(&sp, l),
            v: local(&sp, v),
        };
        shading.brdf_of(&sp, &pair, &inst.basis(m.as_ref(), &pair))
    }

    /// The sampler's density (1/sr) of `l` given `v`.
    pub fn pdf(&self, v: &Vec3, l: &Vec3, uv: Option<[f64; 2]>) -> f64 {
        self.pdf_instance(v, l, uv, None)
    }

    /// [`Material::pdf`] of the instance the uniform `instance` picks (`None`: the material's).
    pub fn pdf_instance(
        &self,
        v: &Vec3,
        l: &Vec3,
        uv: Option<[f64; 2]>,
        instance: Option<f64>,
    ) -> f64 {
        let shading = self.shading();
        let sp = self.point(&shading, uv);
        let (v, l) = (local(&sp, v), local(&sp, l));
        match self.instance_at(&sp, instance) {
            Some(inst) => self.sampler.pdf_instance(&sp.albedos, &inst, &v, &l),
            None => self.sampler.pdf(&sp.albedos, &v, &l),
        }
    }

    /// A light direction sampled for the view `v` from the uniforms `u` in [0, 1)^2.
    pub fn sample(&self, v: &Vec3, u: [f64; 2], uv: Option<[f64; 2]>) -> Sampled {
        self.sample_instance(v, u, uv, None)
    }

    /// [`Material::sample`] from the instance the uniform `instance` picks (`None`: the
    /// material's exact sampler): its weight is the instance's f cos / pdf, with
    /// [`Material::eval_instance`] and [`Material::pdf_instance`] of the same uniform.
    pub fn sample_instance(
        &self,
        v: &Vec3,
        u: [f64; 2],
        uv: Option<[f64; 2]>,
        instance: Option<f64>,
    ) -> Sampled {
        let shading = self.shading();
        let sp = self.point(&shading, uv);
        let v = local(&sp, v);
        let s = match (self.instance_at(&sp, instance), &self.instance_model) {
            (Some(inst), Some(m)) => {
                self.sampler
                    .sample_instance(m.as_ref(), &sp.albedos, &inst, &v, u)
            }
            _ => {
                let own = self.texel_model(&sp);
                let model = own.as_deref().unwrap_or(self.shading.as_ref());
                self.sampler.sample(model, &sp.albedos, sp.height, &v, u)
            }
        };
        self.sampled(&shading, &sp, &v, s)
    }

    /// The model at a shading point whose texel has its own lobe (a lobe map's roughness and
    /// anisotropy): what `eval` shades that texel with, so a sample's weight is the texel's
    /// f cos / pdf. `None`: the result's model. The proposal stays the result's (its pdf is
    /// exact for what it draws).
    fn texel_model(&self, sp: &ShadingPoint) -> Option<Box<dyn ShadingModel>> {
        sp.lobe.and_then(|l| self.shading.with_lobe(l))
    }

    /// [`Material::sample`] of a block of rows, the rung evaluated at all of them at once
    /// ([`Sampler::sample_many`]): the same values, bit for bit.
    fn sample_block(
        &self,
        v: &[Vec3],
        u: &[[f64; 2]],
        uv: Option<&[[f64; 2]]>,
        instance: Option<&[f64]>,
    ) -> Vec<Sampled> {
        let shading = self.shading();
        let points: Vec<ShadingPoint> = (0..v.len())
            .map(|i| self.point(&shading, uv.map(|c| c[i])))
            .collect();
        let draws: Vec<Draw> = points
            .iter()
            .zip(v.iter().zip(u))
            .map(|(sp, (v, u))| Draw {
                albedos: sp.albedos,
                height: sp.height,
                v: local(sp, v),
                u: *u,
            })
            .collect();
        let mut drawn = vec![None; draws.len()];
        if let (Some(r), Some(m)) = (instance, &self.instance_model) {
            let insts: Vec<Instance> = points
                .iter()
                .zip(r)
                .map(|(sp, &r)| self.sampler.instance(r, sp.height))
                .collect();
            self.sampler
                .sample_many_instances(m.as_ref(), &draws, &insts, &mut drawn);
        } else {
            let own: Vec<Option<Box<dyn ShadingModel>>> =
                points.iter().map(|sp| self.texel_model(sp)).collect();
            if own.iter().all(Option::is_none) {
                self.sampler
                    .sample_many(self.shading.as_ref(), &draws, &mut drawn);
            } else {
                // texels with their own lobe (lobe maps: a renderer's material, whose
                // evaluation gains nothing from a batch): row by row, each with its texel's model
                for ((d, m), o) in draws.iter().zip(&own).zip(drawn.iter_mut()) {
                    let m = m.as_deref().unwrap_or(self.shading.as_ref());
                    *o = self.sampler.sample(m, &d.albedos, d.height, &d.v, d.u);
                }
            }
        }
        points
            .iter()
            .zip(draws.iter().zip(drawn))
            .map(|(sp, (d, s))| self.sampled(&shading, sp, &d.v, s))
            .collect()
    }

    /// A sampler's draw at the point `sp` for the view `v` (fibre frame) as the caller sees it:
    /// in the swatch frame, the correction's factor in the weight, a grey result's channel
    /// repeated; a failed draw as zeros.
    fn sampled(
        &self,
        shading: &Shading,
        sp: &ShadingPoint,
        v: &Local,
        s: Option<crate::model::sampling::Sample>,
    ) -> Sampled {
        let Some(s) = s else {
            return Sampled {
                l: [0.0; 3],
                weight: [0.0; 3],
                pdf: 0.0,
            };
        };
        let l = sp.world(&Vec3::new(s.l.t, s.l.b, s.l.n));
        let mut weight = s.weight;
        if self.params.correction.is_some() {
            // the proposal is the rung's; its pdf stays exact, the weight carries the factor
            let pair = model::DirectionPair { l: s.l, v: *v };
            let f = shading.factor(&pair);
            for c in 0..3 {
                weight[c] *= f[c];
            }
        }
        for c in self.channels..3 {
            weight[c] = weight[0];
        }
        Sampled {
            l: [l.x, l.y, l.z],
            weight,
            pdf: s.pdf,
        }
    }

    /// [`Material::eval_instance`] of every row (in parallel), the inputs checked first;
    /// `instance`: a uniform per row picking its instance (`None`: the material itself).
    pub fn eval_many(
        &self,
        l: &[[f64; 3]],
        v: &[[f64; 3]],
        uv: Option<&[[f64; 2]]>,
        instance: Option<&[f64]>,
    ) -> Result<Vec<[f64; 3]>> {
        let (l, v) = (directions(l, "l")?, directions(v, "v")?);
        same_rows(&[("l", l.len()), ("v", v.len())])?;
        let uv = coordinates(uv, l.len())?;
        let instance = instance_uniforms(instance, l.len())?;
        Ok((0..l.len())
            .into_par_iter()
            .map(|i| self.eval_instance(&l[i], &v[i], uv.map(|u| u[i]), instance.map(|r| r[i])))
            .collect())
    }

    /// [`Material::pdf_instance`] of every row (in parallel), the inputs checked first.
    pub fn pdf_many(
        &self,
        v: &[[f64; 3]],
        l: &[[f64; 3]],
        uv: Option<&[[f64; 2]]>,
        instance: Option<&[f64]>,
    ) -> Result<Vec<f64>> {
        let (v, l) = (directions(v, "v")?, directions(l, "l")?);
        same_rows(&[("v", v.len()), ("l", l.len())])?;
        let uv = coordinates(uv, v.len())?;
        let instance = instance_uniforms(instance, v.len())?;
        Ok((0..v.len())
            .into_par_iter()
            .map(|i| self.pdf_instance(&v[i], &l[i], uv.map(|u| u[i]), instance.map(|r| r[i])))
            .collect())
    }

    /// [`Material::sample_instance`] of every row (in parallel), the inputs checked first.
    pub fn sample_many(
        &self,
        v: &[[f64; 3]],
        u: &[[f64; 2]],
        uv: Option<&[[f64; 2]]>,
        instance: Option<&[f64]>,
    ) -> Result<Vec<Sampled>> {
        let v = directions(v, "v")?;
        same_rows(&[("v", v.len()), ("u", u.len())])?;
        if let Some((i, x)) = u
            .iter()
            .enumerate()
            .find(|(_, x)| !x.iter().all(|c| (0.0..1.0).contains(c)))
        {
            bail!(
                "u row {i}: ({}, {}) is not in [0, 1)^2 (uniform random numbers are expected)",
                x[0],
                x[1]
            );
        }
        let uv = coordinates(uv, v.len())?;
        let instance = instance_uniforms(instance, v.len())?;
        // blocks of rows in parallel, each block's rung evaluated at once (in lanes)
        Ok(v.par_chunks(SAMPLE_BLOCK)
            .zip(u.par_chunks(SAMPLE_BLOCK))
            .enumerate()
            .flat_map_iter(|(k, (v, u))| {
                let at = k * SAMPLE_BLOCK;
                let rows = at..at + v.len();
                self.sample_block(
                    v,
                    u,
                    uv.map(|c| &c[rows.clone()]),
                    instance.map(|r| &r[rows]),
                )
            })
            .collect())
    }
}

impl Material {
    /// Image `index` of the capture `capture` as this material renders it, noise-free: per
    /// pixel f(l, v) E cos(theta_i) at the swatch point under the pixel's centre, with the maps
    /// looked up at the pixel's texel (uv = ((x + 0.5) / W, 1 - (y + 0.5) / H)); in the units of
    /// `load::capture_store::radiance_image` (radiance per unit irradiance, the exposure applied).
    /// Call it on [`Material::with_capture`] of the same capture to see what its fit saw.
    pub fn render_capture(&self, capture: &Path, index: usize) -> Result<LinearImage> {
        let store = CaptureStore::load(capture, Subsample::default())?;
        if index >= store.images() {
            bail!(
                "{}: image {index} asked for, but the capture has {} images",
                capture.display(),
                store.images()
            );
        }
        let (w, h, c) = (store.width, store.height, self.channels);
        let data: Vec<f32> = (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let store = &store;
                (0..w).flat_map(move |x| {
                    let uv = [
                        (x as f64 + 0.5) / w as f64,
                        1.0 - (y as f64 + 0.5) / h as f64,
                    ];
                    // NaN where a view map has no direction (no pixel there)
                    let (f, e, cos) = match store.geometry(index, x, y) {
                        Some((l, v, e)) => (self.eval(&l, &v, Some(uv)), e, l.z.max(0.0)),
                        None => ([f64::NAN; 3], 1.0, 1.0),
                    };
                    (0..c).map(move |k| (f[k] * e * cos) as f32)
                })
            })
            .collect();
        Ok(LinearImage {
            width: w,
            height: h,
            channels: c,
            saturated: vec![false; w * h],
            clip: f32::INFINITY,
            data,
        })
    }
}

/// The maps directory a result names, if any.
fn local(sp: &ShadingPoint, d: &Vec3) -> Local {
    let w = sp.local(d);
    Local {
        t: w.x,
        b: w.y,
        n: w.z,
    }
}

/// Rows of unit vectors, normalised; an error names the first row that is not finite or not
/// of unit length (within [`UNIT_TOLERANCE`]).
fn directions(rows: &[[f64; 3]], name: &str) -> Result<Vec<Vec3>> {
    rows.iter()
        .enumerate()
        .map(|(i, r)| {
            let d = Vec3::new(r[0], r[1], r[2]);
            if !r.iter().all(|x| x.is_finite()) {
                bail!(
                    "{name} row {i}: ({}, {}, {}) is not finite",
                    r[0],
                    r[1],
                    r[2]
                );
            }
            let n = d.norm();
            if (n - 1.0).abs() > UNIT_TOLERANCE {
                bail!(
                    "{name} row {i}: ({}, {}, {}) has length {n}; unit vectors are expected",
                    r[0],
                    r[1],
                    r[2]
                );
            }
            Ok(d / n)
        })
        .collect()
}

fn same_rows(arrays: &[(&str, usize)]) -> Result<()> {
    let (first, n) = arrays[0];
    for &(name, m) in &arrays[1..] {
        if m != n {
            bail!("{first} has {n} rows but {name} has {m}; one row per evaluation is expected");
        }
    }
    Ok(())
}

/// The instance uniforms, one per row in [0, 1), checked.
fn instance_uniforms(instance: Option<&[f64]>, rows: usize) -> Result<Option<&[f64]>> {
    let Some(r) = instance else {
        return Ok(None);
    };
    if r.len() != rows {
        bail!(
            "the directions have {rows} rows but instance has {}; one uniform per row is expected",
            r.len()
        );
    }
    if let Some((i, x)) = r.iter().enumerate().find(|(_, x)| !(0.0..1.0).contains(*x)) {
        bail!("instance row {i}: {x} is not in [0, 1) (uniform random numbers are expected)");
    }
    Ok(Some(r))
}

fn coordinates(uv: Option<&[[f64; 2]]>, rows: usize) -> Result<Option<&[[f64; 2]]>> {
    let Some(uv) = uv else { return Ok(None) };
    same_rows(&[("the directions", rows), ("uv", uv.len())])?;
    if let Some((i, c)) = uv
        .iter()
        .enumerate()
        .find(|(_, c)| !c.iter().all(|x| x.is_finite()))
    {
        bail!("uv row {i}: ({}, {}) is not finite", c[0], c[1]);
    }
    Ok(Some(uv))
}
