//! What a photo set samples: each photo's light and view directions at the window's centre, and
//! warnings where they leave a fibre model's parameters undetermined (every view near the
//! normal, no grazing light, light from one side only, only the highlight's peak seen).

use nalgebra::Vector3;

/// A direction as (theta, phi) in degrees from the window's centre to `p` (mm, board frame).
pub fn angles(p: &Vector3<f64>) -> [f64; 2] {
    let d = p.normalize();
    [
        d.z.clamp(-1.0, 1.0).acos().to_degrees(),
        d.y.atan2(d.x).to_degrees().rem_euclid(360.0),
    ]
}

/// Each photo's (light, view, half vector) directions as (theta, phi) degrees at the window's
/// centre, from the cameras' and lights' positions (mm, board frame).
pub fn directions(cameras: &[Vector3<f64>], lights: &[Vector3<f64>]) -> Vec<[[f64; 2]; 3]> {
    cameras
        .iter()
        .zip(lights)
        .map(|(c, l)| {
            let h = c.normalize() + l.normalize();
            [angles(l), angles(c), angles(&h)]
        })
        .collect()
}

/// Views all within this of the normal (deg) cannot separate the fibres' height.
pub const NEAR_NORMAL_DEG: f64 = 25.0;
/// A light this far from the normal (deg) or more is grazing.
pub const GRAZING_DEG: f64 = 45.0;
/// Lights whose azimuths fit in a sector this narrow (deg) come from one side.
pub const ONE_SIDE_DEG: f64 = 120.0;
/// Half vectors all within this of the normal (deg) see only the highlight's peak.
pub const PEAK_ONLY_DEG: f64 = 10.0;

/// The smallest sector (deg) holding every azimuth of `phis` (deg): 360 less the widest gap.
pub fn azimuth_span(phis: &[f64]) -> f64 {
    if phis.len() < 2 {
        return 0.0;
    }
    let mut p: Vec<f64> = phis.iter().map(|x| x.rem_euclid(360.0)).collect();
    p.sort_by(f64::total_cmp);
    let mut gap = p[0] + 360.0 - p[p.len() - 1];
    for w in p.windows(2) {
        gap = gap.max(w[1] - w[0]);
    }
    360.0 - gap
}

/// Warnings on what the directions `dirs` ([`directions`]) leave undetermined.
pub fn warnings(dirs: &[[[f64; 2]; 3]]) -> Vec<String> {
    let mut out = Vec::new();
    let max = |k: usize| dirs.iter().map(|d| d[k][0]).fold(0.0, f64::max);
    if max(1) < NEAR_NORMAL_DEG {
        out.push(format!(
            "every view is within {NEAR_NORMAL_DEG} deg of the normal (largest {:.0} deg): the fibres' height (their shadowing) and the lobe away from the mirror are undetermined; add views at 40-60 deg",
            max(1)
        ));
    }
    if max(0) < GRAZING_DEG {
        out.push(format!(
            "no light is {GRAZING_DEG} deg or more from the normal (largest {:.0} deg): the fibres' height and the fuzz's grazing response are poorly determined; add photos from lower down (or a lamp low to the side)",
            max(0)
        ));
    }
    let span = azimuth_span(&dirs.iter().map(|d| d[0][1]).collect::<Vec<_>>());
    if dirs.len() >= 2 && span < ONE_SIDE_DEG {
        out.push(format!(
            "the lights' azimuths span {span:.0} deg (under {ONE_SIDE_DEG}): light from one side cannot tell along the fibres from across them; light from around the board"
        ));
    }
    if max(2) < PEAK_ONLY_DEG {
        out.push(format!(
            "every half vector is within {PEAK_ONLY_DEG} deg of the normal: only the highlight's peak is seen, not its width or anisotropy"
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(theta: f64, phi: f64) -> Vector3<f64> {
        let (t, p) = (theta.to_radians(), phi.to_radians());
        Vector3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos()) * 300.0
    }

    #[test]
    fn angles_and_spans_are_right() {
        let [t, p] = angles(&at(40.0, 250.0));
        assert!((t - 40.0).abs() < 1e-9 && (p - 250.0).abs() < 1e-9);
        assert!((azimuth_span(&[350.0, 10.0, 20.0]) - 30.0).abs() < 1e-9);
        assert!((azimuth_span(&[0.0, 90.0, 180.0, 270.0]) - 270.0).abs() < 1e-9);
    }

    #[test]
    fn a_set_from_around_warns_of_nothing_and_a_narrow_one_of_each_gap() {
        let around: Vec<Vector3<f64>> = (0..8).map(|i| at(20.0 + 10.0 * (i % 4) as f64, 45.0 * i as f64)).collect();
        assert!(warnings(&directions(&around, &around)).is_empty());
        let narrow: Vec<Vector3<f64>> = (0..4).map(|i| at(2.0 + 2.0 * i as f64, 10.0 * i as f64)).collect();
        let w = warnings(&directions(&narrow, &narrow)).join("\n");
        for want in ["every view", "no light", "span", "half vector"] {
            assert!(w.contains(want), "{want}: {w}");
        }
    }
}
