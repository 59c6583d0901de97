//! Wavefront OBJ writing: planar polygons in (metres, each with the side a camera sees), OBJ text
//! out: shared vertices, faces wound counter-clockwise about their visible side, each under the
//! `g` and `usemtl` given last.

use nalgebra::{Point2, Point3, Vector2, Vector3};
use std::collections::HashMap;
use std::fmt::Write as _;

/// Output coordinates are rounded to 1 nm so that vertices computed along different paths (a
/// mitre point seen from both of its pieces) print identically and decimal inputs print as typed.
const GRID_PER_M: f64 = 1e9;

pub(super) struct ObjWriter {
    /// Grid keys (see [`GRID_PER_M`]) in order of first use.
    pub vertices: Vec<[i64; 3]>,
    index: HashMap<[i64; 3], usize>,
    body: String,
    group: String,
    material: String,
    pub faces: usize,
    /// Faces dropped for having no area.
    pub degenerate: usize,
}

impl ObjWriter {
    pub fn new() -> Self {
        Self {
            vertices: Vec::new(),
            index: HashMap::new(),
            body: String::new(),
            group: String::new(),
            material: String::new(),
            faces: 0,
            degenerate: 0,
        }
    }

    pub fn label(&mut self, group: &str, material: &str) {
        if self.group != group {
            let _ = writeln!(self.body, "g {group}");
            self.group = group.to_string();
        }
        if self.material != material {
            let _ = writeln!(self.body, "usemtl {material}");
            self.material = material.to_string();
        }
    }

    /// A planar polygon, wound counter-clockwise about `visible` (the side a camera sees; the
    /// model is two-sided, but renderers and humans reading the file like a consistent winding).
    fn face(&mut self, points: &[Point3<f64>], visible: Vector3<f64>) {
        let mut keys: Vec<[i64; 3]> = points
            .iter()
            .map(|p| [p.x, p.y, p.z].map(|c| (c * GRID_PER_M).round() as i64))
            .collect();
        keys.dedup();
        while keys.len() > 1 && keys.first() == keys.last() {
            keys.pop();
        }
        let mut newell = Vector3::zeros();
        for k in 0..keys.len() {
            let (a, b) = (keys[k].map(|c| c as f64), keys[(k + 1) % keys.len()].map(|c| c as f64));
            newell += Vector3::new(
                (a[1] - b[1]) * (a[2] + b[2]),
                (a[2] - b[2]) * (a[0] + b[0]),
                (a[0] - b[0]) * (a[1] + b[1]),
            );
        }
        // Validation upstream leaves no degenerate face; this only keeps a slip out of the file.
        if keys.len() < 3 || newell.norm() == 0.0 {
            self.degenerate += 1;
            return;
        }
        if newell.dot(&visible) < 0.0 {
            keys.reverse();
        }
        self.body.push('f');
        for key in keys {
            let next = self.vertices.len();
            let i = *self.index.entry(key).or_insert(next);
            if i == next {
                self.vertices.push(key);
            }
            let _ = write!(self.body, " {}", i + 1);
        }
        self.body.push('\n');
        self.faces += 1;
    }

    pub fn vertical(&mut self, a: Point2<f64>, b: Point2<f64>, z0: f64, z1: f64, visible: Vector2<f64>) {
        let pts = [
            Point3::new(a.x, a.y, z0),
            Point3::new(b.x, b.y, z0),
            Point3::new(b.x, b.y, z1),
            Point3::new(a.x, a.y, z1),
        ];
        self.face(&pts, Vector3::new(visible.x, visible.y, 0.0));
    }

    pub fn horizontal(&mut self, ring: &[Point2<f64>], z: f64, up: bool) {
        let pts: Vec<Point3<f64>> = ring.iter().map(|p| Point3::new(p.x, p.y, z)).collect();
        self.face(&pts, Vector3::new(0.0, 0.0, if up { 1.0 } else { -1.0 }));
    }

    pub fn finish(self, header: &str) -> String {
        let mut out = String::with_capacity(header.len() + self.body.len() + 40 * self.vertices.len());
        out.push_str(header);
        for key in &self.vertices {
            let [x, y, z] = key.map(|c| c as f64 / GRID_PER_M + 0.0);
            let _ = writeln!(out, "v {x} {y} {z}");
        }
        out.push_str(&self.body);
        out
    }
}
