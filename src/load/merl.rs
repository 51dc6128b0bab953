//! MERL measured BRDFs (`.binary`; Matusik et al. 2003, "A Data-Driven Reflectance Model").
//!
//! The file: three little-endian i32 dimensions (theta_h, theta_d, phi_d resolutions; 90, 90,
//! 180 in the published database), then the table as f64, all red values, then all green, then all
//! blue, with phi_d fastest. The table is isotropic and in Rusinkiewicz's half/difference
//! coordinates: theta_h (the half vector from the normal, indexed by sqrt(theta_h / (pi/2)) so
//! that the specular peak is resolved), theta_d and phi_d (the light seen from the half vector,
//! phi_d folded into [0, pi) by reciprocity). Values are scaled per channel by 1/1500, 1.15/1500
//! and 1.66/1500 to give f in 1/sr; lookups take the nearest cell, as the database's reference
//! reader does. Negative entries mark directions that were not measured; such samples are left out
//! and counted.

use super::rgl::MeasuredOptions;
use super::rgl::MAX_MAGNITUDE;
use super::samples::{DataKind, Dropped, Origin, Sample, Samples};
use crate::model::frame::{direction_from_angles, Vec3};
use anyhow::{bail, Result};
use rand::{Rng, SeedableRng};
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Read;
use std::path::Path;

/// Per-channel scale from the stored numbers to 1/sr.
pub const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];

pub struct MerlBrdf {
    /// theta_h, theta_d, phi_d resolutions.
    pub dims: [usize; 3],
    data: Vec<f64>,
}

/// Rotate `v` about the unit `axis` by `angle` (Rodrigues).
fn rotate(v: Vec3, axis: Vec3, angle: f64) -> Vec3 {
    let (s, c) = angle.sin_cos();
    v * c + axis * (axis.dot(&v) * (1.0 - c)) + axis.cross(&v) * s
}

/// Rusinkiewicz's (theta_h, theta_d, phi_d) of a light/view pair.
pub fn half_diff(l: &Vec3, v: &Vec3) -> (f64, f64, f64) {
    let h = (l + v).normalize();
    let theta_h = h.z.clamp(-1.0, 1.0).acos();
    let phi_h = h.y.atan2(h.x);
    let d = rotate(*l, Vec3::z(), -phi_h);
    let d = rotate(d, Vec3::y(), -theta_h);
    (theta_h, d.z.clamp(-1.0, 1.0).acos(), d.y.atan2(d.x))
}

impl MerlBrdf {
    pub fn load(path: &Path) -> Result<Self> {
        let name = path.display();
        let mut input = super::input::open(path, super::input::MAX_MEASURED_BYTES)?;
        let mut header = [0u8; 12];
        let mut got = 0;
        while got < 12 {
            match input.read(&mut header[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(super::input::io_error(path, e)),
            }
        }
        if got < 12 {
            bail!("{name}: not a MERL .binary BRDF: shorter than its 12-byte header");
        }
        let dim = |k: usize| {
            i32::from_le_bytes([
                header[4 * k],
                header[4 * k + 1],
                header[4 * k + 2],
                header[4 * k + 3],
            ])
        };
        let dims = [dim(0), dim(1), dim(2)];
        if dims.iter().any(|&d| !(1..=4096).contains(&d)) {
            bail!("{name}: not a MERL .binary BRDF: dimensions {dims:?} (the database's are 90, 90, 180)");
        }
        let dims = dims.map(|d| d as usize);
        // checked arithmetic: 3 channels x n doubles after the header, within the limit
        let n = dims[0]
            .checked_mul(dims[1])
            .and_then(|x| x.checked_mul(dims[2]))
            .filter(|&n| n.checked_mul(24).is_some());
        let want = n.and_then(|n| (n * 24).checked_add(12)).map(|w| w as u64);
        let (n, want) = match (n, want) {
            (Some(n), Some(w)) if w <= super::input::MAX_MEASURED_BYTES => (n, w),
            _ => bail!(
                "{name}: dimensions {dims:?} need more than {} (3 channels of doubles), the largest measured file read",
                super::input::bytes_text(super::input::MAX_MEASURED_BYTES)
            ),
        };
        let size_said = input.size();
        if let Some(size) = size_said {
            if size != want {
                bail!("{name}: {size} bytes, but dimensions {dims:?} need {want} (3 channels x {n} doubles)");
            }
        }
        // a device or FIFO: read what the header says and one byte more, to see that it ends
        input.limit_to(want + 1);
        let mut bytes = Vec::with_capacity(want as usize - 12);
        match input.read_rest(&mut bytes) {
            Ok(()) => {}
            Err(_) if size_said.is_none() && bytes.len() as u64 > want - 12 => {
                bail!("{name}: longer than the {want} bytes its dimensions {dims:?} need")
            }
            Err(e) => return Err(e),
        }
        if bytes.len() as u64 != want - 12 {
            bail!(
                "{name}: {} bytes, but dimensions {dims:?} need {want} (3 channels x {n} doubles)",
                bytes.len() + 12
            );
        }
        input.finish()?;
        let data: Vec<f64> = bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
            .collect();
        drop(bytes);
        // negative entries mark unmeasured cells (kept, left out when drawn); positive ones must
        // be finite and within the magnitude the fit can square
        if let Some(i) = data
            .iter()
            .position(|v| !(v.is_finite() && *v * SCALE[2] <= MAX_MAGNITUDE))
        {
            let c = ["red", "green", "blue"][i / n];
            let cell = i % n;
            bail!(
                "{name}: table entry {i} ({c}, theta_h {} theta_d {} phi_d {}) is {}: values must be finite and within {MAX_MAGNITUDE:e} 1/sr",
                cell / (dims[1] * dims[2]),
                cell / dims[2] % dims[1],
                cell % dims[2],
                data[i]
            );
        }
        Ok(Self { dims, data })
    }

    /// Table index of a pair (nearest cell).
    fn index(&self, l: &Vec3, v: &Vec3) -> usize {
        let [nh, nd, np] = self.dims;
        let (th, td, mut pd) = half_diff(l, v);
        let ih = ((th / FRAC_PI_2).max(0.0).sqrt() * nh as f64) as usize;
        let id = ((td / FRAC_PI_2).max(0.0) * nd as f64) as usize;
        if pd < 0.0 {
            pd += PI; // reciprocity: phi_d and phi_d + pi are the same pair
        }
        let ip = ((pd / PI).max(0.0) * np as f64) as usize;
        ip.min(np - 1) + id.min(nd - 1) * np + ih.min(nh - 1) * np * nd
    }

    /// f per channel in 1/sr; None where the table marks the cell unmeasured; 0 below the
    /// horizon.
    pub fn brdf(&self, l: &Vec3, v: &Vec3) -> Option<[f64; 3]> {
        if !(l.z > 0.0 && v.z > 0.0) {
            return Some([0.0; 3]);
        }
        let i = self.index(l, v);
        let n = self.data.len() / 3;
        let f = [0, 1, 2].map(|c| self.data[i + c * n] * SCALE[c]);
        f.iter().all(|&x| x >= 0.0).then_some(f)
    }
}

/// Samples of a MERL file at `opts.directions` seeded pairs, light and view uniform in solid
/// angle up to the largest theta.
pub fn load(path: &Path, opts: MeasuredOptions) -> Result<Samples> {
    opts.check()?;
    let b = MerlBrdf::load(path)?;
    let cmin = opts.max_theta_deg.to_radians().cos();
    let mut rng = rand::rngs::StdRng::seed_from_u64(opts.seed);
    let mut dir = || {
        let z: f64 = cmin + (1.0 - cmin) * rng.random::<f64>();
        direction_from_angles(z.acos(), rng.random::<f64>() * 2.0 * PI)
    };
    let mut dropped = Dropped::default();
    let mut samples = Vec::with_capacity(opts.directions);
    for k in 0..opts.directions {
        let (l, v) = (dir(), dir());
        match b.brdf(&l, &v) {
            Some(value) => samples.push(Sample {
                l,
                v,
                fibre_azimuth: None,
                map_value: None,
                texel_height: None,
                value,
                sigma: None,
                weight: 1.0,
                origin: Origin::Line(k as u64 + 1),
            }),
            None => dropped.invalid += 1,
        }
    }
    if samples.is_empty() {
        bail!(
            "{}: no measured cell at any drawn direction",
            path.display()
        );
    }
    super::samples::check_measured_values(&samples, path)?;
    Ok(Samples {
        samples,
        channels: 3,
        kind: DataKind::Measured,
        source: path.to_path_buf(),
        dropped,
        skipped_examples: vec![],
        image_size: None,
        scale_rel_se: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small table whose value is known from its indices: red = 1500 (0.1 + 0.01 i_h),
    /// green = 1500 / 1.15 x 0.01 i_d, blue = 1500 / 1.66 x 0.001 i_p; one row unmeasured.
    fn write_table(path: &Path, dims: [usize; 3]) {
        let [nh, nd, np] = dims;
        let n = nh * nd * np;
        let mut bytes = Vec::new();
        for d in dims {
            bytes.extend_from_slice(&(d as i32).to_le_bytes());
        }
        let mut data = vec![0.0f64; 3 * n];
        for ih in 0..nh {
            for id in 0..nd {
                for ip in 0..np {
                    let i = ip + id * np + ih * np * nd;
                    data[i] = 1500.0 * (0.1 + 0.01 * ih as f64);
                    data[i + n] = 1500.0 / 1.15 * 0.01 * id as f64;
                    data[i + 2 * n] = 1500.0 / 1.66 * 0.001 * ip as f64;
                }
            }
        }
        // red at the last theta_h and theta_d = 0 (every phi_d): unmeasured
        for ip in 0..np {
            data[ip + (nh - 1) * np * nd] = -1.0;
        }
        for v in data {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(path, bytes).unwrap();
    }

    #[test]
    fn lookups_follow_the_half_difference_indexing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.binary");
        let dims = [9, 9, 18];
        write_table(&path, dims);
        let b = MerlBrdf::load(&path).unwrap();
        // l = v at theta: theta_h = theta, theta_d = 0: red follows sqrt(theta / 90 deg) x 9
        for theta in [5.0f64, 20.0, 40.0, 60.0, 70.0] {
            let l = direction_from_angles(theta.to_radians(), 0.7);
            let f = b.brdf(&l, &l).unwrap();
            let ih = ((theta / 90.0).sqrt() * 9.0) as usize;
            assert!(
                (f[0] - (0.1 + 0.01 * ih as f64)).abs() < 1e-12,
                "theta {theta}: {f:?}"
            );
            assert!(f[1].abs() < 1e-12);
        }
        // mirror pair about the normal at theta: theta_h = 0, theta_d = theta
        for theta in [10.0f64, 35.0, 70.0] {
            let l = direction_from_angles(theta.to_radians(), 0.3);
            let v = Vec3::new(-l.x, -l.y, l.z);
            let f = b.brdf(&l, &v).unwrap();
            let id = (theta / 90.0 * 9.0) as usize;
            assert!((f[0] - 0.1).abs() < 1e-12, "{f:?}");
            assert!(
                (f[1] - 0.01 * id as f64).abs() < 1e-12,
                "theta {theta}: {f:?}"
            );
        }
        // reciprocal by construction, and the half/diff coordinates of a known pair
        let l = direction_from_angles(0.5, 0.2);
        let v = direction_from_angles(0.9, 2.4);
        assert_eq!(b.brdf(&l, &v), b.brdf(&v, &l));
        let (th, td, _) = half_diff(&l, &v);
        let h = (l + v).normalize();
        assert!((th - h.z.acos()).abs() < 1e-12);
        assert!((td - l.dot(&h).acos()).abs() < 1e-12);
        // the unmeasured row (l = v at 80 deg: the last theta_h, theta_d = 0): None
        let l = direction_from_angles(80f64.to_radians(), 1.0);
        assert_eq!(b.brdf(&l, &l), None);
        // a truncated file: a named error
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 8]).unwrap();
        let e = MerlBrdf::load(&path).err().unwrap().to_string();
        assert!(e.contains("need") && e.contains("t.binary"), "{e}");
    }
}
