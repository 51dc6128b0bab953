//! Maps from a capture taken as a rig takes it — point lights and pinhole cameras 300 mm away,
//! image 0 lit by a flash beside its lens, so every texel sees its own directions — recovered as
//! accurately as from the same directions with directional lights and orthographic cameras
//! (issue 24 item 1): on the direct path (a 20 mm swatch at 24 x 24 pixels: directions turn too
//! fast between pixels for a lattice of column tables) and on the lattice path (a 3 mm swatch at
//! 48 x 48: node tables blended in the position).

use fibrefit::bench::camera::{synth_config_of, Rig, FIT_MAPS};
use fibrefit::fit::config::FitConfig;
use fibrefit::load::capture_store::CaptureStore;
use fibrefit::model::topology::TopologyMap;
use std::path::Path;

/// How the maps of one capture came out: RMS height error (fibre radii), and the fractions of
/// texels whose H and psi lie within 3 of their standard errors of the truth.
#[derive(Debug)]
struct Accuracy {
    rms_h: f64,
    within_h: f64,
    within_psi: f64,
    texels: usize,
}

fn maps_of(dir: &Path, size: usize, size_mm: f64, rig: Rig) -> (Accuracy, Option<(usize, usize)>) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("synth.toml"), synth_config_of(size, size_mm, rig)).unwrap();
    fibrefit::synth::run(
        &dir.join("synth.toml"),
        &dir.join("d"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let blind = fibrefit::bench::maps::write_blind(&dir.join("d")).unwrap();
    let store = CaptureStore::load(&blind, Default::default()).unwrap();
    let cfg: FitConfig = toml::from_str(FIT_MAPS).unwrap();
    let lattice = fibrefit::fit::maps::lattice_nodes(&store, &cfg.maps);
    let o = fibrefit::fit::maps::recover(
        &store,
        &cfg,
        &cfg.maps,
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let topo = TopologyMap::load(&dir.join("d/topology.png")).unwrap();
    let tan = TopologyMap::load_as(&dir.join("d/tangent.png"), "tangent map").unwrap();
    let (mut sq, mut in_h, mut in_p) = (0.0, 0usize, 0usize);
    for (k, &(x, y)) in o.maps.texels.iter().enumerate() {
        let (x, y) = (x as usize, y as usize);
        let (v, se) = (&o.maps.values[k], &o.maps.std_errors[k]);
        let dh = v.height - (0.9 + 0.6 * (2.0 * topo.texel(x, y) - 1.0));
        let dp = fibrefit::fit::wrap_azimuth(v.psi - (-90.0 + 180.0 * tan.texel(x, y)));
        sq += dh * dh;
        in_h += usize::from(dh.abs() <= 3.0 * se.height);
        in_p += usize::from(dp.abs() <= 3.0 * se.psi);
    }
    let n = o.maps.texels.len();
    let accuracy = Accuracy {
        rms_h: (sq / n as f64).sqrt(),
        within_h: in_h as f64 / n as f64,
        within_psi: in_p as f64 / n as f64,
        texels: n,
    };
    (accuracy, lattice)
}

/// The pinhole capture's maps against the orthographic one's from the same directions.
/// `lattice`: whether the pinhole capture's texels read a lattice of column tables.
fn as_accurate_as_orthographic(size: usize, size_mm: f64, lattice: bool) {
    let dir = tempfile::tempdir().unwrap();
    let (ortho, shared) = maps_of(&dir.path().join("ortho"), size, size_mm, Rig::Distant);
    let (near, nodes) = maps_of(&dir.path().join("near"), size, size_mm, Rig::Near);
    // the orthographic texels share one table; the pinhole ones a lattice or none
    assert_eq!(shared, None);
    assert_eq!(nodes.is_some(), lattice, "{nodes:?}");
    eprintln!("{size} x {size}, {size_mm} mm: orthographic {ortho:?}, pinhole {near:?}");
    assert_eq!(near.texels, size * size);
    for a in [&ortho, &near] {
        assert!(a.within_h >= 0.97 && a.within_psi >= 0.97, "{a:?}");
    }
    // the RMS is set by the few texels in the other flat branch of the height (their errors
    // cover it): as good as the orthographic capture's within that
    assert!(
        near.rms_h <= 1.5 * ortho.rms_h + 0.01,
        "{near:?} vs {ortho:?}"
    );
}

#[test]
fn pinhole_maps_evaluated_directly_are_as_accurate_as_orthographic() {
    as_accurate_as_orthographic(24, 20.0, false);
}

#[test]
fn pinhole_maps_from_the_direction_lattice_are_as_accurate_as_orthographic() {
    as_accurate_as_orthographic(48, 3.0, true);
}
