//! Triangle meshes from Wavefront OBJ files ([`load_obj`]): positions shared by the faces that
//! meet at them (the connectivity curvature needs), in the file's order, triangles, and
//! per-vertex texture coordinates where the file has them. Every object and group of the file
//! is one mesh.
//!
//! Read by our own line parser rather than a crate (tobj before): the issue that asked for it
//! (26) needs errors naming the line, vertices in the file's order (tobj renumbers them by
//! first use in the faces) and `mtllib` files never opened, none of which tobj offers; the
//! subset of OBJ a mesh needs (`v`, `vt`, `f`) is small.

use crate::model::frame::Vec3;
use anyhow::{anyhow, bail, Result};
use std::io::Read;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[usize; 3]>,
    /// Per vertex (u, v), when every vertex a triangle uses has one.
    pub uvs: Option<Vec<[f64; 2]>>,
    pub source: PathBuf,
    /// Degenerate triangles (a repeated vertex or zero area) the file had and that were left
    /// out.
    pub degenerate: usize,
}

impl Mesh {
    /// A mesh from positions and triangles (generated surfaces, tests).
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[usize; 3]>) -> Result<Self> {
        let m = Self {
            positions,
            triangles,
            uvs: None,
            source: PathBuf::from("(generated)"),
            degenerate: 0,
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

/// The most vertices (`v` lines) and triangles a mesh may have: 2^26 each (67 million; 1.6 GB
/// of positions or triangles).
pub const MAX_MESH_VERTICES: usize = 1 << 26;
pub const MAX_MESH_TRIANGLES: usize = 1 << 26;

/// The longest line of an OBJ file: 16 MiB (a face of about two million vertices).
pub const MAX_OBJ_LINE: usize = 16 << 20;

/// Polygons of up to this many corners are triangulated as fans; larger ones as strips.
pub const FAN_CORNERS: usize = 8;

/// The triangles (corner positions, in the polygon's winding) of a polygon of `n` corners: a fan
/// from corner 0 up to [`FAN_CORNERS`]; beyond, a zigzag strip (0, 1, n-1, 2, n-2, ...), which
/// for a convex polygon is as valid and puts every corner in at most three triangles: a fan's
/// corner 0 would be in n - 2, which makes neighbourhoods (curvature) and bounding volumes
/// (rendering) of a large polygon O(n) each.
fn polygon_triangles(n: usize) -> impl Iterator<Item = [usize; 3]> {
    let fan = (n <= FAN_CORNERS).then(|| (1..n.saturating_sub(1)).map(|k| [0, k, k + 1]));
    let strip = (n > FAN_CORNERS).then(|| {
        let (mut f, mut b, mut front) = (1usize, n - 1, true);
        let mut seq = [0usize, 0, 0];
        let mut len = 1;
        std::iter::from_fn(move || {
            while f <= b {
                let next = if front {
                    f += 1;
                    f - 1
                } else {
                    b -= 1;
                    b + 1
                };
                front = !front;
                if len < 3 {
                    seq[len] = next;
                    len += 1;
                    if len < 3 {
                        continue;
                    }
                } else {
                    seq = [seq[1], seq[2], next];
                }
                // corners in increasing order keep the polygon's winding
                let mut t = seq;
                t.sort_unstable();
                return Some(t);
            }
            None
        })
    });
    fan.into_iter().flatten().chain(strip.into_iter().flatten())
}

/// Load `path`: a Wavefront OBJ read line by line (through [`super::input`]: at most
/// [`super::input::MAX_INPUT_BYTES`], hashed, checked unchanged).
///
/// - Positions are the file's `v` lines in file order (x, y, z read as 32-bit floats; extra
///   values such as colours ignored), so per-vertex outputs (`fibrefit tangents`) follow the
///   file's vertex numbering; a vertex that no face uses is kept (it has no neighbours, hence no
///   curvature).
/// - Faces (`f v`, `v/t`, `v//n`, `v/t/n`, negative indices relative to the vertices so far)
///   with n >= 3 corners become n - 2 triangles: fans up to [`FAN_CORNERS`] corners, strips
///   beyond ([`polygon_triangles`]; O(n) and no corner shared by all of them). Triangles with a
///   repeated vertex or zero area are degenerate: they are left out (so that no normal is
///   NaN) and counted in [`Mesh::degenerate`].
/// - Texture coordinates: per vertex from the faces' `vt` indices (the last face naming a vertex
///   wins), kept when every vertex a face uses has one.
/// - Normals (`vn`), points, lines, groups, objects, smoothing groups and materials are
///   ignored: `mtllib` files are never opened.
///
/// Errors name the file and line: malformed numbers, non-finite coordinates, indices of 0 or
/// beyond the vertices, faces of fewer than 3 vertices, more than [`MAX_MESH_VERTICES`] or
/// [`MAX_MESH_TRIANGLES`], lines longer than [`MAX_OBJ_LINE`].
pub fn load_obj(path: &Path) -> Result<Mesh> {
    use std::io::BufRead;
    let name = path.display().to_string();
    let input = super::input::open(path, super::input::MAX_INPUT_BYTES)?;
    let mut reader = std::io::BufReader::with_capacity(1 << 16, input);
    let mut positions: Vec<Vec3> = Vec::new();
    let mut texcoords: Vec<[f64; 2]> = Vec::new();
    let mut triangles: Vec<[usize; 3]> = Vec::new();
    let mut corner_uv: Vec<Option<usize>> = Vec::new();
    // the largest positive vertex and texture indices, and their lines (forward references are
    // resolved at the end, as other readers do)
    let mut max_v: (usize, u64) = (0, 0);
    let mut max_t: (usize, u64) = (0, 0);
    let mut any_uv = false;
    let mut repeated = 0usize;
    let mut line_no = 0u64;
    let mut raw: Vec<u8> = Vec::new();
    let mut logical = String::new();
    let mut corners: Vec<(usize, Option<usize>)> = Vec::new();
    loop {
        raw.clear();
        let n = (&mut reader)
            .take(MAX_OBJ_LINE as u64 + 1)
            .read_until(b'\n', &mut raw)
            .map_err(|e| super::input::io_error(path, e))?;
        if n == 0 {
            break;
        }
        line_no += 1;
        if raw.len() > MAX_OBJ_LINE {
            bail!(
                "{name}:{line_no}: a line longer than {} (the longest an OBJ line may be)",
                super::input::bytes_text(MAX_OBJ_LINE as u64)
            );
        }
        let text = String::from_utf8_lossy(&raw);
        let text = text.trim_end_matches(['\n', '\r']);
        // a trailing backslash continues the line
        if let Some(head) = text.strip_suffix('\\') {
            logical.push_str(head);
            logical.push(' ');
            if logical.len() > MAX_OBJ_LINE {
                bail!(
                    "{name}:{line_no}: a continued line longer than {} bytes",
                    MAX_OBJ_LINE
                );
            }
            continue;
        }
        logical.push_str(text);
        let line = std::mem::take(&mut logical);
        let body = line.split('#').next().unwrap_or("");
        let mut tok = body.split_ascii_whitespace();
        let Some(key) = tok.next() else { continue };
        let at = |what: String| anyhow!("{name}:{line_no}: {what}");
        // OBJ statements are lower-case words (v, vt, f, usemtl, c_interp, ...): anything else
        // is not an OBJ file (a binary file or a device is refused at its first line)
        if !key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
            let shown: String = key.chars().take(20).collect();
            return Err(at(format!(
                "'{shown}' is not an OBJ statement (expected v, vt, vn, f, o, g, ...)"
            )));
        }
        match key {
            "v" => {
                let mut c = [0.0f64; 3];
                for (k, x) in c.iter_mut().enumerate() {
                    let t = tok.next().ok_or_else(|| {
                        at(format!(
                            "a vertex needs x, y and z; coordinate {} is missing",
                            k + 1
                        ))
                    })?;
                    let v: f32 = t
                        .parse()
                        .map_err(|_| at(format!("vertex coordinate '{t}' is not a number")))?;
                    if !v.is_finite() {
                        return Err(at(format!(
                            "vertex coordinate '{t}' is not finite (as a 32-bit float)"
                        )));
                    }
                    *x = v as f64;
                }
                if positions.len() >= MAX_MESH_VERTICES {
                    return Err(at(format!(
                        "more than {MAX_MESH_VERTICES} vertices, the most a mesh may have"
                    )));
                }
                positions.push(Vec3::new(c[0], c[1], c[2]));
            }
            "vt" => {
                let mut c = [0.0f64; 2];
                for (k, x) in c.iter_mut().enumerate() {
                    match tok.next() {
                        Some(t) => {
                            let v: f32 = t.parse().map_err(|_| {
                                at(format!("texture coordinate '{t}' is not a number"))
                            })?;
                            if !v.is_finite() {
                                return Err(at(format!("texture coordinate '{t}' is not finite")));
                            }
                            *x = v as f64;
                        }
                        None if k == 0 => {
                            return Err(at("a texture coordinate needs u (and v)".into()))
                        }
                        None => {}
                    }
                }
                if texcoords.len() >= MAX_MESH_VERTICES {
                    return Err(at(format!(
                        "more than {MAX_MESH_VERTICES} texture coordinates"
                    )));
                }
                texcoords.push(c);
            }
            "f" => {
                corners.clear();
                for t in tok {
                    let mut parts = t.split('/');
                    let index = |s: Option<&str>,
                                 count: usize,
                                 what: &str|
                     -> Result<Option<usize>> {
                        let Some(s) = s.filter(|s| !s.is_empty()) else {
                            return Ok(None);
                        };
                        let i: i64 = s.parse().map_err(|_| {
                            at(format!(
                                "face corner '{t}': {what} index '{s}' is not an integer"
                            ))
                        })?;
                        match i {
                            0 => Err(at(format!(
                                "face corner '{t}': {what} index 0 (OBJ indices start at 1)"
                            ))),
                            i if i > 0 => Ok(Some(i as usize - 1)),
                            i => {
                                let back = i.unsigned_abs();
                                if back > count as u64 {
                                    Err(at(format!(
                                        "face corner '{t}': {what} index {i} reaches before the first of the {count} so far"
                                    )))
                                } else {
                                    Ok(Some(count - back as usize))
                                }
                            }
                        }
                    };
                    let v = index(parts.next(), positions.len(), "vertex")?
                        .ok_or_else(|| at(format!("face corner '{t}' has no vertex index")))?;
                    let uv = index(parts.next(), texcoords.len(), "texture")?;
                    if v >= max_v.0 {
                        max_v = (v, line_no);
                    }
                    if let Some(u) = uv {
                        if u >= max_t.0 {
                            max_t = (u, line_no);
                        }
                    }
                    corners.push((v, uv));
                }
                if corners.len() < 3 {
                    return Err(at(format!(
                        "a face needs at least 3 vertices, this one has {}",
                        corners.len()
                    )));
                }
                if triangles.len() + corners.len() - 2 > MAX_MESH_TRIANGLES {
                    return Err(at(format!(
                        "more than {MAX_MESH_TRIANGLES} triangles, the most a mesh may have"
                    )));
                }
                for c in polygon_triangles(corners.len()) {
                    let c = c.map(|k| corners[k]);
                    let tri = c.map(|x| x.0);
                    if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                        repeated += 1;
                        continue;
                    }
                    triangles.push(tri);
                    for x in c {
                        any_uv |= x.1.is_some();
                        corner_uv.push(x.1);
                    }
                }
            }
            _ => {} // vn, l, p, o, g, s, usemtl, mtllib, curves: not needed
        }
    }
    let input = reader.into_inner();
    input.finish()?;
    let n = positions.len();
    if !triangles.is_empty() && max_v.0 >= n {
        bail!(
            "{name}:{}: a face refers to vertex {} but the file has {n}",
            max_v.1,
            max_v.0 + 1
        );
    }
    if any_uv && max_t.0 >= texcoords.len() {
        bail!(
            "{name}:{}: a face refers to texture coordinate {} but the file has {}",
            max_t.1,
            max_t.0 + 1,
            texcoords.len()
        );
    }
    // zero-area triangles (collinear or coincident corners) have no normal: left out
    let mut zero_area = 0usize;
    let mut kept_uv = Vec::with_capacity(corner_uv.len());
    let mut kept = Vec::with_capacity(triangles.len());
    for (k, t) in triangles.iter().enumerate() {
        let p = t.map(|i| positions[i]);
        let area = (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
        if !(area > 0.0 && area.is_finite()) {
            zero_area += 1;
            continue;
        }
        kept.push(*t);
        kept_uv.extend_from_slice(&corner_uv[3 * k..3 * k + 3]);
    }
    drop(triangles);
    let uvs = if any_uv {
        let mut uv: Vec<Option<[f64; 2]>> = vec![None; n];
        for (t, c) in kept.iter().zip(kept_uv.chunks_exact(3)) {
            for k in 0..3 {
                if let Some(i) = c[k] {
                    uv[t[k]] = Some(texcoords[i]);
                }
            }
        }
        let mut used = vec![false; n];
        kept.iter().flatten().for_each(|&i| used[i] = true);
        (0..n)
            .all(|i| !used[i] || uv[i].is_some())
            .then(|| uv.into_iter().map(|x| x.unwrap_or([0.0, 0.0])).collect())
    } else {
        None
    };
    let m = Mesh {
        positions,
        triangles: kept,
        uvs,
        source: path.to_path_buf(),
        degenerate: repeated + zero_area,
    };
    if m.triangles.is_empty() && m.degenerate > 0 {
        bail!(
            "{name}: no triangles: all {} are degenerate (a repeated vertex or zero area)",
            m.degenerate
        );
    }
    m.check()?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygons_become_fans_then_strips_in_their_winding() {
        let t: Vec<_> = polygon_triangles(4).collect();
        assert_eq!(t, [[0, 1, 2], [0, 2, 3]]);
        let t: Vec<_> = polygon_triangles(3).collect();
        assert_eq!(t, [[0, 1, 2]]);
        for n in [9usize, 10, 11, 1000] {
            let t: Vec<_> = polygon_triangles(n).collect();
            assert_eq!(t.len(), n - 2, "{n}");
            // a triangulation of the convex n-gon: every triangle sorted, every corner in at most
            // 3, edges of the polygon used once, diagonals twice
            let mut uses = vec![0; n];
            let mut edges = std::collections::HashMap::new();
            for tri in &t {
                assert!(tri[0] < tri[1] && tri[1] < tri[2], "{tri:?}");
                for c in tri {
                    uses[*c] += 1;
                }
                for (a, b) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[0], tri[2])] {
                    *edges.entry((a, b)).or_insert(0) += 1;
                }
            }
            assert!(uses.iter().all(|&u| (1..=3).contains(&u)), "{n}: {uses:?}");
            for ((a, b), k) in edges {
                let boundary = b == a + 1 || (a == 0 && b == n - 1);
                assert_eq!(k, if boundary { 1 } else { 2 }, "{n}: edge {a}-{b}");
            }
        }
    }
}
