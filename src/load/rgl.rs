//! RGL material database BRDFs (`.bsdf` tensor files; Dupuy & Jakob 2018, "An Adaptive
//! Parameterization for Efficient Material Acquisition and Rendering").
//!
//! The file is a Mitsuba tensor file: the magic `tensor_file\0`, version 1.0, a field count,
//! then per field its name, rank, type, data offset and shape (little endian). A measured BRDF
//! holds the incidence grid (`theta_i`, `phi_i`), the microfacet distribution `ndf` and projected
//! area `sigma` (2D tables over the unit square u = (sqrt(2 theta / pi), (phi + pi) / (2 pi))),
//! the visible-normal warp `vndf` (a 2D distribution per incidence) and the reflectance table
//! `rgb` (per incidence and channel) over the warped square.
//!
//! Evaluation at light l and view v (both in the file's frame; the file's incident direction
//! is the light): the half vector m = (l + v)/|l + v| in unit coordinates u_m (its azimuth taken
//! relative to phi_i for isotropic files) is mapped through the inverse of the vndf warp to a
//! point s of the unit square; the value is rgb(s) ndf(u_m) / (4 sigma(u_l)). Tables are bilinear
//! in their square and linear in the incidence parameters (the warp is the marginal-conditional
//! inversion of a bilinear interpolant). The value so computed is f cos(theta_o) (the database's
//! and Mitsuba's convention); this loader divides by cos(theta_o), so samples hold f in 1/sr.

use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::{direction_from_angles, Vec3};
use anyhow::{anyhow, bail, Result};
use rand::{Rng, SeedableRng};
use std::collections::HashMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::Path;

/// How a measured file is turned into samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredOptions {
    /// Direction pairs drawn (light and view uniform in solid angle).
    pub directions: usize,
    /// Seed of the directions' draw.
    pub seed: u64,
    /// Largest theta of light and view, degrees (the light also stays within the file's
    /// measured incidence range).
    pub max_theta_deg: f64,
}

/// The most direction pairs a measured file is sampled at (`--directions`): 10 million (about
/// 1.8 GB of samples).
pub const MAX_DIRECTIONS: usize = 10_000_000;

impl MeasuredOptions {
    /// `--directions` in [1, `MAX_DIRECTIONS`] and `--max-theta` in (0, 90) degrees.
    pub fn check(&self) -> Result<()> {
        if !(1..=MAX_DIRECTIONS).contains(&self.directions) {
            bail!(
                "--directions {}: expected 1 to {MAX_DIRECTIONS}",
                self.directions
            );
        }
        if !(self.max_theta_deg > 0.0 && self.max_theta_deg < 90.0) {
            bail!("--max-theta must lie in (0, 90) degrees");
        }
        Ok(())
    }
}

impl Default for MeasuredOptions {
    fn default() -> Self {
        Self {
            directions: 3000,
            seed: 0,
            max_theta_deg: 78.0,
        }
    }
}

/// One field of a tensor file: shape and values (converted to f64; empty for types the BRDF
/// does not use).
struct Field {
    shape: Vec<usize>,
    values: Vec<f64>,
}

/// Values beyond this magnitude are refused, as the goniometric CSV loader refuses them: their
/// squares (in a fit's residuals) would overflow.
pub const MAX_MAGNITUDE: f64 = 1e100;

fn read_tensor_file(path: &Path) -> Result<HashMap<String, Field>> {
    let name = path.display();
    let bad = |what: &str| anyhow!("{name}: not an RGL/Mitsuba tensor file: {what}");
    // the magic first (a device or another kind of file is refused after 18 bytes), then the rest
    let mut input = super::input::open(path, super::input::MAX_MEASURED_BYTES)?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(&mut input, 18), &mut bytes)
        .map_err(|e| super::input::io_error(path, e))?;
    if bytes.len() < 18 || &bytes[..12] != b"tensor_file\0" {
        return Err(bad("no `tensor_file` header"));
    }
    input.read_rest(&mut bytes)?;
    input.finish()?;
    if bytes[12..14] != [1, 0] {
        bail!(
            "{name}: tensor file version {}.{} (this loader reads 1.0)",
            bytes[12],
            bytes[13]
        );
    }
    let mut p = 14;
    let take = |p: &mut usize, n: usize| -> Result<&[u8]> {
        let s = p
            .checked_add(n)
            .and_then(|end| bytes.get(*p..end))
            .ok_or_else(|| bad("truncated field table"))?;
        *p += n;
        Ok(s)
    };
    let u16_at = |s: &[u8]| u16::from_le_bytes([s[0], s[1]]) as usize;
    let u64_at = |s: &[u8]| u64::from_le_bytes([s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]]);
    let n_fields = u32::from_le_bytes([bytes[14], bytes[15], bytes[16], bytes[17]]) as usize;
    p += 4;
    let mut fields = HashMap::new();
    for _ in 0..n_fields {
        let len = u16_at(take(&mut p, 2)?);
        let fname = String::from_utf8_lossy(take(&mut p, len)?).into_owned();
        let ndim = u16_at(take(&mut p, 2)?);
        let dtype = take(&mut p, 1)?[0];
        let offset = u64_at(take(&mut p, 8)?);
        let mut shape = Vec::with_capacity(ndim.min(16));
        for _ in 0..ndim {
            let d = u64_at(take(&mut p, 8)?);
            shape.push(
                usize::try_from(d)
                    .map_err(|_| bad(&format!("field `{fname}` has a dimension of {d}")))?,
            );
        }
        // types: 1 u8, 2 i8, 3 u16, 4 i16, 5 u32, 6 i32, 7 u64, 8 i64, 9 f16, 10 f32, 11 f64
        let size: usize = match dtype {
            1 | 2 => 1,
            3 | 4 | 9 => 2,
            5 | 6 | 10 => 4,
            7 | 8 | 11 => 8,
            _ => return Err(bad(&format!("field `{fname}` has unknown type {dtype}"))),
        };
        // the shape's product and the data's extent in checked arithmetic (no wrap-around)
        let beyond = || {
            bad(&format!(
                "field `{fname}` (shape {shape:?}, {size}-byte values at offset {offset}) lies beyond the end of the {}-byte file",
                bytes.len()
            ))
        };
        let count = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(beyond)?;
        let data = usize::try_from(offset)
            .ok()
            .and_then(|o| Some((o, count.checked_mul(size)?)))
            .and_then(|(o, n)| bytes.get(o..o.checked_add(n)?))
            .ok_or_else(beyond)?;
        let values: Vec<f64> = match dtype {
            1 => data.iter().map(|&b| b as f64).collect(),
            10 => data
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
                .collect(),
            11 => data
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
            _ => vec![], // not needed by the BRDF
        };
        if fields
            .insert(fname.clone(), Field { shape, values })
            .is_some()
        {
            return Err(bad(&format!("field `{fname}` appears twice")));
        }
    }
    Ok(fields)
}

/// A 2D table over the unit square, bilinear, possibly depending linearly on parameters, and (for
/// the warp) its marginal-conditional CDFs.
struct Table2D {
    /// Columns (x) and rows (y).
    nx: usize,
    ny: usize,
    /// Parameter grids, outermost first.
    params: Vec<Vec<f64>>,
    /// Stride of each parameter in slices (0 for a parameter with one value).
    strides: Vec<usize>,
    data: Vec<f64>,
    marginal: Vec<f64>,
    conditional: Vec<f64>,
}

impl Table2D {
    /// `normalized`: scale each slice to integrate to one and build the CDFs (the warp);
    /// otherwise plain interpolation of the values.
    fn new(shape: &[usize], data: &[f64], params: Vec<Vec<f64>>, normalized: bool) -> Self {
        let k = shape.len();
        let (ny, nx) = (shape[k - 2], shape[k - 1]);
        let mut strides = vec![0; params.len()];
        let mut slices = 1;
        for i in (0..params.len()).rev() {
            strides[i] = if params[i].len() > 1 { slices } else { 0 };
            slices *= params[i].len();
        }
        let n = nx * ny;
        let mut out = Table2D {
            nx,
            ny,
            params,
            strides,
            data: data.to_vec(),
            marginal: vec![],
            conditional: vec![],
        };
        if normalized {
            out.marginal = vec![0.0; slices * ny];
            out.conditional = vec![0.0; slices * n];
            for s in 0..slices {
                let d = &mut out.data[s * n..(s + 1) * n];
                let c = &mut out.conditional[s * n..(s + 1) * n];
                let m = &mut out.marginal[s * ny..(s + 1) * ny];
                for y in 0..ny {
                    let mut sum = 0.0;
                    c[y * nx] = 0.0;
                    for x in 0..nx - 1 {
                        sum += 0.5 * (d[y * nx + x] + d[y * nx + x + 1]);
                        c[y * nx + x + 1] = sum;
                    }
                }
                let mut sum = 0.0;
                m[0] = 0.0;
                for y in 0..ny - 1 {
                    sum += 0.5 * (c[(y + 1) * nx - 1] + c[(y + 2) * nx - 1]);
                    m[y + 1] = sum;
                }
                // a slice with no mass (padding at the horizon) stays zero rather than NaN
                let norm = if m[ny - 1] > 0.0 {
                    1.0 / m[ny - 1]
                } else {
                    0.0
                };
                c.iter_mut().for_each(|v| *v *= norm);
                m.iter_mut().for_each(|v| *v *= norm);
                d.iter_mut().for_each(|v| *v *= norm);
            }
        }
        out
    }

    /// Slice offset and interpolation weights for parameter values `p`.
    fn weights(&self, p: &[f64]) -> (usize, Vec<[f64; 2]>) {
        let mut offset = 0;
        let mut w = Vec::with_capacity(self.params.len());
        for (dim, grid) in self.params.iter().enumerate() {
            if grid.len() == 1 {
                w.push([1.0, 0.0]);
                continue;
            }
            // the interval [i, i + 1] holding p, clamped to the grid
            let i = grid
                .partition_point(|&g| g <= p[dim])
                .saturating_sub(1)
                .min(grid.len() - 2);
            let t = ((p[dim] - grid[i]) / (grid[i + 1] - grid[i])).clamp(0.0, 1.0);
            w.push([1.0 - t, t]);
            offset += self.strides[dim] * i;
        }
        (offset, w)
    }

    /// Value of `array` at index `i0` of the first slice, interpolated over the parameters
    /// (`size`: elements per slice of that array).
    fn lookup(&self, array: &[f64], i0: usize, size: usize, w: &[[f64; 2]], dim: usize) -> f64 {
        if dim == 0 {
            return array[i0];
        }
        let d = dim - 1;
        let v0 = self.lookup(array, i0, size, w, d);
        if w[d][1] == 0.0 {
            return v0 * w[d][0];
        }
        let v1 = self.lookup(array, i0 + self.strides[d] * size, size, w, d);
        v0 * w[d][0] + v1 * w[d][1]
    }

    /// Bilinear value at `pos` in the unit square, interpolated over the parameters.
    fn eval(&self, pos: [f64; 2], p: &[f64]) -> f64 {
        let (slice, w) = self.weights(p);
        let n = self.nx * self.ny;
        let (fx, fy) = (pos[0] * (self.nx - 1) as f64, pos[1] * (self.ny - 1) as f64);
        let (x, y) = (
            (fx.max(0.0) as usize).min(self.nx - 2),
            (fy.max(0.0) as usize).min(self.ny - 2),
        );
        let (tx, ty) = (fx - x as f64, fy - y as f64);
        let i = x + y * self.nx + slice * n;
        let at = |k: usize| self.lookup(&self.data, k, n, &w, w.len());
        let (v00, v10, v01, v11) = (at(i), at(i + 1), at(i + self.nx), at(i + self.nx + 1));
        (1.0 - ty) * ((1.0 - tx) * v00 + tx * v10) + ty * ((1.0 - tx) * v01 + tx * v11)
    }

    /// The inverse of the warp: the point of the unit square that maps to `pos`.
    fn invert(&self, pos: [f64; 2], p: &[f64]) -> [f64; 2] {
        let (slice, w) = self.weights(p);
        let (nx, ny) = (self.nx, self.ny);
        let n = nx * ny;
        let d = w.len();
        let (fx, fy) = (pos[0] * (nx - 1) as f64, pos[1] * (ny - 1) as f64);
        let (x, y) = (
            (fx.max(0.0) as usize).min(nx - 2),
            (fy.max(0.0) as usize).min(ny - 2),
        );
        let (mut sx, sy) = (fx - x as f64, fy - y as f64);
        let i = x + y * nx + slice * n;
        let at = |a: &[f64], k: usize, size: usize| self.lookup(a, k, size, &w, d);
        let (v00, v10, v01, v11) = (
            at(&self.data, i, n),
            at(&self.data, i + 1, n),
            at(&self.data, i + nx, n),
            at(&self.data, i + nx + 1, n),
        );
        let c0 = (1.0 - sy) * v00 + sy * v01;
        let c1 = (1.0 - sy) * v10 + sy * v11;
        sx *= c0 + 0.5 * sx * (c1 - c0);
        let (k0, k1) = (
            at(&self.conditional, i, n),
            at(&self.conditional, i + nx, n),
        );
        sx += (1.0 - sy) * k0 + sy * k1;
        let row = y * nx + slice * n;
        let r0 = at(&self.conditional, row + nx - 1, n);
        let r1 = at(&self.conditional, row + 2 * nx - 1, n);
        sx /= (1.0 - sy) * r0 + sy * r1;
        let mut out_y = sy * (r0 + 0.5 * sy * (r1 - r0));
        out_y += at(&self.marginal, y + slice * ny, ny);
        [sx, out_y]
    }
}

/// A measured BRDF from the RGL database.
pub struct RglBsdf {
    pub description: String,
    isotropic: bool,
    ndf: Table2D,
    sigma: Table2D,
    vndf: Table2D,
    rgb: Table2D,
    /// Largest measured incidence angle, radians (the grid's last node below the horizon).
    pub max_theta_i: f64,
}

fn theta_to_u(theta: f64) -> f64 {
    (theta * (2.0 / PI)).sqrt()
}

fn phi_to_u(phi: f64) -> f64 {
    (phi + PI) / (2.0 * PI)
}

/// The fields of a tensor file that a measured BRDF is made of.
struct RglFields {
    theta_i: Field,
    phi_i: Field,
    ndf: Field,
    sigma: Field,
    vndf: Field,
    rgb: Field,
}

impl RglFields {
    /// Take the BRDF's fields out of the file's, each of its rank and with float data.
    fn take(f: &mut HashMap<String, Field>, name: &str) -> Result<Self> {
        let mut take = |k: &str, rank: usize| -> Result<Field> {
            let field = f
                .remove(k)
                .ok_or_else(|| anyhow!("{name}: no field `{k}`; not an RGL measured BRDF"))?;
            if field.shape.len() != rank || field.values.is_empty() {
                bail!(
                    "{name}: field `{k}` has shape {:?}; expected rank {rank}, float data",
                    field.shape
                );
            }
            Ok(field)
        };
        let theta_i = take("theta_i", 1)?;
        let phi_i = take("phi_i", 1)?;
        let ndf = take("ndf", 2)?;
        let sigma = take("sigma", 2)?;
        let vndf = take("vndf", 4)?;
        let rgb = take("rgb", 5).map_err(|e| {
            anyhow!("{e:#} (only RGB files are read: the `_rgb.bsdf` variant of a material)")
        })?;
        Ok(Self {
            theta_i,
            phi_i,
            ndf,
            sigma,
            vndf,
            rgb,
        })
    }

    /// The tables agree with the incidence grid, and each is at least 2 x 2.
    fn check_shapes(&self, name: &str) -> Result<()> {
        let (vndf, rgb) = (&self.vndf, &self.rgb);
        let (np, nt) = (self.phi_i.values.len(), self.theta_i.values.len());
        if vndf.shape[..2] != [np, nt] || rgb.shape[..3] != [np, nt, 3] || nt < 2 {
            bail!(
                "{name}: inconsistent shapes: theta_i {nt}, phi_i {np}, vndf {:?}, rgb {:?}",
                vndf.shape,
                rgb.shape
            );
        }
        // every table at least 2 x 2 (bilinear interpolation needs two nodes each way)
        for (k, field) in [
            ("ndf", &self.ndf),
            ("sigma", &self.sigma),
            ("vndf", vndf),
            ("rgb", rgb),
        ] {
            let r = field.shape.len();
            if field.shape[r - 2] < 2 || field.shape[r - 1] < 2 {
                bail!(
                    "{name}: field `{k}` has shape {:?}; its last two dimensions (the table) must each be at least 2",
                    field.shape
                );
            }
        }
        Ok(())
    }

    /// The tables' values: finite, within the magnitude the fit can square, and of the right
    /// sign.
    fn check_values(&self, name: &str) -> Result<()> {
        let check = |k: &str, field: &Field, min: f64, strict: bool| -> Result<()> {
            let bad = field.values.iter().position(|&v| {
                !(v.is_finite() && v.abs() <= MAX_MAGNITUDE && (v > min || (!strict && v == min)))
            });
            if let Some(i) = bad {
                let v = field.values[i];
                let want = if strict { "positive" } else { "non-negative" };
                let why = if !v.is_finite() {
                    "values must be finite".to_string()
                } else if v.abs() > MAX_MAGNITUDE {
                    format!("values beyond {MAX_MAGNITUDE:e} in magnitude are refused")
                } else {
                    format!("values must be {want}")
                };
                bail!("{name}: field `{k}` entry {i} is {v}: {why}");
            }
            Ok(())
        };
        check("ndf", &self.ndf, 0.0, false)?;
        check("sigma", &self.sigma, 0.0, true)?;
        check("vndf", &self.vndf, 0.0, false)?;
        check("rgb", &self.rgb, 0.0, false)
    }

    /// The incidence grid: finite angles, increasing, theta in [0, 90] and phi in [-180, 180]
    /// degrees; an anisotropic file covers the whole circle of phi.
    fn check_incidence(&self, name: &str) -> Result<()> {
        let grid = |k: &str, g: &[f64], lo: f64, hi: f64| -> Result<()> {
            const SLACK: f64 = 1e-4;
            if let Some(i) = g
                .iter()
                .position(|&t| !(t.is_finite() && t >= lo - SLACK && t <= hi + SLACK))
            {
                bail!(
                    "{name}: field `{k}` entry {i} is {} rad: incidence angles must lie in [{lo:.4}, {hi:.4}] rad",
                    g[i]
                );
            }
            if let Some(i) = g.windows(2).position(|w| w[1] <= w[0]) {
                bail!(
                    "{name}: field `{k}` is not increasing: entry {} ({}) follows {}",
                    i + 1,
                    g[i + 1],
                    g[i]
                );
            }
            Ok(())
        };
        grid("theta_i", &self.theta_i.values, 0.0, FRAC_PI_2)?;
        grid("phi_i", &self.phi_i.values, -PI, PI)?;
        let np = self.phi_i.values.len();
        if np > 2 {
            let span = self.phi_i.values[np - 1] - self.phi_i.values[0];
            if ((2.0 * PI / span).round() as i64) != 1 {
                bail!("{name}: anisotropic files with a reduced phi_i range are not supported");
            }
        }
        Ok(())
    }

    /// The BRDF's tables, interpolated over the incidence grid.
    fn into_bsdf(self, description: String) -> RglBsdf {
        let (theta_i, phi_i) = (self.theta_i, self.phi_i);
        let (ndf, sigma, vndf, rgb) = (self.ndf, self.sigma, self.vndf, self.rgb);
        let np = phi_i.values.len();
        let incidence = vec![phi_i.values.clone(), theta_i.values.clone()];
        // incidences measured: the grid below the horizon (the last node at 90 deg is padding)
        let max_theta_i = theta_i
            .values
            .iter()
            .copied()
            .filter(|&t| t < FRAC_PI_2 - 1e-6)
            .fold(0.0, f64::max);
        RglBsdf {
            description,
            isotropic: np <= 2,
            ndf: Table2D::new(&ndf.shape, &ndf.values, vec![], false),
            sigma: Table2D::new(&sigma.shape, &sigma.values, vec![], false),
            vndf: Table2D::new(&vndf.shape, &vndf.values, incidence.clone(), true),
            rgb: Table2D::new(
                &rgb.shape,
                &rgb.values,
                vec![
                    incidence[0].clone(),
                    incidence[1].clone(),
                    vec![0.0, 1.0, 2.0],
                ],
                false,
            ),
            max_theta_i,
        }
    }
}

impl RglBsdf {
    pub fn load(path: &Path) -> Result<Self> {
        let mut f = read_tensor_file(path)?;
        let name = path.display().to_string();
        let fields = RglFields::take(&mut f, &name)?;
        fields.check_shapes(&name)?;
        fields.check_values(&name)?;
        fields.check_incidence(&name)?;
        let description = f
            .remove("description")
            .map(|d| d.values.iter().map(|&b| b as u8 as char).collect())
            .unwrap_or_default();
        Ok(fields.into_bsdf(description))
    }

    /// f(l, v) per channel in 1/sr (the file's value divided by cos theta_o); 0 at or below the
    /// horizon.
    pub fn brdf(&self, l: &Vec3, v: &Vec3) -> [f64; 3] {
        if !(l.z > 0.0 && v.z > 0.0) {
            return [0.0; 3];
        }
        let m = (l + v).normalize();
        let (theta_i, phi_i) = (l.z.clamp(-1.0, 1.0).acos(), l.y.atan2(l.x));
        let (theta_m, phi_m) = (m.z.clamp(-1.0, 1.0).acos(), m.y.atan2(m.x));
        let u_i = [theta_to_u(theta_i), phi_to_u(phi_i)];
        let mut u_m = [
            theta_to_u(theta_m),
            phi_to_u(if self.isotropic { phi_m - phi_i } else { phi_m }),
        ];
        u_m[1] -= u_m[1].floor();
        let inc = [phi_i, theta_i];
        let s = self.vndf.invert(u_m, &inc);
        let scale = self.ndf.eval(u_m, &inc) / (4.0 * self.sigma.eval(u_i, &inc)) / v.z;
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            *o = self.rgb.eval(s, &[phi_i, theta_i, c as f64]) * scale;
        }
        out
    }
}

/// Samples of an RGL file at `opts.directions` seeded pairs: light uniform in solid angle up to
/// min(max theta, the file's measured incidence), view up to max theta.
pub fn load(path: &Path, opts: MeasuredOptions) -> Result<Samples> {
    opts.check()?;
    let b = RglBsdf::load(path)?;
    let max_v = opts.max_theta_deg.to_radians();
    let max_l = max_v.min(b.max_theta_i);
    let mut rng = rand::rngs::StdRng::seed_from_u64(opts.seed);
    let mut dir = |max: f64| {
        let cmin = max.cos();
        let z: f64 = cmin + (1.0 - cmin) * rng.random::<f64>();
        direction_from_angles(z.acos(), rng.random::<f64>() * 2.0 * PI)
    };
    let samples = (0..opts.directions)
        .map(|k| {
            let l = dir(max_l);
            let v = dir(max_v);
            let value = b.brdf(&l, &v);
            // the tables are checked field by field; this catches what their combination gives
            if !value.iter().all(|f| f.is_finite() && f.abs() <= MAX_MAGNITUDE) {
                bail!(
                    "{}: the tables give f = {value:?} at direction pair {} (light theta {:.2}, view theta {:.2} degrees): values must be finite and within {MAX_MAGNITUDE:e}",
                    path.display(),
                    k + 1,
                    l.z.acos().to_degrees(),
                    v.z.acos().to_degrees()
                );
            }
            Ok(Sample {
                l,
                v,
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value,
                sigma: None,
                weight: 1.0,
                origin: Origin::Line(k as u64 + 1),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    super::samples::check_measured_values(&samples, path)?;
    Ok(Samples {
        samples,
        channels: 3,
        kind: DataKind::Measured,
        source: path.to_path_buf(),
        dropped: Dropped::default(),
        skipped_examples: vec![],
        image_size: None,
        scale_rel_se: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shared felt against 200 values of an independent evaluator (tests/data/rgl/README.md).
    #[test]
    fn reproduces_the_shared_check_values() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/rgl");
        let b = RglBsdf::load(&dir.join("acrylic_felt_green_rgb.bsdf")).unwrap();
        assert!(b.description.contains("felt"), "{}", b.description);
        assert!((b.max_theta_i.to_degrees() - 78.56).abs() < 0.1);
        let text = std::fs::read_to_string(dir.join("acrylic_felt_green_check.csv")).unwrap();
        let mut worst: f64 = 0.0;
        for line in text.lines().skip(1) {
            let x: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
            let l = direction_from_angles(x[0].to_radians(), x[1].to_radians());
            let v = direction_from_angles(x[2].to_radians(), x[3].to_radians());
            let f = b.brdf(&l, &v);
            for c in 0..3 {
                worst = worst.max((f[c] - x[4 + c]).abs() / x[4 + c].abs().max(1e-12));
            }
        }
        eprintln!("RGL check values: worst relative difference {worst:e}");
        assert!(worst < 1e-4, "worst relative difference {worst:e}");
    }
}
