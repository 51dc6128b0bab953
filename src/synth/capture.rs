//! Synthetic image captures: every image rendered pixel by pixel from the rung (with the
//! tangent, topology and recovered maps the capture uses), noised from one seeded stream per
//! image, written as EXR or 16-bit PNG, and described in `capture.toml`.

use super::{relative_to, write_file, CaptureSpec, Noise, SynthImage};
use crate::export::images;
use crate::load::capture::{self, Camera, CaptureFile, ImageSpec, Swatch};
use crate::load::image_io::Encoding;
use crate::load::texel_maps::TexelMapsIn as UnitMaps;
use crate::model::frame::FibreFrame;
use crate::model::params::ModelParams;
use crate::model::topology::TopologyMap;
use crate::model::{DirectionPair, ShadingModel};
use anyhow::{anyhow, bail, Result};
use indicatif::ProgressBar;
use rand::SeedableRng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// What rendering a capture needs: its spec, the model and its parameters, the noise, and
/// where the files go.
pub(super) struct CaptureRequest<'a> {
    pub spec: &'a CaptureSpec,
    /// The substrate albedo follows a kd map (the parameters give no substrate albedo).
    pub substrate_tied: bool,
    pub shading: &'a dyn ShadingModel,
    pub params: &'a ModelParams,
    pub noise: &'a Noise,
    pub out_dir: &'a Path,
    pub progress: &'a crate::progress::Progress,
}

/// Render the capture `req.spec` asks for into `req.out_dir`: the tangent map, every image,
/// the recovered maps it used and `capture.toml`. Returns the files written, in that order.
pub(super) fn render_capture(req: &CaptureRequest) -> Result<Vec<String>> {
    let c = req.spec;
    let format = ImageFormat::of(c)?;
    let mut files = Vec::new();
    let tangent_file = write_tangent(req, &mut files)?;
    let scene = CaptureScene::new(req, format, &tangent_file)?;
    let bar = req.progress.bar((c.images.len() * c.height) as u64, "rendering");
    let mut specs = Vec::new();
    for (k, img) in c.images.iter().enumerate() {
        if matches!(img.camera, Camera::ViewMap { .. }) {
            bail!("[[capture.images]] {k}: synth renders orthographic or pinhole cameras, not view maps");
        }
        let pixels = scene.render(img, &bar);
        let (file, spec) = scene.write_image(k, img, &pixels)?;
        files.push(file);
        specs.push(spec);
    }
    bar.finish_and_clear();
    scene.write_description(specs, tangent_file, &mut files)?;
    Ok(files)
}

/// How the images are stored: EXR, or 16-bit PNG with an encoding.
#[derive(Clone, Copy)]
struct ImageFormat {
    png: bool,
    encoding: Option<Encoding>,
}

impl ImageFormat {
    /// The spec's format, refused when unknown (or when the capture has no pixels or images).
    fn of(c: &CaptureSpec) -> Result<Self> {
        let (w, h) = (c.width, c.height);
        if w == 0 || h == 0 || c.images.is_empty() {
            bail!("[capture] needs width, height > 0 and at least one [[capture.images]]");
        }
        let png = match c.format.as_str() {
            "exr" => false,
            "png" => true,
            other => bail!("capture.format = '{other}': expected \"exr\" or \"png\""),
        };
        let encoding = if png {
            Some(c.encoding.unwrap_or(Encoding::Srgb))
        } else {
            None
        };
        Ok(Self { png, encoding })
    }
}

/// The fibre azimuth (radians) of pixel column `x`: the capture's tangent ramp, quantised
/// exactly as the tangent map stores it, or `default` without one.
fn tangent_psi(c: &CaptureSpec, default: f64, x: usize) -> f64 {
    match &c.tangent {
        Some(t) => {
            // quantised exactly as the tangent map stores it
            let m = ((x as f64 + 0.5) / c.width as f64 * 65535.0).round() / 65535.0;
            let deg = t.from_deg + (t.to_deg - t.from_deg) * m;
            deg.to_radians()
        }
        None => default,
    }
}

/// Write `tangent.png` when the capture has a tangent ramp; its name, relative to the output.
fn write_tangent(req: &CaptureRequest, files: &mut Vec<String>) -> Result<Option<PathBuf>> {
    let c = req.spec;
    let (w, h) = (c.width, c.height);
    let Some(t) = &c.tangent else {
        return Ok(None);
    };
    if !(-90.0..=90.0).contains(&t.from_deg) || !(-90.0..=90.0).contains(&t.to_deg) {
        bail!("capture.tangent: angles must lie in [-90, 90] degrees");
    }
    let default = req.params.fibre_azimuth;
    // stored as m with psi = -90 + 180 m
    let values: Vec<f32> = (0..h)
        .flat_map(|_| {
            (0..w).map(|x| ((tangent_psi(c, default, x).to_degrees() + 90.0) / 180.0) as f32)
        })
        .collect();
    images::write_gray16(&req.out_dir.join("tangent.png"), w, h, &values)?;
    files.push("tangent.png".to_string());
    Ok(Some(PathBuf::from("tangent.png")))
}

/// A capture being rendered: the request with the maps its pixels read.
struct CaptureScene<'a> {
    req: &'a CaptureRequest<'a>,
    format: ImageFormat,
    /// The tangent map as written (so pixels use exactly the stored angle).
    tangent_map: Option<TopologyMap>,
    topo_map: Option<std::sync::Arc<TopologyMap>>,
    unit_maps: Option<UnitMaps>,
    /// Channels of the images: 3 when the parameters or a kd or ks map are RGB.
    channels: usize,
}

impl<'a> CaptureScene<'a> {
    /// Read back the tangent map, check the topology map against the capture's size and load
    /// the recovered maps.
    fn new(
        req: &'a CaptureRequest<'a>,
        format: ImageFormat,
        tangent_file: &Option<PathBuf>,
    ) -> Result<Self> {
        let (c, p) = (req.spec, req.params);
        let (w, h) = (c.width, c.height);
        // Re-read the tangent map so pixels use exactly the stored angle.
        let tangent_map = match tangent_file {
            Some(f) => Some(TopologyMap::load(&req.out_dir.join(f))?),
            None => None,
        };
        let topo_map = p.topology.map.clone();
        if let Some(m) = &topo_map {
            if (m.width, m.height) != (w, h) {
                bail!(
                    "the topology map is {}x{} but the capture is {w}x{h}; they must be registered",
                    m.width,
                    m.height
                );
            }
        }
        let unit_maps = match &c.maps {
            Some(dir) => Some(
                UnitMaps::load(dir, Some((w, h)))
                    .map_err(|e| anyhow!("capture.maps = {}: {e:#}", dir.display()))?,
            ),
            None => None,
        };
        if let Some(m) = &unit_maps {
            let dir = c.maps.as_ref().expect("loaded from it");
            m.lobe_for(req.shading.id(), dir)
                .map_err(|e| anyhow!("capture.maps = {}: {e:#}", dir.display()))?;
            if m.psi.is_some() && c.tangent.is_some() {
                bail!("give capture.tangent or a fibre_azimuth.exr in capture.maps, not both");
            }
        }
        let mut channels = p.albedos.channels();
        if unit_maps.as_ref().is_some_and(|m| {
            [&m.kd, &m.ks]
                .iter()
                .any(|x| x.as_ref().is_some_and(|i| i.channels == 3))
        }) {
            channels = 3;
        }
        Ok(Self {
            req,
            format,
            tangent_map,
            topo_map,
            unit_maps,
            channels,
        })
    }

    /// Per pixel of image `img`, rows in parallel: the BRDF per channel and E cos(theta_i)
    /// (radiance = BRDF x that).
    fn render(&self, img: &SynthImage, bar: &ProgressBar) -> Vec<([f64; 3], f64)> {
        let (w, h) = (self.req.spec.width, self.req.spec.height);
        (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let row: Vec<([f64; 3], f64)> = (0..w).map(|x| self.pixel(img, x, y)).collect();
                bar.inc(1);
                row
            })
            .collect()
    }

    /// The BRDF per channel and E cos(theta_i) of image `img` at pixel (x, y), with the fibre
    /// azimuth, height and albedos the maps give there.
    fn pixel(&self, img: &SynthImage, x: usize, y: usize) -> ([f64; 3], f64) {
        let (c, p, shading) = (self.req.spec, self.req.params, self.req.shading);
        let (w, h) = (c.width, c.height);
        let pos = capture::pixel_position(c.size_mm, w, h, x, y);
        let (l, e) = capture::light_at(&img.light, &pos);
        let v = capture::view_at(&img.camera, &pos).expect("checked: not a view map");
        let um = self.unit_maps.as_ref();
        let psi = match (
            &self.tangent_map,
            um.and_then(|m| UnitMaps::at(&m.psi, x, y, 0)),
        ) {
            (_, Some(deg)) => deg.to_radians(),
            (Some(t), None) => (-90.0 + 180.0 * t.texel(x, y)).to_radians(),
            (None, None) => tangent_psi(c, p.fibre_azimuth, x),
        };
        let pair = DirectionPair::new(&FibreFrame::from_azimuth(psi), &l, &v);
        let height = um.and_then(|m| UnitMaps::at(&m.height, x, y, 0)).or(self
            .topo_map
            .as_ref()
            .map(|m| p.topology.texel_height(m.texel(x, y), p.spacing)));
        // a texel's own roughness and anisotropy (a renderer material's lobe maps)
        let lobe = um
            .and_then(|m| m.lobe_at(x, y, p.lobe(shading.id())))
            .and_then(|l| shading.with_lobe(l));
        let basis = match (height, lobe) {
            (_, Some(m)) => m.basis(&pair),
            (Some(hh), None) if shading.rung().has(crate::model::Ability::Topology) => {
                shading.basis_at_height(&pair, hh).unwrap_or_default()
            }
            _ => shading.basis(&pair),
        };
        let mut albedos = p.albedos;
        for ch in 0..3 {
            if let Some(k) = um.and_then(|m| UnitMaps::at(&m.kd, x, y, ch)) {
                albedos.diffuse[ch] = k;
                if self.req.substrate_tied {
                    albedos.substrate[ch] = k;
                }
            }
            if let Some(k) = um.and_then(|m| UnitMaps::at(&m.ks, x, y, ch)) {
                albedos.specular[ch] = k;
            }
        }
        (
            [0, 1, 2].map(|ch| basis.brdf(&albedos, ch)),
            e * l.z.max(0.0),
        )
    }

    /// Image `k` from its `pixels`: noised (in BRDF units, one seeded stream per image), as
    /// radiance, scaled to its exposure for PNG, and written. Its file's name and its entry of
    /// the capture file.
    fn write_image(
        &self,
        k: usize,
        img: &SynthImage,
        pixels: &[([f64; 3], f64)],
    ) -> Result<(String, ImageSpec)> {
        let (w, h, channels) = (self.req.spec.width, self.req.spec.height, self.channels);
        let (png, encoding) = (self.format.png, self.format.encoding);
        let noise = self.req.noise;
        // noise in BRDF units, per pixel and channel, from one seeded stream per image
        let mut rng =
            rand::rngs::StdRng::seed_from_u64(noise.spec.seed.wrapping_add(k as u64 * 7919));
        let mut data: Vec<f32> = Vec::with_capacity(w * h * channels);
        for (brdf, scale) in pixels {
            for &f in &brdf[..channels] {
                data.push((noise.apply(f, &mut rng) * scale) as f32);
            }
        }
        let exposure = if png {
            let max = data.iter().copied().fold(0.0f32, f32::max).max(1e-30);
            let exposure = (max / 0.8) as f64;
            for v in data.iter_mut() {
                *v = (*v as f64 / exposure) as f32;
            }
            exposure
        } else {
            1.0
        };
        let file = format!("img_{k:03}.{}", if png { "png" } else { "exr" });
        let path = self.req.out_dir.join(&file);
        if png {
            images::write_png16(
                &path,
                w,
                h,
                channels,
                &data,
                encoding.expect("png has encoding"),
            )?;
        } else {
            images::write_exr(&path, w, h, channels, &data)?;
        }
        let spec = ImageSpec {
            file: Some(file.clone().into()),
            bracket: vec![],
            encoding,
            exposure,
            saturation: None,
            noise: None,
            light: img.light.clone(),
            camera: img.camera.clone(),
        };
        Ok((file, spec))
    }

    /// Copy the recovered height and fibre azimuth maps beside the capture (they travel with
    /// it, as its maps) and write `capture.toml` describing the images `specs`.
    fn write_description(
        &self,
        specs: Vec<ImageSpec>,
        tangent_file: Option<PathBuf>,
        files: &mut Vec<String>,
    ) -> Result<()> {
        let (c, p, out_dir) = (self.req.spec, self.req.params, self.req.out_dir);
        // recovered maps travel with the capture, as its height and fibre azimuth maps
        let mut copy_map = |name: &str| -> Result<Option<PathBuf>> {
            let Some(dir) = &c.maps else { return Ok(None) };
            let src = dir.join(name);
            if !src.exists() {
                return Ok(None);
            }
            let bytes = crate::load::read_input(&src, crate::load::input::MAX_INPUT_BYTES)?.bytes;
            write_file(&out_dir.join(name), &bytes)?;
            files.push(name.to_string());
            Ok(Some(PathBuf::from(name)))
        };
        let height_map = copy_map("height.exr")?;
        let fibre_azimuth_map = copy_map("fibre_azimuth.exr")?;
        let capture_file = CaptureFile {
            scale_rel_se: None,
            swatch: Swatch {
                size_mm: c.size_mm,
                roi: None,
                mask: None,
                fibre_azimuth_deg: if tangent_file.is_none() && fibre_azimuth_map.is_none() {
                    Some(p.fibre_azimuth.to_degrees())
                } else {
                    None
                },
                tangent_map: tangent_file,
                topology_map: if height_map.is_none() {
                    self.topo_map
                        .as_ref()
                        .map(|m| relative_to(&m.source, out_dir))
                } else {
                    None
                },
                height_map,
                fibre_azimuth_map,
            },
            images: specs,
        };
        let text = format!(
            "# Image capture rendered by fibrefit synth ({}). Format: fibrefit docs/formats.md, \"Image captures\".\n{}",
            self.req.shading.id(),
            toml::to_string(&capture_file)?
        );
        write_file(&out_dir.join("capture.toml"), text.as_bytes())?;
        files.push("capture.toml".into());
        Ok(())
    }
}
