//! Topology maps (MODEL.md §4): 8/16-bit PNG and float EXR load to the same values; bad maps are
//! named errors; the model's mean over a map matches the reference's exact mean.

mod common;
use common::*;
use exr::prelude::*;
use fibrefit::model::topology::{Topology, TopologyMap};
use fibrefit::model::{reference::Reference, varying_topology::VaryingTopology, ShadingModel};
use std::path::Path;
use std::sync::Arc;

const W: u32 = 24;
const H: u32 = 16;

fn value(x: u32, y: u32) -> f64 {
    ((x * 7 + y * 13) % 256) as f64 / 255.0
}

fn write_png8(path: &Path) {
    let img = image::GrayImage::from_fn(W, H, |x, y| {
        image::Luma([(value(x, y) * 255.0).round() as u8])
    });
    img.save(path).unwrap();
}

fn write_png16(path: &Path) {
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(W, H, |x, y| {
        image::Luma([(value(x, y) * 65535.0).round() as u16])
    });
    img.save(path).unwrap();
}

fn write_exr(path: &Path, f: impl Fn(u32, u32) -> f32) {
    let values: Vec<f32> = (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .map(|(x, y)| f(x, y))
        .collect();
    let channel = AnyChannel::new("Y", FlatSamples::F32(values));
    let layer = Layer::new(
        (W as usize, H as usize),
        LayerAttributes::named("topology"),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(vec![channel].into()),
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

#[test]
fn png8_png16_and_exr_load_the_same_map() {
    let dir = tempfile::tempdir().unwrap();
    let (p8, p16, pe) = (
        dir.path().join("m8.png"),
        dir.path().join("m16.png"),
        dir.path().join("m.exr"),
    );
    write_png8(&p8);
    write_png16(&p16);
    write_exr(&pe, |x, y| value(x, y) as f32);
    let maps: Vec<TopologyMap> = [&p8, &p16, &pe]
        .iter()
        .map(|p| TopologyMap::load(p).unwrap())
        .collect();
    for m in &maps {
        assert_eq!((m.width, m.height), (W as usize, H as usize));
        for y in 0..H {
            for x in 0..W {
                assert!(
                    (m.texel(x as usize, y as usize) - value(x, y)).abs() < 1e-6,
                    "{}",
                    m.source.display()
                );
            }
        }
    }
}

#[test]
fn bad_maps_are_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = dir.path().join("rgb.png");
    image::RgbImage::from_pixel(4, 4, image::Rgb([1, 2, 3]))
        .save(&rgb)
        .unwrap();
    let e = TopologyMap::load(&rgb).unwrap_err().to_string();
    assert!(e.contains("rgb.png") && e.contains("grayscale"), "{e}");
    let hot = dir.path().join("hot.exr");
    write_exr(&hot, |x, y| if (x, y) == (3, 2) { 1.5 } else { 0.5 });
    let e = TopologyMap::load(&hot).unwrap_err().to_string();
    assert!(
        e.contains("hot.exr") && e.contains("(3, 2)") && e.contains("[0, 1]"),
        "{e}"
    );
    let nan = dir.path().join("nan.exr");
    write_exr(&nan, |x, _| if x == 5 { f32::NAN } else { 0.5 });
    assert!(TopologyMap::load(&nan)
        .unwrap_err()
        .to_string()
        .contains("NaN"));
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"not a png").unwrap();
    let e = format!("{:#}", TopologyMap::load(&junk).unwrap_err());
    assert!(e.contains("junk.png"), "{e}");
    let txt = dir.path().join("map.txt");
    std::fs::write(&txt, b"0.5").unwrap();
    assert!(TopologyMap::load(&txt)
        .unwrap_err()
        .to_string()
        .contains(".png or .exr"));
}

#[test]
fn model_mean_over_an_8bit_map_matches_the_exact_reference() {
    let dir = tempfile::tempdir().unwrap();
    let p8 = dir.path().join("m8.png");
    write_png8(&p8);
    let map = Arc::new(TopologyMap::load(&p8).unwrap());
    let topo = Topology {
        height: 0.8,
        map_scale: 0.6,
        map: Some(map),
    };
    let exact = Reference::new(2.0, 20.0, topo.clone());
    // 256 bins hold one distinct 8-bit value each: the histogram is then exact too
    let fine = VaryingTopology::new(2.0, 20.0, 64, topo.discretise(2.0, 256));
    let coarse = VaryingTopology::new(2.0, 20.0, 64, topo.discretise(2.0, 2));
    let (mut worst_fine, mut worst_coarse) = (0.0f64, 0.0f64);
    for pair in random_pairs(10, 8, 0.1) {
        let (a, b, c) = (fine.basis(&pair), exact.basis(&pair), coarse.basis(&pair));
        worst_fine = worst_fine.max(rel_diff(a.diffuse, b.diffuse));
        worst_coarse = worst_coarse.max(rel_diff(c.diffuse, b.diffuse));
        assert!(
            rel_diff(a.specular, b.specular) < 1e-6,
            "{} vs {}",
            a.specular,
            b.specular
        );
    }
    assert!(worst_fine < 1e-9, "{worst_fine}");
    assert!(worst_coarse > worst_fine);
}
