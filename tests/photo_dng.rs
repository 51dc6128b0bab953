//! Camera RAW photos (issue 36): a DNG written as a camera writes one (`export::dng`: Bayer
//! mosaic, black and white levels, colour matrix) decodes through the kept RAW decoder to the
//! linear values it holds, channel by channel and pixel by pixel; corrupt, truncated and
//! oversized DNGs are refused by name.

use fibrefit::export::dng::{dng_bytes, DngExposure, BLACK, WHITE};
use fibrefit::load::image_io::decode_raw;

const EXPOSURE: DngExposure = DngExposure {
    time_s: 0.01,
    iso: 100,
    f_number: 2.0,
};

/// A smooth colour field with ramps along x and y.
fn field(w: usize, h: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(3 * w * h);
    for y in 0..h {
        for x in 0..w {
            let (u, t) = (x as f32 / w as f32, y as f32 / h as f32);
            v.extend([0.1 + 0.6 * u, 0.2 + 0.5 * t, 0.15 + 0.3 * u * t]);
        }
    }
    v
}

#[test]
fn a_dng_decodes_to_the_linear_values_it_holds() {
    let (w, h) = (1600usize, 1200usize);
    let truth = field(w, h);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ramp.dng");
    std::fs::write(
        &path,
        dng_bytes(w as u32, h as u32, &truth, EXPOSURE).unwrap(),
    )
    .unwrap();
    let (dw, dh, got) = decode_raw(&path, "photo").unwrap();
    assert_eq!((dw, dh), (w, h));
    // a linear field is what bilinear demosaicing reproduces exactly, away from the border;
    // the codes quantise to 1 / (white - black)
    let step = 1.0 / (WHITE - BLACK) as f32;
    let mut worst = [0.0f32; 3];
    for y in 2..h - 2 {
        for x in 2..w - 2 {
            for c in 0..3 {
                let i = 3 * (y * w + x) + c;
                let e = (got[i] - truth[i]).abs();
                if e > 1e-3 && x % 50 == 0 {
                    eprintln!("x {x} y {y} c {c}: err {e}");
                }
                worst[c] = worst[c].max(e);
            }
        }
    }
    eprintln!("worst |decoded - truth| per channel: {worst:?} (code step {step:.2e})");
    // the blue channel's product u t is not linear: bilinear demosaicing misses its curvature
    // by at most 0.3 / (w h) x 1 px^2
    for c in 0..3 {
        assert!(worst[c] < 3.0 * step + 1e-4, "channel {c}: {}", worst[c]);
    }
}

#[test]
fn broken_dngs_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (64usize, 48usize);
    let bytes = dng_bytes(w as u32, h as u32, &field(w, h), EXPOSURE).unwrap();
    // truncated in its pixels
    let cut = dir.path().join("cut.dng");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    // not a DNG at all
    let junk = dir.path().join("junk.dng");
    std::fs::write(&junk, b"II*\0 this is not a raw file at all").unwrap();
    // a header that claims 2^20 x 2^20 pixels: ImageWidth and ImageLength patched
    let mut bomb = bytes.clone();
    patch_long_tag(&mut bomb, 256, 1 << 20);
    patch_long_tag(&mut bomb, 257, 1 << 20);
    let big = dir.path().join("bomb.dng");
    std::fs::write(&big, &bomb).unwrap();
    for (p, what) in [(&cut, "truncated"), (&junk, "not a DNG"), (&big, "bomb")] {
        let e = decode_raw(p, "photo").unwrap_err();
        let text = format!("{e:#}");
        eprintln!("{what}: {text}");
        assert!(text.contains(&p.display().to_string()), "{text}");
    }
}

/// Set the LONG value of tag `tag` in the first directory of the little-endian TIFF `bytes`.
fn patch_long_tag(bytes: &mut [u8], tag: u16, value: u32) {
    let ifd = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes(bytes[ifd..ifd + 2].try_into().unwrap()) as usize;
    for e in 0..n {
        let at = ifd + 2 + 12 * e;
        if u16::from_le_bytes(bytes[at..at + 2].try_into().unwrap()) == tag {
            let kind = u16::from_le_bytes(bytes[at + 2..at + 4].try_into().unwrap());
            match kind {
                3 => {
                    bytes[at + 8..at + 10].copy_from_slice(&(value.min(65535) as u16).to_le_bytes())
                }
                _ => bytes[at + 8..at + 12].copy_from_slice(&value.to_le_bytes()),
            }
            return;
        }
    }
    panic!("tag {tag} not found");
}
