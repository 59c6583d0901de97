//! The building model: vertices, planar faces, and the model segments the tracker matches.
//!
//! In: a Wavefront OBJ (docs/interfaces.md, "Building model": `v`, `f`, `l`; `o`/`g`/`usemtl`
//! kept as labels; metres, z up). Out: a [`Model`] whose [`Segment`]s are the boundaries of its surfaces — the lines
//! where the surface is not flat (creases, corners, free borders) — plus the free `l` segments.
//! A triangulation diagonal or a seam between coplanar faces is not a segment; collinear pieces
//! of one straight boundary are one segment; an edge shared by several faces appears once and
//! lists them all.
//!
//! Also the geometry every layer above casts rays into: [`bvh`] (a bounding-volume hierarchy
//! over triangles) and [`triangulate`] (faces into triangles).

pub mod bvh;
mod obj;
mod segments;
pub mod triangulate;

use nalgebra::{Point3, Unit, Vector3};
use std::path::Path;

pub use segments::SegmentTolerances;

/// A planar polygon of the model, opaque from both sides.
#[derive(Debug, Clone, PartialEq)]
pub struct Face {
    /// Indices into [`Model::vertices`], counter-clockwise about `normal`.
    pub vertices: Vec<u32>,
    pub normal: Unit<Vector3<f64>>,
    /// `normal · p` for every point p of the face's plane.
    pub offset: f64,
    /// 1-based number of the `f` record in file order (degenerate records keep their number, so
    /// these match the file even when some are skipped). A non-planar record split into
    /// triangles gives several faces with one number.
    pub obj_number: u32,
    /// Indices into [`Model::labels`] of the `o`, `g` and `usemtl` names in force (0 = none).
    pub object: u32,
    pub group: u32,
    pub material: u32,
}

/// A straight 3D line of the model that an image edge can be matched to.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    pub a: Point3<f64>,
    pub b: Point3<f64>,
    /// Indices into [`Model::faces`] of the faces this segment bounds; empty for a free segment
    /// (an `l` record), which can be matched but occludes nothing.
    pub faces: Vec<u32>,
}

impl Segment {
    pub fn length(&self) -> f64 {
        (self.b - self.a).norm()
    }
    pub fn direction(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(self.b - self.a)
    }
    pub fn is_free(&self) -> bool {
        self.faces.is_empty()
    }
}

/// What loading skipped or repaired, so that nothing is dropped silently.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ModelStats {
    /// `f` records with fewer than three distinct vertices or no area: skipped.
    pub degenerate_faces: usize,
    /// `f` records whose vertices are not in one plane: split into a triangle fan.
    pub nonplanar_faces: usize,
    /// `v` records merged into an earlier vertex at the same position.
    pub welded_vertices: usize,
    /// Records other than v/f/l/o/g/usemtl (vn, vt, s, mtllib, …): ignored.
    pub ignored_records: usize,
    /// `l` edges of zero length: skipped.
    pub degenerate_lines: usize,
}

/// A loaded, segmented building model.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    pub vertices: Vec<Point3<f64>>,
    pub faces: Vec<Face>,
    pub segments: Vec<Segment>,
    /// Names from `o`, `g` and `usemtl`; index 0 is the empty name.
    pub labels: Vec<String>,
    pub stats: ModelStats,
}

/// A model file that cannot be used: `file:line: what is wrong`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct ModelError {
    pub file: String,
    pub line: Option<usize>,
    pub message: String,
}

impl Model {
    /// Reads an OBJ file and extracts its segments with the default tolerances.
    pub fn load(path: &Path) -> Result<Model, ModelError> {
        let file = path.display().to_string();
        let text = crate::text_file::read_text(path, crate::text_file::LARGE_FILE_LIMIT).map_err(|e| ModelError {
            file: file.clone(),
            line: None,
            message: format!("cannot read model: {e}"),
        })?;
        Model::from_obj_str(&text, &file)
    }

    /// Parses OBJ text; `file` names it in error messages.
    pub fn from_obj_str(text: &str, file: &str) -> Result<Model, ModelError> {
        Model::from_obj_str_with(text, file, &SegmentTolerances::default())
    }

    pub fn from_obj_str_with(text: &str, file: &str, tol: &SegmentTolerances) -> Result<Model, ModelError> {
        let parsed = obj::parse(text, file)?;
        let mut stats = parsed.stats;
        let (vertices, remap) = segments::weld(&parsed.vertices, tol.weld_m);
        stats.welded_vertices = parsed.vertices.len() - vertices.len();
        let mut faces = Vec::with_capacity(parsed.faces.len());
        for raw in &parsed.faces {
            let idx: Vec<u32> = raw.vertices.iter().map(|&i| remap[i as usize]).collect();
            match segments::make_faces(&vertices, &idx, tol) {
                segments::FaceShape::Degenerate => stats.degenerate_faces += 1,
                segments::FaceShape::Planar(f) => faces.push(raw.label(f)),
                segments::FaceShape::Split(fs) => {
                    stats.nonplanar_faces += 1;
                    faces.extend(fs.into_iter().map(|f| raw.label(f)));
                }
            }
        }
        let mut free_edges = Vec::new();
        for l in &parsed.lines {
            for w in l.windows(2) {
                let (a, b) = (remap[w[0] as usize], remap[w[1] as usize]);
                if a == b {
                    stats.degenerate_lines += 1;
                } else {
                    free_edges.push([a, b]);
                }
            }
        }
        let segments = segments::extract(&vertices, &faces, &free_edges, tol);
        Ok(Model {
            vertices,
            faces,
            segments,
            labels: parsed.labels,
            stats,
        })
    }

    /// Axis-aligned bounds of the vertices, or `None` for an empty model.
    pub fn bounds(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        let first = *self.vertices.first()?;
        Some(
            self.vertices
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
        )
    }

    /// The `o`/`g`/`usemtl` name with this index (empty for 0).
    pub fn label(&self, index: u32) -> &str {
        self.labels.get(index as usize).map(String::as_str).unwrap_or("")
    }
}
