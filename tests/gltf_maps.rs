//! `fibrefit export --gltf` of a `fit --maps` result carries the maps as textures (base colour,
//! metallic-roughness, KHR_materials_anisotropy's texture), registered to the mesh's TEXCOORD_0;
//! a result without maps keeps the factors alone.

mod common;

use assert_cmd::Command;
use common::{maps_fit, SYNTH};
use fibrefit::fit::gltf_material::{self, TexelMaterials};
use fibrefit::load::image_io;
use std::path::Path;

fn fibrefit() -> Command {
    Command::cargo_bin("fibrefit").expect("binary built")
}

fn glb_json(bytes: &[u8]) -> serde_json::Value {
    let glb = gltf::binary::Glb::from_slice(bytes).unwrap();
    serde_json::from_slice(&glb.json).unwrap()
}

/// Image `i` of a GLB, decoded to 8-bit RGB.
fn image_rgb(g: &gltf::Gltf, i: usize) -> image::RgbImage {
    let blob = g.blob.as_ref().unwrap();
    let img = g.images().nth(i).unwrap();
    let gltf::image::Source::View { view, mime_type } = img.source() else {
        panic!("image {i} is not in the buffer");
    };
    assert_eq!(mime_type, "image/png");
    let bytes = &blob[view.offset()..view.offset() + view.length()];
    image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .unwrap()
        .to_rgb8()
}

fn srgb8(linear: f64) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let e = if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round() as u8
}

fn near(a: u8, b: u8, tol: u8) -> bool {
    a.abs_diff(b) <= tol
}

#[test]
fn a_maps_fit_exported_as_gltf_carries_its_maps_as_textures() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("synth.toml"), SYNTH).unwrap();
    fibrefit::synth::run(
        &d.join("synth.toml"),
        &d.join("cap"),
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let blind = fibrefit::bench::maps::write_blind(&d.join("cap")).unwrap();
    // fewer rounds than tests/maps.rs: the textures are checked against the maps as fitted
    std::fs::write(d.join("fit.toml"), maps_fit(8)).unwrap();
    let maps = d.join("maps");
    let result = d.join("r.json");
    fibrefit()
        .arg("fit")
        .arg(&blind)
        .arg("--config")
        .arg(d.join("fit.toml"))
        .arg("--out")
        .arg(&result)
        .arg("--maps")
        .arg(&maps)
        .arg("-q")
        .assert()
        .success();
    let glb = d.join("m.glb");
    let run = fibrefit()
        .arg("export")
        .arg(&result)
        .arg("--gltf")
        .arg(&glb)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    eprintln!("{stderr}");
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains("textures from the maps in")
            && stderr.contains("base colour, metallic-roughness, anisotropy"),
        "{stderr}"
    );
    let bytes = std::fs::read(&glb).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    assert_eq!(g.images().count(), 3);
    assert_eq!(g.textures().count(), 3);
    assert_eq!(g.samplers().count(), 1);
    let prim = g.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|_| Some(g.blob.as_deref().unwrap()));
    let uvs: Vec<[f32; 2]> = reader
        .read_tex_coords(0)
        .expect("TEXCOORD_0")
        .into_f32()
        .collect();
    assert_eq!(uvs.len(), 17 * 17);
    let mat = prim.material();
    let pbr = mat.pbr_metallic_roughness();
    assert_eq!(pbr.base_color_factor(), [1.0; 4]);
    assert_eq!(pbr.roughness_factor(), 1.0);
    assert_eq!(pbr.metallic_factor(), 0.0);
    let base_tex = pbr.base_color_texture().expect("a base colour texture");
    let mr_tex = pbr
        .metallic_roughness_texture()
        .expect("a roughness texture");
    assert_eq!(base_tex.tex_coord(), 0);
    let raw = glb_json(&bytes);
    let an = &raw["materials"][0]["extensions"]["KHR_materials_anisotropy"];
    assert_eq!(an["anisotropyStrength"].as_f64(), Some(1.0));
    let an_tex = an["anisotropyTexture"]["index"]
        .as_u64()
        .expect("an anisotropy texture") as usize;
    let source = |t: usize| g.textures().nth(t).unwrap().source().index();
    let base = image_rgb(&g, source(base_tex.texture().index()));
    let rough = image_rgb(&g, source(mr_tex.texture().index()));
    let aniso = image_rgb(&g, source(an_tex));
    for img in [&base, &rough, &aniso] {
        assert_eq!(img.dimensions(), (16, 16));
    }
    let described = &raw["materials"][0]["extras"]["fibrefit"]["textures"];
    assert_eq!(
        described["height_nodes"].as_array().unwrap().len(),
        9,
        "{described}"
    );

    // the maps and the globals, read back as an engine's exporter would see them
    let read = |n: &str| image_io::read(&maps.join(n), None, None).unwrap();
    let (kd, psi, height) = (
        read("kd.exr"),
        read("fibre_azimuth.exr"),
        read("height.exr"),
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    let psi0 = r["parameters"]["fibre_azimuth_deg"]["value"]
        .as_f64()
        .unwrap();

    // the anisotropy direction is the texel's azimuth relative to the TANGENT (the globals')
    let mut worst: f64 = 0.0;
    for y in 0..16 {
        for x in 0..16 {
            let px = aniso.get_pixel(x as u32, y as u32).0;
            let (c, s) = (
                2.0 * px[0] as f64 / 255.0 - 1.0,
                2.0 * px[1] as f64 / 255.0 - 1.0,
            );
            let got = s.atan2(c).to_degrees();
            let want = psi.pixel(x, y)[0] as f64 - psi0;
            let diff = (got - want + 90.0).rem_euclid(180.0) - 90.0;
            worst = worst.max(diff.abs());
        }
    }
    assert!(worst < 1.0, "anisotropy direction off by {worst} deg");
    // the maps span 70 deg of azimuth, so a flipped or transposed texture would fail above
    let (lo, hi) = psi
        .data
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(hi - lo > 50.0, "{lo} {hi}");

    // base colour, roughness and strength at texels: the glTF fit's own per-texel values
    let (_, id, params) =
        fibrefit::api::eval::load_params(&result, None, &fibrefit::progress::Progress::quiet())
            .unwrap();
    let model = fibrefit::model::build(id, &params).unwrap();
    let fitted = gltf_material::fit(model.as_ref(), &params.albedos, 1).unwrap();
    let h_max = fibrefit::model::topology::max_height(params.spacing);
    let (hlo, hhi) = height.data.iter().fold((f64::MAX, f64::MIN), |(a, b), &v| {
        let v = (v as f64).clamp(0.0, h_max);
        (a.min(v), b.max(v))
    });
    let table = TexelMaterials::new(
        model.as_ref(),
        &params.albedos,
        &fitted,
        Some((hlo, hhi)),
        1,
    )
    .unwrap();
    let nodes = table.nodes();
    assert_eq!(nodes.len(), 9);
    assert!(nodes.iter().all(|n| n.relative_rms_error < 1.0));
    for &(x, y) in &[
        (0usize, 0usize),
        (15, 0),
        (0, 15),
        (7, 9),
        (12, 4),
        (15, 15),
    ] {
        let mut a = params.albedos;
        let k = kd.pixel(x, y)[0] as f64;
        assert!(k.is_finite());
        a.diffuse = [k; 3];
        if params.albedos.substrate == params.albedos.diffuse {
            a.substrate = [k; 3];
        }
        let m = table.at(Some((height.pixel(x, y)[0] as f64).clamp(0.0, h_max)), &a);
        let got = base.get_pixel(x as u32, y as u32).0;
        for c in 0..3 {
            assert!(
                near(got[c], srgb8(m.base_color[c]), 1),
                "({x}, {y}) {got:?} {m:?}"
            );
        }
        let rp = rough.get_pixel(x as u32, y as u32).0;
        assert!(
            near(rp[1], (m.roughness * 255.0).round() as u8, 1),
            "{rp:?} {m:?}"
        );
        assert_eq!(rp[2], 0);
        let ap = aniso.get_pixel(x as u32, y as u32).0;
        assert!(near(
            ap[2],
            (m.anisotropy_strength * 255.0).round() as u8,
            1
        ));
    }
    // brighter kd, brighter base colour (grey capture: the three channels agree)
    let texels: Vec<(usize, usize)> = (0..16).flat_map(|y| (0..16).map(move |x| (x, y))).collect();
    let (dark, bright) = (
        texels
            .iter()
            .min_by(|a, b| kd.pixel(a.0, a.1)[0].total_cmp(&kd.pixel(b.0, b.1)[0]))
            .unwrap(),
        texels
            .iter()
            .max_by(|a, b| kd.pixel(a.0, a.1)[0].total_cmp(&kd.pixel(b.0, b.1)[0]))
            .unwrap(),
    );
    let at = |t: &(usize, usize)| base.get_pixel(t.0 as u32, t.1 as u32).0;
    assert!(at(dark)[0] == at(dark)[1] && at(dark)[1] == at(dark)[2]);
    assert!(
        kd.pixel(bright.0, bright.1)[0] - kd.pixel(dark.0, dark.1)[0] < 0.05
            || at(bright)[0] >= at(dark)[0]
    );

    // the same result without its maps: the global material, no images, the mesh unchanged
    std::fs::rename(&maps, d.join("moved")).unwrap();
    let plain = d.join("plain.glb");
    let run = fibrefit()
        .arg("export")
        .arg(&result)
        .arg("--gltf")
        .arg(&plain)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("the GLB carries no textures"), "{stderr}");
    let plain_bytes = std::fs::read(&plain).unwrap();
    let p = glb_json(&plain_bytes);
    for key in ["images", "textures", "samplers"] {
        assert!(p.get(key).is_none(), "{key}");
    }
    let pm = &p["materials"][0];
    let c = fitted.material.base_color;
    assert_eq!(
        pm["pbrMetallicRoughness"]["baseColorFactor"],
        serde_json::json!([c[0], c[1], c[2], 1.0])
    );
    assert_eq!(
        pm["pbrMetallicRoughness"]["roughnessFactor"].as_f64(),
        Some(fitted.material.roughness)
    );
    assert!(pm["pbrMetallicRoughness"].get("baseColorTexture").is_none());
    let tm = &raw["materials"][0];
    assert_eq!(
        pm["extensions"]["KHR_materials_anisotropy"]["anisotropyRotation"],
        tm["extensions"]["KHR_materials_anisotropy"]["anisotropyRotation"]
    );
    assert_eq!(
        pm["extensions"]["KHR_materials_ior"],
        tm["extensions"]["KHR_materials_ior"]
    );
    // the mesh's accessors and the buffer up to the images are the same bytes
    for key in ["accessors", "meshes", "nodes"] {
        assert_eq!(p[key], raw[key], "{key}");
    }
    let views = p["bufferViews"].as_array().unwrap();
    assert_eq!(
        raw["bufferViews"].as_array().unwrap()[..views.len()],
        views[..]
    );
    let (pg, tg) = (gltf::Gltf::from_slice(&plain_bytes).unwrap(), g);
    let mesh_len = p["buffers"][0]["byteLength"].as_u64().unwrap() as usize;
    assert_eq!(
        pg.blob.as_ref().unwrap()[..mesh_len],
        tg.blob.as_ref().unwrap()[..mesh_len]
    );
}

#[test]
fn the_texel_base_colour_law_is_the_least_squares_base_colour() {
    // the per-texel base colour (linear in the albedos) equals the least squares solved afresh
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (_, id, params) = fibrefit::api::eval::load_params(
        &root.join("configs/silk_params.toml"),
        None,
        &fibrefit::progress::Progress::quiet(),
    )
    .unwrap();
    let model = fibrefit::model::build(id, &params).unwrap();
    let fitted = gltf_material::fit(model.as_ref(), &params.albedos, 1).unwrap();
    let table = TexelMaterials::new(model.as_ref(), &params.albedos, &fitted, None, 1).unwrap();
    assert!(table.nodes().is_empty());
    let same = table.at(None, &params.albedos);
    for c in 0..3 {
        assert!((same.base_color[c] - fitted.material.base_color[c]).abs() < 1e-9);
    }
    assert_eq!(same.roughness, fitted.material.roughness);
    let mut other = params.albedos;
    other.diffuse = [0.2, 0.5, 0.7];
    other.specular = [0.1, 0.1, 0.1];
    let law = table.at(None, &other).base_color;
    let direct = gltf_material::base_color(model.as_ref(), &other, &fitted.material, 1);
    for c in 0..3 {
        assert!((law[c] - direct[c]).abs() < 1e-9, "{law:?} {direct:?}");
    }
}
