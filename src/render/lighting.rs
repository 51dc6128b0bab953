//! Lightings for a preview (`render --preset`): cloth is judged at grazing light, so the default
//! (`studio`) adds a raking light and a rim light behind the object to the key light, where
//! sheen, fuzz and anisotropy show; `grazing` is one light at 80 deg incidence; `flat` is the
//! caller's own lights (one key light by default), as before.

use super::Light;
use crate::model::frame::Vec3;
use anyhow::{bail, Result};

/// A preview's lighting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preset {
    /// A key light in front to the left, a raking light from the right at 80 deg from the
    /// zenith and a rim light behind the object on the right.
    #[default]
    Studio,
    /// One light at 80 deg from the zenith, from the camera's right.
    Grazing,
    /// The caller's lights, as given.
    Flat,
}

impl Preset {
    /// The presets' names, in order.
    pub const NAMES: [&'static str; 3] = ["studio", "grazing", "flat"];

    /// The preset called `name`; an error names them all.
    pub fn parse(name: &str) -> Result<Self> {
        Ok(match name {
            "studio" => Preset::Studio,
            "grazing" => Preset::Grazing,
            "flat" => Preset::Flat,
            _ => bail!(
                "--preset {name}: expected one of {}",
                Self::NAMES.join(", ")
            ),
        })
    }

    /// The preset's lights for a camera looking from `camera` (unit, world z up); `None` for
    /// `flat` (the caller's lights). Irradiances relative to a key light of 1.
    pub fn lights(self, camera: Vec3) -> Option<Vec<Light>> {
        let (c, right, up) = camera_frame(camera);
        // theta from the zenith, towards the camera's right (+1) or left (-1), in front
        // (towards the camera, `front` > 0) or behind
        let raking = |side: f64, theta_deg: f64| {
            let t = theta_deg.to_radians();
            let across = (right - Vec3::z() * right.z).normalize();
            (Vec3::z() * t.cos() + across * (side * t.sin())).normalize()
        };
        let light = |direction: Vec3, irradiance: f64| Light::Directional {
            direction: direction.normalize(),
            irradiance,
        };
        match self {
            Preset::Flat => None,
            Preset::Grazing => Some(vec![light(raking(1.0, 80.0), 1.0)]),
            Preset::Studio => Some(vec![
                // key: in front, to the left, above
                light(c * 0.6 - right * 0.55 + up * 0.6, 1.0),
                // raking: from the right, 80 deg from the zenith
                light(raking(1.0, 80.0), 0.8),
                // rim: behind the object, to the right and above
                light(-c * 0.8 + right * 0.45 + up * 0.45, 0.5),
            ]),
        }
    }
}

/// The camera's frame: towards the camera, the picture's right and up (world z up; a camera
/// at the zenith takes x for right).
fn camera_frame(camera: Vec3) -> (Vec3, Vec3, Vec3) {
    let c = camera.normalize();
    let up0 = Vec3::z() - c * c.z;
    let up = if up0.norm() > 1e-6 {
        up0.normalize()
    } else {
        c.cross(&Vec3::x()).normalize()
    };
    // looking along -c with up: right = -c x up = up x c
    let right = up.cross(&c);
    (c, right, up)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn studio_lights_sit_around_the_camera_as_named() {
        let cam = crate::model::frame::direction_from_angles(50f64.to_radians(), 270f64.to_radians());
        let (c, right, up) = camera_frame(cam);
        assert!(right.dot(&c).abs() < 1e-12 && up.dot(&c).abs() < 1e-12 && up.z > 0.0);
        let Some(ls) = Preset::Studio.lights(cam) else {
            panic!("studio has lights")
        };
        let dirs: Vec<Vec3> = ls.iter().map(|l| l.at(&Vec3::zeros()).0).collect();
        assert!(dirs[0].dot(&c) > 0.0 && dirs[0].dot(&right) < 0.0);
        assert!((dirs[1].z - 80f64.to_radians().cos()).abs() < 1e-12 && dirs[1].dot(&right) > 0.0);
        assert!(dirs[2].dot(&c) < 0.0 && dirs[2].dot(&right) > 0.0);
        assert_eq!(Preset::Flat.lights(cam).map(|l| l.len()), None);
        assert!(Preset::parse("disco").unwrap_err().to_string().contains("studio, grazing, flat"));
    }
}
