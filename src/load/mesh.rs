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
    let name = path.display().to_string();
    let input = super::input::open(path, super::input::MAX_INPUT_BYTES)?;
    let mut lines = ObjLines {
        reader: std::io::BufReader::with_capacity(1 << 16, input),
        path,
        name: &name,
        line_no: 0,
        raw: Vec::new(),
        logical: String::new(),
    };
    let mut obj = ObjStatements::default();
    while let Some(line) = lines.next_line()? {
        let at = At {
            name: &name,
            line: lines.line_no,
        };
        obj.statement(&line, at)?;
    }
    lines.reader.into_inner().finish()?;
    obj.check_references(&name)?;
    obj.into_mesh(path)
}

/// Where an error is: the file's name and the line (the last of a continued line).
#[derive(Clone, Copy)]
struct At<'a> {
    name: &'a str,
    line: u64,
}

impl At<'_> {
    /// `what`, prefixed with the file and line.
    fn err(self, what: String) -> anyhow::Error {
        anyhow!("{}:{}: {what}", self.name, self.line)
    }
}

/// The logical lines of an OBJ file: physical lines of at most [`MAX_OBJ_LINE`] bytes, joined
/// where a trailing backslash continues them.
struct ObjLines<'a> {
    reader: std::io::BufReader<super::input::Input>,
    path: &'a Path,
    name: &'a str,
    /// The physical lines read so far.
    line_no: u64,
    raw: Vec<u8>,
    logical: String,
}

impl ObjLines<'_> {
    /// The next logical line, or `None` at the end of the file (a continuation that the file
    /// ends in is dropped).
    fn next_line(&mut self) -> Result<Option<String>> {
        use std::io::BufRead;
        let name = self.name;
        loop {
            self.raw.clear();
            let n = (&mut self.reader)
                .take(MAX_OBJ_LINE as u64 + 1)
                .read_until(b'\n', &mut self.raw)
                .map_err(|e| super::input::io_error(self.path, e))?;
            if n == 0 {
                return Ok(None);
            }
            self.line_no += 1;
            let line_no = self.line_no;
            if self.raw.len() > MAX_OBJ_LINE {
                bail!(
                    "{name}:{line_no}: a line longer than {} (the longest an OBJ line may be)",
                    super::input::bytes_text(MAX_OBJ_LINE as u64)
                );
            }
            let text = String::from_utf8_lossy(&self.raw);
            let text = text.trim_end_matches(['\n', '\r']);
            // a trailing backslash continues the line
            if let Some(head) = text.strip_suffix('\\') {
                self.logical.push_str(head);
                self.logical.push(' ');
                if self.logical.len() > MAX_OBJ_LINE {
                    bail!(
                        "{name}:{line_no}: a continued line longer than {} bytes",
                        MAX_OBJ_LINE
                    );
                }
                continue;
            }
            self.logical.push_str(text);
            return Ok(Some(std::mem::take(&mut self.logical)));
        }
    }
}

/// What the statements of an OBJ file have given so far.
#[derive(Default)]
struct ObjStatements {
    positions: Vec<Vec3>,
    texcoords: Vec<[f64; 2]>,
    triangles: Vec<[usize; 3]>,
    /// The texture index of each triangle's corners, three per triangle.
    corner_uv: Vec<Option<usize>>,
    // the largest positive vertex and texture indices, and their lines (forward references are
    // resolved at the end, as other readers do)
    max_v: (usize, u64),
    max_t: (usize, u64),
    any_uv: bool,
    /// Triangles left out for a repeated vertex.
    repeated: usize,
    /// The current face's corners (vertex, texture), kept to reuse its allocation.
    corners: Vec<(usize, Option<usize>)>,
}

impl ObjStatements {
    /// Read one logical line: `v`, `vt` and `f` are kept, other statements ignored, anything
    /// that is not an OBJ statement refused.
    fn statement(&mut self, line: &str, at: At) -> Result<()> {
        let body = line.split('#').next().unwrap_or("");
        let mut tok = body.split_ascii_whitespace();
        let Some(key) = tok.next() else {
            return Ok(());
        };
        // OBJ statements are lower-case words (v, vt, f, usemtl, c_interp, ...): anything else
        // is not an OBJ file (a binary file or a device is refused at its first line)
        if !key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
            let shown: String = key.chars().take(20).collect();
            return Err(at.err(format!(
                "'{shown}' is not an OBJ statement (expected v, vt, vn, f, o, g, ...)"
            )));
        }
        match key {
            "v" => self.vertex(tok, at),
            "vt" => self.texcoord(tok, at),
            "f" => self.face(tok, at),
            _ => Ok(()), // vn, l, p, o, g, s, usemtl, mtllib, curves: not needed
        }
    }

    /// A `v` line: x, y and z as finite 32-bit floats.
    fn vertex<'t>(&mut self, mut tok: impl Iterator<Item = &'t str>, at: At) -> Result<()> {
        let mut c = [0.0f64; 3];
        for (k, x) in c.iter_mut().enumerate() {
            let t = tok.next().ok_or_else(|| {
                at.err(format!(
                    "a vertex needs x, y and z; coordinate {} is missing",
                    k + 1
                ))
            })?;
            let v: f32 = t
                .parse()
                .map_err(|_| at.err(format!("vertex coordinate '{t}' is not a number")))?;
            if !v.is_finite() {
                return Err(at.err(format!(
                    "vertex coordinate '{t}' is not finite (as a 32-bit float)"
                )));
            }
            *x = v as f64;
        }
        if self.positions.len() >= MAX_MESH_VERTICES {
            return Err(at.err(format!(
                "more than {MAX_MESH_VERTICES} vertices, the most a mesh may have"
            )));
        }
        self.positions.push(Vec3::new(c[0], c[1], c[2]));
        Ok(())
    }

    /// A `vt` line: u and an optional v as finite 32-bit floats.
    fn texcoord<'t>(&mut self, mut tok: impl Iterator<Item = &'t str>, at: At) -> Result<()> {
        let mut c = [0.0f64; 2];
        for (k, x) in c.iter_mut().enumerate() {
            match tok.next() {
                Some(t) => {
                    let v: f32 = t
                        .parse()
                        .map_err(|_| at.err(format!("texture coordinate '{t}' is not a number")))?;
                    if !v.is_finite() {
                        return Err(at.err(format!("texture coordinate '{t}' is not finite")));
                    }
                    *x = v as f64;
                }
                None if k == 0 => return Err(at.err("a texture coordinate needs u (and v)".into())),
                None => {}
            }
        }
        if self.texcoords.len() >= MAX_MESH_VERTICES {
            return Err(at.err(format!("more than {MAX_MESH_VERTICES} texture coordinates")));
        }
        self.texcoords.push(c);
        Ok(())
    }

    /// An `f` line: its corners, triangulated by [`polygon_triangles`]; triangles with a
    /// repeated vertex are counted and left out.
    fn face<'t>(&mut self, tok: impl Iterator<Item = &'t str>, at: At) -> Result<()> {
        self.corners.clear();
        for t in tok {
            let mut parts = t.split('/');
            let v = corner_index(parts.next(), self.positions.len(), "vertex", t, at)?
                .ok_or_else(|| at.err(format!("face corner '{t}' has no vertex index")))?;
            let uv = corner_index(parts.next(), self.texcoords.len(), "texture", t, at)?;
            if v >= self.max_v.0 {
                self.max_v = (v, at.line);
            }
            if let Some(u) = uv {
                if u >= self.max_t.0 {
                    self.max_t = (u, at.line);
                }
            }
            self.corners.push((v, uv));
        }
        let corners = &self.corners;
        if corners.len() < 3 {
            return Err(at.err(format!(
                "a face needs at least 3 vertices, this one has {}",
                corners.len()
            )));
        }
        if self.triangles.len() + corners.len() - 2 > MAX_MESH_TRIANGLES {
            return Err(at.err(format!(
                "more than {MAX_MESH_TRIANGLES} triangles, the most a mesh may have"
            )));
        }
        for c in polygon_triangles(corners.len()) {
            let c = c.map(|k| corners[k]);
            let tri = c.map(|x| x.0);
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                self.repeated += 1;
                continue;
            }
            self.triangles.push(tri);
            for x in c {
                self.any_uv |= x.1.is_some();
                self.corner_uv.push(x.1);
            }
        }
        Ok(())
    }

    /// Refuse faces that referred to vertices or texture coordinates the file never gave
    /// (forward references are allowed until the end).
    fn check_references(&self, name: &str) -> Result<()> {
        let n = self.positions.len();
        let (max_v, max_t) = (self.max_v, self.max_t);
        if !self.triangles.is_empty() && max_v.0 >= n {
            bail!(
                "{name}:{}: a face refers to vertex {} but the file has {n}",
                max_v.1,
                max_v.0 + 1
            );
        }
        if self.any_uv && max_t.0 >= self.texcoords.len() {
            bail!(
                "{name}:{}: a face refers to texture coordinate {} but the file has {}",
                max_t.1,
                max_t.0 + 1,
                self.texcoords.len()
            );
        }
        Ok(())
    }

    /// The mesh: zero-area triangles left out, texture coordinates per vertex; refused when no
    /// triangle is left.
    fn into_mesh(mut self, path: &Path) -> Result<Mesh> {
        let name = path.display();
        let n = self.positions.len();
        let (kept, kept_uv, zero_area) = self.without_zero_area();
        let uvs = if self.any_uv {
            per_vertex_uvs(n, &kept, &kept_uv, &self.texcoords)
        } else {
            None
        };
        let m = Mesh {
            positions: self.positions,
            triangles: kept,
            uvs,
            source: path.to_path_buf(),
            degenerate: self.repeated + zero_area,
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

    /// The triangles of nonzero area with their corners' texture indices, and how many had
    /// zero area; the full list is dropped.
    fn without_zero_area(&mut self) -> (Vec<[usize; 3]>, Vec<Option<usize>>, usize) {
        // zero-area triangles (collinear or coincident corners) have no normal: left out
        let triangles = std::mem::take(&mut self.triangles);
        let mut zero_area = 0usize;
        let mut kept_uv = Vec::with_capacity(self.corner_uv.len());
        let mut kept = Vec::with_capacity(triangles.len());
        for (k, t) in triangles.iter().enumerate() {
            let p = t.map(|i| self.positions[i]);
            let area = (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
            if !(area > 0.0 && area.is_finite()) {
                zero_area += 1;
                continue;
            }
            kept.push(*t);
            kept_uv.extend_from_slice(&self.corner_uv[3 * k..3 * k + 3]);
        }
        drop(triangles);
        (kept, kept_uv, zero_area)
    }
}

/// A face corner's vertex or texture index (`what`) from its text `s` in corner `t`: 1-based,
/// or negative counting back from the `count` so far; `None` when absent or empty.
fn corner_index(
    s: Option<&str>,
    count: usize,
    what: &str,
    t: &str,
    at: At,
) -> Result<Option<usize>> {
    let Some(s) = s.filter(|s| !s.is_empty()) else {
        return Ok(None);
    };
    let i: i64 = s.parse().map_err(|_| {
        at.err(format!(
            "face corner '{t}': {what} index '{s}' is not an integer"
        ))
    })?;
    match i {
        0 => Err(at.err(format!(
            "face corner '{t}': {what} index 0 (OBJ indices start at 1)"
        ))),
        i if i > 0 => Ok(Some(i as usize - 1)),
        i => {
            let back = i.unsigned_abs();
            if back > count as u64 {
                Err(at.err(format!(
                    "face corner '{t}': {what} index {i} reaches before the first of the {count} so far"
                )))
            } else {
                Ok(Some(count - back as usize))
            }
        }
    }
}

/// Texture coordinates per vertex from the kept triangles' corners (the last corner naming a
/// vertex wins), or `None` unless every vertex a triangle uses has one.
fn per_vertex_uvs(
    n: usize,
    kept: &[[usize; 3]],
    kept_uv: &[Option<usize>],
    texcoords: &[[f64; 2]],
) -> Option<Vec<[f64; 2]>> {
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
