//! How precise the GPU driver's built-in asin, atan2, acos, cos, sin, exp2 and log2 are (why the
//! exported shader writes asin, acos, atan2 and ln out itself): each evaluated by the machine's
//! Vulkan driver over 200 000 arguments and compared with f64.
//!
//! `cargo run --release --example driver_precision`
use fibrefit::export::shader::gpu::{Case, Gpu};

/// A stand-in "library" whose entry points return the built-ins of the case's inputs.
const LIB: &str = "
fn fibrefit_brdf(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec3<f32> { return vec3<f32>(asin(l.x), atan2(l.y, l.z), acos(l.x)); }
fn fibrefit_basis(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>) -> vec4<f32> { return vec4<f32>(cos(v.x), sin(v.x), exp2(v.y), log2(v.z)); }
fn fibrefit_brdf_at(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, h: f32, o: f32) -> vec3<f32> { return fibrefit_brdf(l, v, n, t); }
fn fibrefit_basis_at(l: vec3<f32>, v: vec3<f32>, n: vec3<f32>, t: vec3<f32>, h: f32, o: f32) -> vec4<f32> { return fibrefit_basis(l, v, n, t); }
";

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new()?;
    println!("{}", gpu.adapter);
    let n = 200_000;
    let cases: Vec<Case> = (0..n)
        .map(|i| {
            let u = (i as f64 + 0.5) / n as f64;
            Case {
                // asin/acos over [-1, 1], atan2 round the circle
                l: [
                    (2.0 * u - 1.0) as f32,
                    (u * 7.0).sin() as f32,
                    (u * 7.0).cos() as f32,
                ],
                // cos/sin over [-3, 3], exp2 over [-20, 0], log2 over [1e-4, 1]
                v: [
                    ((u - 0.5) * 6.0) as f32,
                    (-20.0 + 20.0 * u) as f32,
                    (1e-4 + u) as f32,
                ],
                n: [0.0; 3],
                t: [0.0; 3],
                at: None,
            }
        })
        .collect();
    let out = gpu.evaluate(LIB, &cases)?;
    let names = [
        "asin (absolute)",
        "atan2 (absolute)",
        "acos (absolute)",
        "cos (absolute)",
        "sin (absolute)",
        "exp2 (relative)",
        "log2 (absolute)",
    ];
    let mut worst = [0.0f64; 7];
    for (c, o) in cases.iter().zip(&out) {
        let x = c.l[0] as f64;
        let want = [
            x.asin(),
            (c.l[1] as f64).atan2(c.l[2] as f64),
            x.acos(),
            (c.v[0] as f64).cos(),
            (c.v[0] as f64).sin(),
            (c.v[1] as f64).exp2(),
            (c.v[2] as f64).log2(),
        ];
        let got = [
            o.brdf[0], o.brdf[1], o.brdf[2], o.basis[0], o.basis[1], o.basis[2], o.basis[3],
        ];
        for (k, ((w, g), x)) in worst.iter_mut().zip(got).zip(want).enumerate() {
            let e = (g as f64 - x).abs() / if k == 5 { x } else { 1.0 };
            *w = w.max(e);
        }
    }
    for (name, w) in names.iter().zip(worst) {
        println!("{name:<18} worst error {w:.2e}");
    }
    Ok(())
}
