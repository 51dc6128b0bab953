//! `fibrefit tangents MESH.obj --out T.csv|T.glb`: the principal-curvature-aligned tangent field.

use crate::export::atomic::Outputs;
use crate::load::mesh;
use crate::render::curvature::{self, UMBILIC_TOLERANCE};
use anyhow::{bail, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
Per vertex: the normal (angle-weighted face normals) and the principal curvature directions
and magnitudes from a quadric z = a x^2 + b xy + c y^2 + d x + e y fitted to the vertex's
k-ring in its tangent frame (libigl's method). k1 >= k2; curvatures in 1 / (the mesh's length
unit), positive where the surface bends away from its normal (a sphere with outward normals:
k1 = k2 = 1/r). Directions have no sign; a renderer flips each triangle's corners to agree with
its first corner before interpolating. Umbilic vertices (|k1 - k2| <= 5 % of the larger, or a
flat region) have no principal direction: CSV writes NaN for their directions, GLB marks them
in the vertex attribute _UMBILIC (1.0) and gives them a tangent perpendicular to the normal
only so that the file is valid.
CSV: one row per vertex in file order, header x,y,z,nx,ny,nz,k1x,k1y,k1z,k2x,k2y,k2z,k1,k2.
GLB: the mesh with NORMAL and TANGENT (k1's direction; w = +-1 so that N x T . w = k2's
direction), TEXCOORD_0 when the OBJ has texture coordinates: any glTF viewer can show
KHR_materials_anisotropy along it.")]
pub struct TangentsArgs {
    /// Triangle mesh (Wavefront OBJ; polygons of up to 8 corners become fans, larger ones strips;
    /// degenerate triangles are left out and counted)
    pub mesh: PathBuf,
    /// Output: .csv (per vertex) or .glb (the mesh with NORMAL and TANGENT)
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Rings of neighbours each vertex's quadric is fitted to
    #[arg(long, value_name = "K", default_value_t = 2)]
    pub rings: usize,
    /// No summary on stderr
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &TangentsArgs) -> Result<()> {
    let ext = args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let glb = match ext.as_deref() {
        Some("csv") => false,
        Some("glb") => true,
        _ => bail!(
            "--out {}: expected a .csv or .glb file name",
            args.out.display()
        ),
    };
    if !(1..=8).contains(&args.rings) {
        bail!("--rings {}: expected 1 to 8", args.rings);
    }
    // the output checked before the work; never the mesh it reads
    let mut outs = Outputs::new(std::slice::from_ref(&args.mesh));
    let id = outs.file(&args.out, "--out")?;
    let mesh = mesh::load_obj(&args.mesh)?;
    if mesh.degenerate > 0 && !args.quiet {
        eprintln!(
            "warning: {}: {} degenerate triangles (a repeated vertex or zero area) left out",
            args.mesh.display(),
            mesh.degenerate
        );
    }
    let curv = curvature::principal_curvatures(&mesh, args.rings);
    let umbilic = curv.iter().filter(|c| c.umbilic).count();
    crate::export::tangent_field::write(&mut outs, id, &mesh, &curv, glb)?;
    outs.commit()?;
    if !args.quiet {
        eprintln!(
            "wrote {} ({} vertices, {} triangles; {umbilic} umbilic: |k1 - k2| <= {:.0} % of the larger or flat, no direction)",
            args.out.display(),
            mesh.positions.len(),
            mesh.triangles.len(),
            100.0 * UMBILIC_TOLERANCE
        );
    }
    Ok(())
}
