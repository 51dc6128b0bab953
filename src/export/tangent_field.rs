//! A mesh's curvature-aligned tangent field (`fibrefit tangents`) as files: CSV (one row per
//! vertex in the file's order) or GLB (the mesh with NORMAL, TANGENT and _UMBILIC).

use super::atomic::{OutputId, Outputs};
use super::gltf_out::{self, VertexFrames};
use crate::load::mesh::Mesh;
use crate::render::curvature::VertexCurvature;
use anyhow::Result;
use std::io::Write;

/// Write the field of `mesh` (`curv` per vertex) into the reserved output `id`: GLB when `glb`,
/// else CSV.
pub fn write(
    outs: &mut Outputs,
    id: OutputId,
    mesh: &Mesh,
    curv: &[VertexCurvature],
    glb: bool,
) -> Result<()> {
    if glb {
        let normals: Vec<_> = curv.iter().map(|c| c.normal).collect();
        let tangents: Vec<_> = curv.iter().map(|c| c.k1_direction).collect();
        let bitangents: Vec<_> = curv.iter().map(|c| c.k2_direction).collect();
        let undefined: Vec<bool> = curv.iter().map(|c| c.umbilic).collect();
        let mut w = std::io::BufWriter::new(outs.writer(id));
        gltf_out::write_glb(
            &mut w,
            &mesh,
            &VertexFrames {
                normals: &normals,
                tangents: &tangents,
                bitangents: &bitangents,
                undefined: &undefined,
            },
            None,
            &format!("fibrefit {} tangents", env!("CARGO_PKG_VERSION")),
        )?;
        w.flush()?;
    } else {
        let mut w = csv::Writer::from_writer(outs.writer(id));
        w.write_record([
            "x", "y", "z", "nx", "ny", "nz", "k1x", "k1y", "k1z", "k2x", "k2y", "k2z", "k1", "k2",
        ])?;
        for (p, c) in mesh.positions.iter().zip(curv) {
            let dir = |d: &crate::model::frame::Vec3| {
                if c.umbilic {
                    [f64::NAN; 3]
                } else {
                    [d.x, d.y, d.z]
                }
            };
            let (d1, d2) = (dir(&c.k1_direction), dir(&c.k2_direction));
            let row = [
                p.x, p.y, p.z, c.normal.x, c.normal.y, c.normal.z, d1[0], d1[1], d1[2], d2[0],
                d2[1], d2[2], c.k1, c.k2,
            ];
            w.write_record(row.iter().map(|v| v.to_string()))?;
        }
        w.flush()?;
    }
    Ok(())
}
