//! Triangle meshes from Wavefront OBJ files (read by the `tobj` crate): positions shared by the
//! faces that meet at them (the connectivity curvature needs), triangles, and per-vertex
//! texture coordinates where the file has them. Every object and group of the file is one mesh.

use crate::model::frame::Vec3;
use anyhow::{anyhow, bail, Result};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[usize; 3]>,
    /// Per vertex (u, v), when every vertex has one.
    pub uvs: Option<Vec<[f64; 2]>>,
    pub source: PathBuf,
}

impl Mesh {
    /// A mesh from positions and triangles (generated surfaces, tests).
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[usize; 3]>) -> Result<Self> {
        let m = Self {
            positions,
            triangles,
            uvs: None,
            source: PathBuf::from("(generated)"),
        };
        m.check()?;
        Ok(m)
    }

    fn check(&self) -> Result<()> {
        let name = self.source.display();
        if self.triangles.is_empty() {
            bail!("{name}: no triangles");
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|p| !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()))
        {
            bail!("{name}: vertex {} has a non-finite coordinate", i + 1);
        }
        let n = self.positions.len();
        if let Some(f) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| i >= n))
        {
            bail!(
                "{name}: face {} refers to a vertex beyond the {n} the file has",
                f + 1
            );
        }
        Ok(())
    }
}

/// Load `path` (triangulating polygons as fans).
pub fn load_obj(path: &Path) -> Result<Mesh> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) = tobj::load_obj(path, &opts)
        .map_err(|e| anyhow!("{}: cannot read as an OBJ mesh: {e}", path.display()))?;
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut uvs: Vec<Option<[f64; 2]>> = Vec::new();
    for m in &models {
        let mesh = &m.mesh;
        let base = positions.len();
        positions.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
        );
        uvs.resize(positions.len(), None);
        for (k, tri) in mesh.indices.chunks_exact(3).enumerate() {
            triangles.push([
                base + tri[0] as usize,
                base + tri[1] as usize,
                base + tri[2] as usize,
            ]);
            if !mesh.texcoord_indices.is_empty() {
                for c in 0..3 {
                    let t = mesh.texcoord_indices[3 * k + c] as usize;
                    if let Some(uv) = mesh.texcoords.get(2 * t..2 * t + 2) {
                        uvs[base + tri[c] as usize] = Some([uv[0] as f64, uv[1] as f64]);
                    }
                }
            } else if mesh.texcoords.len() == mesh.positions.len() / 3 * 2 {
                for &t in tri {
                    let i = t as usize;
                    uvs[base + i] = Some([
                        mesh.texcoords[2 * i] as f64,
                        mesh.texcoords[2 * i + 1] as f64,
                    ]);
                }
            }
        }
    }
    let uvs = uvs
        .iter()
        .all(Option::is_some)
        .then(|| uvs.iter().flatten().copied().collect());
    let m = Mesh {
        positions,
        triangles,
        uvs,
        source: path.to_path_buf(),
    };
    m.check()?;
    Ok(m)
}
