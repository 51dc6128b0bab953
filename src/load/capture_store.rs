//! An image capture's pixels held compactly and grouped by texel: what lets a fit work at camera
//! resolution (8 images x 1 Mpx and beyond).
//!
//! The images are decoded one at a time; of each, only the raw value of every kept pixel stays,
//! as f32 in a texel-major array `[texel][image][channel]` (NaN: the texel has no sample in
//! that image), so a texel's pixels lie side by side. Everything else a [`Sample`] holds is
//! computed on demand, in f64 and exactly as the loader always did: the light and view
//! directions and the irradiance from the image's geometry and the pixel's position, the BRDF
//! value from the raw value, the exposure and the irradiance, and the texel's topology, height
//! and fibre azimuth from the capture's maps (kept as loaded, one f32 per pixel). Storage:
//! 4 B per channel and pixel value, 8 B per texel, 4 B per pixel for the texel index, and the
//! maps the capture gives (4 B per pixel each; a view map 12 B per pixel and image), where a
//! vector of [`Sample`]s took ~160 B per pixel value and a fit ~1000 B
//! (`CaptureStore::bytes`; `tests/capture_store.rs` keeps it from regressing).
//!
//! Precision: the raw values are the decoded image's own f32 (PNG codes and EXR half/float
//! values are exact in f32), so nothing is lost: samples made from the store equal, bit for
//! bit, those of the loader before the store existed.

use super::bracket::{self, ImageNoise};
use super::capture::{
    check_image_spec, check_no_negatives, check_size, light_at, pixel_position, resolve, view_at,
    Camera, CaptureFile, ImageSpec, Subsample,
};
use super::image_io::{self, LinearImage};
use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::Vec3;
use crate::model::topology::TopologyMap;
use anyhow::{anyhow, bail, Result};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Texels drawn together by [`CaptureStore::sample_texels`].
pub const SAMPLE_RUN: usize = 4;

/// No texel at this pixel (outside the ROI or masked, or no usable sample).
const NO_TEXEL: u32 = u32::MAX;

/// A capture's kept pixels, grouped by texel (texels row-major).
pub struct CaptureStore {
    pub source: PathBuf,
    pub width: usize,
    pub height: usize,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    pub dropped: Dropped,
    desc: CaptureFile,
    /// (x, y) of every texel with at least one sample, row-major.
    texels: Vec<(u32, u32)>,
    /// Texel index of every pixel (row-major), [`NO_TEXEL`] where there is none.
    index: Vec<u32>,
    /// Raw pixel values `[texel][image][channel]`; NaN where the texel has no sample.
    values: Vec<f32>,
    topology: Option<TopologyMap>,
    tangent: Option<TopologyMap>,
    height_map: Option<LinearImage>,
    azimuth_map: Option<LinearImage>,
    view_maps: Vec<Option<LinearImage>>,
    /// Per image, the noise of its values when the capture has exposure brackets (empty when
    /// it has none: then samples carry no sigma).
    noise: Vec<ImageNoise>,
}

impl CaptureStore {
    /// Load the capture described by the TOML at `path`, keeping the pixels `subsample` keeps.
    pub fn load(path: &Path, subsample: Subsample) -> Result<Self> {
        let desc = CaptureFile::load(path)?;
        let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let name = path.display().to_string();
        check_description(&name, &desc, subsample)?;
        // every image must have the first's size: the whole capture's memory is known from the
        // first image's header, before any pixel is decoded
        // (a header that cannot be read is left to the image's own reading, whose error
        // says why in the words of its checks)
        if let Ok((w0, h0, c0)) = image_io::header(&resolve(&base, desc.images[0].frames()[0].0)) {
            check_capture_memory(&name, &desc, (w0, h0), c0)?;
        }
        let first = read_image(&base, &desc.images[0])?;
        let (w, h, channels) = (first.image.width, first.image.height, first.image.channels);
        let maps = SwatchMaps::load(&base, &desc, (w, h))?;
        let (index, texels) = candidate_texels(&name, desc.swatch.roi, maps.mask.as_ref(), (w, h))?;
        let images = desc.images.len();
        let mut dropped = Dropped {
            masked: ((w * h - texels.len()) * images) as u64,
            ..Dropped::default()
        };
        let mut store = Self {
            source: path.to_path_buf(),
            width: w,
            height: h,
            channels,
            dropped: Dropped::default(),
            desc,
            texels,
            index,
            values: vec![],
            topology: maps.topology,
            tangent: maps.tangent,
            height_map: maps.height_map,
            azimuth_map: maps.azimuth_map,
            view_maps: maps.view_maps,
            noise: vec![],
        };
        let read = store.read_values(&base, first, subsample, &mut dropped)?;
        store.keep_sampled_texels(&name, read.values, &dropped)?;
        store.dropped = dropped;
        let given: Vec<bool> = store.desc.images.iter().map(|s| s.noise.is_some()).collect();
        store.noise = capture_noise(&name, read.noise, &read.noise_rows, &given)?;
        Ok(store)
    }

    /// Read every image in turn (the first is read already) and keep, of each, the raw value of
    /// every candidate texel's pixel that is usable; the others are counted in `dropped`.
    fn read_values(
        &self,
        base: &Path,
        first: ReadImage,
        subsample: Subsample,
        dropped: &mut Dropped,
    ) -> Result<ReadValues> {
        let (w, h, channels) = (self.width, self.height, self.channels);
        let images = self.desc.images.len();
        let mut values = vec![f32::NAN; self.texels.len() * images * channels];
        let mut img = Some(first);
        let mut noise = Vec::with_capacity(images);
        let mut noise_rows: Vec<Vec<[f64; 9]>> = vec![vec![]; channels];
        for k in 0..images {
            let read = match img.take() {
                Some(i) => i,
                None => read_image(base, &self.desc.images[k])?,
            };
            let img_k = read.image;
            if let Some(r) = read.rows {
                for (c, rows) in r.0.into_iter().enumerate() {
                    noise_rows[c].extend(rows);
                }
            }
            noise.push((read.noise, img_k.clip));
            let spec = &self.desc.images[k];
            let file = resolve(base, spec.frames()[0].0);
            check_size("image", &file, (img_k.width, img_k.height), (w, h))?;
            if img_k.channels != channels {
                bail!(
                    "{}: has {} channels, the first image {channels}; all images must match",
                    file.display(),
                    img_k.channels
                );
            }
            self.keep_pixels(k, &img_k, subsample, &mut values, dropped);
        }
        Ok(ReadValues {
            values,
            noise,
            noise_rows,
        })
    }

    /// Copy into `values` the pixel of image `k` at every candidate texel that subsampling
    /// keeps, that is not saturated, finite (and its maps too) and lit and seen from above the
    /// horizon; count the others in `dropped`.
    fn keep_pixels(
        &self,
        k: usize,
        img_k: &LinearImage,
        subsample: Subsample,
        values: &mut [f32],
        dropped: &mut Dropped,
    ) {
        let (w, channels) = (self.width, self.channels);
        let images = self.desc.images.len();
        for (t, &(x, y)) in self.texels.iter().enumerate() {
            let (x, y) = (x as usize, y as usize);
            if !subsample.keeps(k, x, y) {
                dropped.subsampled += 1;
                continue;
            }
            if img_k.saturated[y * w + x] {
                dropped.saturated += 1;
                continue;
            }
            let px = img_k.pixel(x, y);
            let map_nan =
                |m: &Option<LinearImage>| m.as_ref().is_some_and(|m| m.pixel(x, y)[0].is_nan());
            if px.iter().any(|v| !v.is_finite())
                || map_nan(&self.height_map)
                || map_nan(&self.azimuth_map)
            {
                dropped.invalid += 1;
                continue;
            }
            match self.geometry(k, x, y) {
                None => dropped.invalid += 1,
                Some((l, v, e)) if l.z <= 0.0 || v.z <= 0.0 || !(e > 0.0) => {
                    dropped.below_horizon += 1
                }
                Some(_) => {
                    let i = (t * images + k) * channels;
                    values[i..i + channels].copy_from_slice(px);
                }
            }
        }
    }

    /// Keep the texels with a sample (and their `values`), renumbering the texel index;
    /// refused when no texel has one.
    fn keep_sampled_texels(
        &mut self,
        name: &str,
        mut values: Vec<f32>,
        dropped: &Dropped,
    ) -> Result<()> {
        let w = self.width;
        let per_texel = self.desc.images.len() * self.channels;
        let keep: Vec<bool> = values
            .chunks(per_texel)
            .map(|c| c.iter().any(|v| !v.is_nan()))
            .collect();
        if !keep.iter().any(|&k| k) {
            let d = dropped;
            bail!(
                "{name}: no usable pixels: {} masked or outside the ROI, {} saturated, {} with light or view at or below the horizon, {} non-finite, {} subsampled away",
                d.masked, d.saturated, d.below_horizon, d.invalid, d.subsampled
            );
        }
        if keep.iter().any(|&k| !k) {
            let mut kept_values = Vec::with_capacity(values.len());
            let mut kept_texels = Vec::new();
            self.index.fill(NO_TEXEL);
            for (t, chunk) in values.chunks(per_texel).enumerate() {
                if keep[t] {
                    let (x, y) = self.texels[t];
                    self.index[y as usize * w + x as usize] = kept_texels.len() as u32;
                    kept_texels.push((x, y));
                    kept_values.extend_from_slice(chunk);
                }
            }
            self.texels = kept_texels;
            values = kept_values;
        }
        values.shrink_to_fit();
        self.texels.shrink_to_fit();
        self.values = values;
        Ok(())
    }

    /// Light direction, view direction and perpendicular irradiance of image `k` at pixel
    /// (x, y); `None` where a view map has no direction.
    pub fn geometry(&self, k: usize, x: usize, y: usize) -> Option<(Vec3, Vec3, f64)> {
        let spec = &self.desc.images[k];
        let p = pixel_position(self.desc.swatch.size_mm, self.width, self.height, x, y);
        let (l, e) = light_at(&spec.light, &p);
        let v = match &self.view_maps[k] {
            Some(m) => {
                let d = m.pixel(x, y);
                let v = Vec3::new(d[0] as f64, d[1] as f64, d[2] as f64);
                let n = v.norm();
                if !(n > 0.0) {
                    return None;
                }
                v / n
            }
            None => view_at(&spec.camera, &p).expect("non-map camera"),
        };
        Some((l, v, e))
    }

    /// Number of images.
    pub fn images(&self) -> usize {
        self.desc.images.len()
    }

    /// (x, y) of every texel with a sample, row-major.
    pub fn texels(&self) -> &[(u32, u32)] {
        &self.texels
    }

    /// The texel at pixel (x, y), if any.
    pub fn texel_at(&self, x: i64, y: i64) -> Option<usize> {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return None;
        }
        let t = self.index[y as usize * self.width + x as usize];
        (t != NO_TEXEL).then_some(t as usize)
    }

    /// Number of samples (pixel values kept).
    pub fn sample_count(&self) -> usize {
        self.values
            .chunks(self.channels)
            .filter(|c| !c[0].is_nan())
            .count()
    }

    /// Bytes the store holds: pixel values, texels, texel index and maps.
    pub fn bytes(&self) -> usize {
        let image = |m: &Option<LinearImage>| {
            m.as_ref()
                .map_or(0, |m| m.data.len() * 4 + m.saturated.len())
        };
        let map = |m: &Option<TopologyMap>| m.as_ref().map_or(0, |m| m.values.len() * 4);
        self.values.capacity() * 4
            + self.texels.capacity() * 8
            + self.index.capacity() * 4
            + map(&self.topology)
            + map(&self.tangent)
            + image(&self.height_map)
            + image(&self.azimuth_map)
            + self.view_maps.iter().map(image).sum::<usize>()
    }

    /// The sample of texel `t` in image `k`, if the texel has one there.
    pub fn sample(&self, t: usize, k: usize) -> Option<Sample> {
        let ch = self.channels;
        let i = (t * self.images() + k) * ch;
        let px = &self.values[i..i + ch];
        if px[0].is_nan() {
            return None;
        }
        let (x, y) = (self.texels[t].0 as usize, self.texels[t].1 as usize);
        let (l, v, e) = self
            .geometry(k, x, y)
            .expect("kept samples have a geometry");
        let spec = &self.desc.images[k];
        let to_brdf = spec.exposure / (e * l.z);
        let mut value = [0.0; 3];
        for (c, out) in value.iter_mut().enumerate() {
            *out = px[c.min(ch - 1)] as f64 * to_brdf;
        }
        let sigma = self.noise.get(k).map(|n| {
            let s = n.sigmas(px);
            let mut out = [0.0; 3];
            for (c, o) in out.iter_mut().enumerate() {
                *o = s[c.min(ch - 1)] * to_brdf;
            }
            out
        });
        let texel_height = self.height_map.as_ref().map(|m| m.pixel(x, y)[0] as f64);
        let texel_psi = self.azimuth_map.as_ref().map(|m| m.pixel(x, y)[0] as f64);
        Some(Sample {
            l,
            v,
            fibre_azimuth: match (&self.tangent, self.desc.swatch.fibre_azimuth_deg, texel_psi) {
                (_, _, Some(psi)) => Some(psi.to_radians()),
                (Some(t), _, _) => Some((-90.0 + 180.0 * t.texel(x, y)).to_radians()),
                (None, Some(psi), _) => Some(psi.to_radians()),
                (None, None, None) => None,
            },
            map_value: self.topology.as_ref().map(|t| t.texel(x, y)),
            texel_height,
            value,
            sigma,
            weight: 1.0,
            origin: Origin::Pixel {
                image: k as u32,
                x: x as u32,
                y: y as u32,
            },
        })
    }

    /// The samples of texel `t`, image by image.
    pub fn texel_samples(&self, t: usize) -> Vec<Sample> {
        (0..self.images())
            .filter_map(|k| self.sample(t, k))
            .collect()
    }

    /// The samples of the texels `ids` (ascending), image by image as the loader orders them.
    pub fn samples_of(&self, ids: &[usize]) -> Samples {
        let samples = (0..self.images())
            .flat_map(|k| ids.iter().filter_map(move |&t| self.sample(t, k)))
            .collect();
        Samples {
            samples,
            channels: self.channels,
            kind: DataKind::Capture,
            source: self.source.clone(),
            dropped: self.dropped.clone(),
            skipped_examples: vec![],
            image_size: Some((self.width, self.height)),
            scale_rel_se: self.desc.scale_rel_se,
        }
    }

    /// The samples of image `k` at the texels `texels` (ascending), in the order of
    /// [`Self::to_samples`]: a piece of it.
    pub fn image_samples(&self, k: usize, texels: Range<usize>) -> Samples {
        Samples {
            samples: texels.filter_map(|t| self.sample(t, k)).collect(),
            channels: self.channels,
            kind: DataKind::Capture,
            source: self.source.clone(),
            dropped: self.dropped.clone(),
            skipped_examples: vec![],
            image_size: Some((self.width, self.height)),
            scale_rel_se: self.desc.scale_rel_se,
        }
    }

    /// The texels in consecutive ranges of whole image rows, each of at least `min_texels`
    /// texels but the last: pieces of an image for passes that need a row's pixels together
    /// (the noise from neighbouring pixels).
    pub fn row_chunks(&self, min_texels: usize) -> Vec<Range<usize>> {
        let mut out = Vec::new();
        let mut start = 0;
        for t in 1..self.texels.len() {
            if t - start >= min_texels && self.texels[t].1 != self.texels[t - 1].1 {
                out.push(start..t);
                start = t;
            }
        }
        if start < self.texels.len() {
            out.push(start..self.texels.len());
        }
        out
    }

    /// |BRDF value| of channel `c` of every sample, in no particular order (for a median).
    pub fn channel_magnitudes(&self, c: usize) -> Vec<f64> {
        use rayon::prelude::*;
        (0..self.images())
            .into_par_iter()
            .flat_map_iter(|k| {
                (0..self.texels.len())
                    .filter_map(move |t| self.sample(t, k).map(|s| s.value[c].abs()))
            })
            .collect()
    }

    /// Every sample, image by image, rows from the top.
    pub fn to_samples(&self) -> Samples {
        let all: Vec<usize> = (0..self.texels.len()).collect();
        self.samples_of(&all)
    }

    /// A seeded sample of `n` texels (all of them when there are no more), ascending, drawn in
    /// runs of [`SAMPLE_RUN`] neighbours along a row: the quality checks estimate the noise
    /// from neighbouring pixels.
    pub fn sample_texels(&self, n: usize, seed: u64) -> Vec<usize> {
        use rand::seq::SliceRandom;
        use rand::SeedableRng;
        let all = self.texels.len();
        if n >= all {
            return (0..all).collect();
        }
        let mut runs: Vec<usize> = (0..all.div_ceil(SAMPLE_RUN)).collect();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        runs.shuffle(&mut rng);
        let mut ids: Vec<usize> = runs
            .iter()
            .flat_map(|r| r * SAMPLE_RUN..((r + 1) * SAMPLE_RUN).min(all))
            .take(n)
            .collect();
        ids.sort_unstable();
        ids
    }

    /// Per image, the noise model of its values: empty unless the capture has exposure
    /// brackets.
    pub fn noise(&self) -> &[ImageNoise] {
        &self.noise
    }
}

/// The raw values of a capture's images as [`CaptureStore::read_values`] keeps them, with
/// every image's noise and clip level and the brackets' pixel pairs per channel.
struct ReadValues {
    values: Vec<f32>,
    noise: Vec<(Option<ImageNoise>, f32)>,
    noise_rows: Vec<Vec<[f64; 9]>>,
}

/// The maps a capture's description names, read and checked against the images' size.
struct SwatchMaps {
    topology: Option<TopologyMap>,
    height_map: Option<LinearImage>,
    azimuth_map: Option<LinearImage>,
    tangent: Option<TopologyMap>,
    mask: Option<TopologyMap>,
    view_maps: Vec<Option<LinearImage>>,
}

impl SwatchMaps {
    /// The swatch's maps and the images' view maps, for images of `w` x `h` pixels.
    fn load(base: &Path, desc: &CaptureFile, (w, h): (usize, usize)) -> Result<Self> {
        let load_map = |p: &Option<PathBuf>, what: &str| -> Result<Option<TopologyMap>> {
            match p {
                Some(p) => {
                    let full = resolve(base, p);
                    let m = TopologyMap::load_as(&full, what)?;
                    check_size(what, &full, (m.width, m.height), (w, h))?;
                    Ok(Some(m))
                }
                None => Ok(None),
            }
        };
        let topology = load_map(&desc.swatch.topology_map, "topology map")?;
        let height_map = load_unit_map(
            base,
            &desc.swatch.height_map,
            "height map (fibre radii)",
            (0.0, 20.0),
            (w, h),
        )?;
        let azimuth_map = load_unit_map(
            base,
            &desc.swatch.fibre_azimuth_map,
            "fibre azimuth map (degrees)",
            (-90.0, 90.0),
            (w, h),
        )?;
        let tangent = load_map(&desc.swatch.tangent_map, "tangent map")?;
        let mask = load_map(&desc.swatch.mask, "mask")?;
        let view_maps = view_maps(base, desc, (w, h))?;
        Ok(Self {
            topology,
            height_map,
            azimuth_map,
            tangent,
            mask,
            view_maps,
        })
    }
}

/// Per image, its view map where its camera is one (R, G, B holding x, y, z).
fn view_maps(
    base: &Path,
    desc: &CaptureFile,
    (w, h): (usize, usize),
) -> Result<Vec<Option<LinearImage>>> {
    desc.images
        .iter()
        .map(|spec| match &spec.camera {
            Camera::ViewMap { file } => {
                let full = resolve(base, file);
                let m = image_io::read(&full, None, None)?;
                check_size("view map", &full, (m.width, m.height), (w, h))?;
                if m.channels != 3 {
                    bail!(
                        "{}: a view map needs R, G, B channels holding x, y, z",
                        full.display()
                    );
                }
                Ok(Some(m))
            }
            _ => Ok(None),
        })
        .collect::<Result<_>>()
}

/// The candidate texels: the pixels inside the ROI and the mask, row-major, with the texel
/// index of every pixel ([`NO_TEXEL`] elsewhere); refused when the ROI is not inside the image.
fn candidate_texels(
    name: &str,
    roi: Option<[usize; 4]>,
    mask: Option<&TopologyMap>,
    (w, h): (usize, usize),
) -> Result<(Vec<u32>, Vec<(u32, u32)>)> {
    let roi = roi.unwrap_or([0, 0, w, h]);
    if roi[0] >= roi[2] || roi[1] >= roi[3] || roi[2] > w || roi[3] > h {
        bail!("{name}: swatch.roi = {roi:?} is not a rectangle inside the {w}x{h} image");
    }
    let mut index = vec![NO_TEXEL; w * h];
    let mut texels = Vec::new();
    for y in roi[1]..roi[3] {
        for x in roi[0]..roi[2] {
            if mask.is_some_and(|m| m.texel(x, y) == 0.0) {
                continue;
            }
            index[y * w + x] = texels.len() as u32;
            texels.push((x as u32, y as u32));
        }
    }
    Ok((index, texels))
}

/// An image as read: its linear values, and for a bracket the noise model its frames gave
/// alone and their pixel pairs (for the capture's estimate).
pub(crate) struct ReadImage {
    pub image: LinearImage,
    pub noise: Option<ImageNoise>,
    pub rows: Option<bracket::NoiseRows>,
}

/// The most memory a capture may take while it is read (docs/safety.md): 2 GiB, counted from
/// the first image's size before any other image is decoded ([`capture_memory`]).
pub const MAX_CAPTURE_BYTES: u64 = 2 << 30;

/// The memory reading the capture `desc` of `w` x `h` images with `channels` channels takes at
/// most: the store (4 B per value of every image, twice while the texels are compacted; 12 B
/// per pixel of texel index and position), the maps it gives (4 B per pixel each, a view map 12
/// B per pixel and image), and one image being read (each frame of the largest bracket as a
/// linear image, plus the decoding of one frame, [`image_io::image_memory`] of float samples).
pub fn capture_memory(desc: &CaptureFile, (w, h): (usize, usize), channels: usize) -> u128 {
    let px = w as u128 * h as u128;
    let (images, c) = (desc.images.len() as u128, channels as u128);
    let store = px * (images * c * 4 * 2 + 12);
    let sw = &desc.swatch;
    let maps = [
        &sw.mask,
        &sw.tangent_map,
        &sw.topology_map,
        &sw.height_map,
        &sw.fibre_azimuth_map,
    ]
    .iter()
    .filter(|m| m.is_some())
    .count() as u128;
    let views = desc
        .images
        .iter()
        .filter(|s| matches!(s.camera, Camera::ViewMap { .. }))
        .count() as u128;
    let frames = desc
        .images
        .iter()
        .map(|s| s.frames().len())
        .max()
        .unwrap_or(1) as u128;
    let linear = px * (c * 4 + 1);
    let decoding = image_io::image_memory(w as u64, h as u64, channels as u64, 4)
        .map_or(u128::MAX / 4, u128::from);
    store + px * (maps * 4 + views * 12) + frames * linear + decoding
}

/// Refuse a capture whose reading would take more than [`MAX_CAPTURE_BYTES`], with the estimate.
fn check_capture_memory(
    name: &str,
    desc: &CaptureFile,
    size: (usize, usize),
    channels: usize,
) -> Result<()> {
    let bytes = capture_memory(desc, size, channels);
    if bytes > MAX_CAPTURE_BYTES as u128 {
        bail!(
            "{name}: {} images of {}x{} pixels with {channels} channels would take {:.2} GiB of memory to read; the most a capture may take is {} (docs/safety.md): use fewer or smaller images, or crop them to the swatch",
            desc.images.len(),
            size.0,
            size.1,
            bytes as f64 / (1u64 << 30) as f64,
            super::input::bytes_text(MAX_CAPTURE_BYTES)
        );
    }
    Ok(())
}

/// Image `spec` (its file, or its bracket merged), checked for negative values.
pub(crate) fn read_image(base: &Path, spec: &ImageSpec) -> Result<ReadImage> {
    let frames = spec.frames();
    if frames.len() == 1 {
        let full = resolve(base, frames[0].0);
        let image = image_io::read(&full, spec.encoding, spec.saturation)?;
        check_no_negatives(&full, &image)?;
        let noise = spec.noise.as_ref().map(|n| ImageNoise::given(n, image.clip));
        return Ok(ReadImage {
            image,
            noise,
            rows: None,
        });
    }
    let mut read = Vec::with_capacity(frames.len());
    for (file, factor) in &frames {
        let full = resolve(base, file);
        let img = image_io::read(&full, spec.encoding, spec.saturation)?;
        check_no_negatives(&full, &img)?;
        if let Some((first, _, first_file)) = read.first() {
            let first: &LinearImage = first;
            check_size(
                &format!("bracket frame (like {})", Path::new(first_file).display()),
                &full,
                (img.width, img.height),
                (first.width, first.height),
            )?;
            if img.channels != first.channels {
                bail!(
                    "{}: has {} channels, the bracket's first frame {}; a bracket's frames must match",
                    full.display(),
                    img.channels,
                    first.channels
                );
            }
        }
        read.push((img, *factor, full.display().to_string()));
    }
    let frames: Vec<(LinearImage, f64)> = read.into_iter().map(|(i, f, _)| (i, f)).collect();
    let (image, noise, rows) =
        bracket::merge(&frames).map_err(|e| anyhow::anyhow!("{}: {e}", spec.label()))?;
    Ok(ReadImage {
        image,
        noise: Some(noise),
        rows: Some(rows),
    })
}

/// Every image's noise model once the brackets are read (with each image's saturation level):
/// an image's own `noise` where it gives one (`given`); otherwise from the pixel pairs of all
/// the capture's brackets pooled (one camera), images without a bracket getting the model with
/// one frame. None when no image has either; refused when some images have a noise model and
/// others cannot get one.
fn capture_noise(
    name: &str,
    noise: Vec<(Option<ImageNoise>, f32)>,
    rows: &[Vec<[f64; 9]>],
    given: &[bool],
) -> Result<Vec<ImageNoise>> {
    if noise.iter().all(|(n, _)| n.is_none()) {
        return Ok(vec![]);
    }
    if rows.iter().all(|r| r.is_empty()) {
        // no brackets: every image must give its own
        if let Some(k) = noise.iter().position(|(n, _)| n.is_none()) {
            let j = given.iter().position(|g| *g).unwrap_or(0);
            bail!(
                "{name}: [[images]] {} gives `noise` but [[images]] {} does not: give every image's noise or none",
                j + 1,
                k + 1
            );
        }
        return Ok(noise.into_iter().map(|(n, _)| n.expect("checked")).collect());
    }
    let mut var0 = [0.0; 3];
    let mut gain = [0.0; 3];
    let mut pairs = 0;
    for (c, r) in rows.iter().enumerate() {
        let Some((v, g, used)) = bracket::fit_noise(r) else {
            bail!(
                "{name}: the brackets' frames share too few pixels that adjacent exposures both \
                 resolve (neither clipped nor black, channel {c}: at least {} over a range of \
                 values) to estimate the camera's noise; give exposures that overlap",
                bracket::MIN_NOISE_PAIRS
            );
        };
        var0[c] = v;
        gain[c] = g;
        pairs += used;
    }
    for c in rows.len()..3 {
        var0[c] = var0[rows.len() - 1];
        gain[c] = gain[rows.len() - 1];
    }
    Ok(noise
        .into_iter()
        .zip(given)
        .map(|((n, clip), given)| {
            if *given {
                return n.expect("an image's own noise");
            }
            let (frames, weights) = n.map_or((vec![(1.0, clip)], [(0.0, 1.0); 3]), |n| {
                (n.frames, n.weights)
            });
            ImageNoise {
                frames,
                var0,
                gain,
                weights,
                pairs,
            }
        })
        .collect())
}

/// The description's own checks: images, swatch size, fibre direction and topology given once,
/// subsampling, each image's geometry.
fn check_description(name: &str, desc: &CaptureFile, subsample: Subsample) -> Result<()> {
    if desc.images.is_empty() {
        bail!("{name}: no [[images]]");
    }
    if let Some(r) = desc.scale_rel_se {
        if r.iter().any(|x| !(x.is_finite() && (0.0..1.0).contains(x))) {
            bail!("{name}: scale_rel_se = {r:?} must be three relative standard errors in [0, 1)");
        }
    }
    let [w_mm, h_mm] = desc.swatch.size_mm;
    if !(w_mm > 0.0 && h_mm > 0.0 && w_mm.is_finite() && h_mm.is_finite()) {
        bail!("{name}: swatch.size_mm must be two positive lengths in millimetres");
    }
    let sw = &desc.swatch;
    if [
        sw.fibre_azimuth_deg.is_some(),
        sw.tangent_map.is_some(),
        sw.fibre_azimuth_map.is_some(),
    ]
    .iter()
    .filter(|x| **x)
    .count()
        > 1
    {
        bail!("{name}: swatch.fibre_azimuth_deg, swatch.tangent_map and swatch.fibre_azimuth_map each give the fibre direction: give one, not both");
    }
    if sw.topology_map.is_some() && sw.height_map.is_some() {
        bail!("{name}: give swatch.topology_map or swatch.height_map, not both");
    }
    if let Some(psi) = desc.swatch.fibre_azimuth_deg {
        if !(-90.0..=90.0).contains(&psi) {
            bail!("{name}: swatch.fibre_azimuth_deg = {psi} is outside [-90, 90] degrees");
        }
    }
    if subsample.stride == 0 || !(subsample.fraction > 0.0 && subsample.fraction <= 1.0) {
        bail!("subsampling: stride must be >= 1 and fraction in (0, 1]");
    }
    for (k, spec) in desc.images.iter().enumerate() {
        check_image_spec(name, k, spec)?;
    }
    Ok(())
}

/// A map in physical units (recovered by `fit --maps`), one channel, values in `range` or NaN.
fn load_unit_map(
    base: &Path,
    p: &Option<PathBuf>,
    what: &str,
    (lo, hi): (f32, f32),
    (w, h): (usize, usize),
) -> Result<Option<LinearImage>> {
    let Some(p) = p else { return Ok(None) };
    let full = resolve(base, p);
    let m = image_io::read(&full, None, None)?;
    check_size(what, &full, (m.width, m.height), (w, h))?;
    if m.channels != 1 {
        bail!(
            "{}: a {what} has one channel, this has {}",
            full.display(),
            m.channels
        );
    }
    if let Some(i) = m
        .data
        .iter()
        .position(|v| !v.is_nan() && !(lo..=hi).contains(v))
    {
        bail!(
            "{}: texel ({}, {}) has value {}; {what} values must lie in [{lo}, {hi}] (NaN: no texel)",
            full.display(),
            i % w,
            i / w,
            m.data[i]
        );
    }
    Ok(Some(m))
}

/// The per-texel fields a capture's swatch gives (registered to its images), for rendering it:
/// the fibre azimuth psi in degrees (from `fibre_azimuth_map`, or `tangent_map` as
/// -90 + 180 m) and the height H in fibre radii (`height_map`); `None` where it gives none.
pub struct SwatchFields {
    pub psi_deg: Option<LinearImage>,
    pub height: Option<LinearImage>,
}

impl CaptureStore {
    /// The swatch's per-texel fields, as this store read and checked them.
    pub fn swatch_fields(&self) -> SwatchFields {
        let psi_deg = self.azimuth_map.clone().or_else(|| {
            self.tangent.as_ref().map(|m| LinearImage {
                width: m.width,
                height: m.height,
                channels: 1,
                data: m.values.iter().map(|&v| -90.0 + 180.0 * v).collect(),
                saturated: vec![false; m.width * m.height],
                clip: f32::INFINITY,
            })
        });
        SwatchFields {
            psi_deg,
            height: self.height_map.clone(),
        }
    }
}

/// Image `index` of a capture as the fit reads it: linear values times the image's exposure
/// (radiance per unit irradiance), channels interleaved, row 0 at the top; with its width,
/// height and channel count, and per pixel whether it is saturated.
pub fn radiance_image(path: &Path, index: usize) -> Result<LinearImage> {
    let desc = CaptureFile::load(path)?;
    let spec = desc.images.get(index).ok_or_else(|| {
        anyhow!(
            "{}: image {index} asked for, but the capture has {} images",
            path.display(),
            desc.images.len()
        )
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut img = read_image(base, spec)?.image;
    for x in &mut img.data {
        *x *= spec.exposure as f32;
    }
    Ok(img)
}
