//! The model as exporters write it: a [`Layout`] in, Wavefront OBJ text out. Every wall run is
//! cut around its holes into independent boxes (or single quads for a thin wall), floors and
//! ceilings run under the walls to their axes, the stair is a pile of step boxes; faces are
//! triangulated and wound the other way as drawn.

use super::layout::{Layout, Run};
use super::{P2, STAIR_WIDTH_M};
use crate::render::appearance::Rng;
use nalgebra::Vector2;
use std::collections::HashMap;
use std::fmt::Write as _;

/// Vertices shared by position; faces grouped by name.
struct Mesh {
    vertices: Vec<[f64; 3]>,
    index: HashMap<[i64; 3], u32>,
    groups: Vec<(String, Vec<Vec<u32>>)>,
}

impl Mesh {
    fn new() -> Self {
        Mesh {
            vertices: Vec::new(),
            index: HashMap::new(),
            groups: Vec::new(),
        }
    }

    fn group(&mut self, name: String) {
        self.groups.push((name, Vec::new()));
    }

    fn vertex(&mut self, p: [f64; 3]) -> u32 {
        // 1 µm keys: positions computed along different paths are one vertex.
        let key = p.map(|c| (c * 1e6).round() as i64);
        let next = self.vertices.len() as u32;
        *self.index.entry(key).or_insert_with(|| {
            self.vertices.push(p);
            next
        })
    }

    fn face(&mut self, pts: &[[f64; 3]]) {
        let f: Vec<u32> = pts.iter().map(|&p| self.vertex(p)).collect();
        if let Some((_, faces)) = self.groups.last_mut() {
            faces.push(f);
        }
    }

    /// A horizontal rectangle, wound about `up` (+z) or down.
    fn rect(&mut self, lo: P2, hi: P2, z: f64, up: bool) {
        let mut q = [[lo.x, lo.y, z], [hi.x, lo.y, z], [hi.x, hi.y, z], [lo.x, hi.y, z]];
        if !up {
            q.reverse();
        }
        self.face(&q);
    }

    /// A box around the axis `a`→`b`, `half` either side of it, from `z0` to `z1`; a single
    /// vertical quad when `half` is 0.
    fn wall_box(&mut self, a: P2, b: P2, half: f64, z0: f64, z1: f64) {
        let u = (b - a).normalize();
        let n = Vector2::new(-u.y, u.x) * half;
        let p = |q: P2, z: f64| [q.x, q.y, z];
        if half == 0.0 {
            self.face(&[p(a, z0), p(b, z0), p(b, z1), p(a, z1)]);
            return;
        }
        let (a0, b0, b1, a1) = (a - n, b - n, b + n, a + n);
        // Outward: the −n side, the +n side, the two ends, bottom and top.
        self.face(&[p(a0, z0), p(b0, z0), p(b0, z1), p(a0, z1)]);
        self.face(&[p(b1, z0), p(a1, z0), p(a1, z1), p(b1, z1)]);
        self.face(&[p(b0, z0), p(b1, z0), p(b1, z1), p(b0, z1)]);
        self.face(&[p(a1, z0), p(a0, z0), p(a0, z1), p(a1, z1)]);
        self.face(&[p(a0, z0), p(a1, z0), p(b1, z0), p(b0, z0)]);
        self.face(&[p(a0, z1), p(b0, z1), p(b1, z1), p(a1, z1)]);
    }

    /// A wall run cut around its holes: between consecutive hole edges, one box per solid height
    /// interval. Thick runs reach half their thickness past both ends, so corners close.
    fn run(&mut self, r: &Run, top: f64) {
        let len = (r.b - r.a).norm();
        let u = (r.b - r.a) / len;
        let half = r.thickness / 2.0;
        let mut cuts = vec![-half, len + half];
        for h in &r.holes {
            cuts.push(h.s0);
            cuts.push(h.s1);
        }
        cuts.sort_by(f64::total_cmp);
        cuts.dedup_by(|x, y| (*x - *y).abs() < 1e-6);
        for w in cuts.windows(2) {
            let (s0, s1) = (w[0], w[1]);
            let mid = (s0 + s1) / 2.0;
            let mut gaps: Vec<(f64, f64)> = r
                .holes
                .iter()
                .filter(|h| h.s0 < mid && mid < h.s1)
                .map(|h| (h.z0, h.z1))
                .collect();
            gaps.sort_by(|x, y| x.0.total_cmp(&y.0));
            let mut z = 0.0;
            for (g0, g1) in gaps.into_iter().chain([(top, top)]) {
                if g0 > z + 1e-6 {
                    self.wall_box(r.a + u * s0, r.a + u * s1, half, z, g0.min(top));
                }
                z = z.max(g1);
            }
        }
    }

    /// OBJ text: triangulated if asked, `flip_fraction` of the faces (drawn by `rng`) reversed.
    /// Returns the text, the face count and how many were reversed.
    fn to_obj(&self, header: &str, triangulate: bool, flip_fraction: f64, rng: &mut Rng) -> (String, usize, usize) {
        let mut out = String::from(header);
        for v in &self.vertices {
            let _ = writeln!(out, "v {} {} {}", v[0], v[1], v[2]);
        }
        let (mut faces, mut flipped) = (0, 0);
        for (name, group) in &self.groups {
            let _ = writeln!(out, "g {name}");
            for f in group {
                let pieces: Vec<Vec<u32>> = if triangulate && f.len() == 4 {
                    // Either diagonal, as exporters choose.
                    if rng.unit() < 0.5 {
                        vec![vec![f[0], f[1], f[2]], vec![f[0], f[2], f[3]]]
                    } else {
                        vec![vec![f[0], f[1], f[3]], vec![f[1], f[2], f[3]]]
                    }
                } else {
                    vec![f.clone()]
                };
                for mut p in pieces {
                    if rng.unit() < flip_fraction {
                        p.reverse();
                        flipped += 1;
                    }
                    faces += 1;
                    out.push('f');
                    for i in p {
                        let _ = write!(out, " {}", i + 1);
                    }
                    out.push('\n');
                }
            }
        }
        (out, faces, flipped)
    }
}

/// The building's OBJ text, drawing the diagonals and flips from `rng`; returns the text, the
/// face count and how many faces were wound the other way.
pub(super) fn model_obj(layout: &Layout, seed: u64, rng: &mut Rng) -> (String, usize, usize) {
    let Layout {
        outline,
        walls,
        triangulated,
        flip_fraction,
        height,
        storeys,
        top_of_ground,
        steps,
        hall,
        stair_axis,
        ..
    } = *layout;
    let (runs, rects) = (&layout.runs, &layout.rects);
    let top = if storeys > 1 { top_of_ground + height } else { height };
    let mut mesh = Mesh::new();
    for (k, r) in runs.iter().enumerate() {
        mesh.group(format!("wall_{k}"));
        mesh.run(r, top);
    }
    for (k, (lo, hi)) in rects.iter().enumerate() {
        let is_hall = hall.is_some_and(|(h, _)| h == k);
        mesh.group(format!("room_{k}_floor"));
        mesh.rect(*lo, *hi, 0.0, true);
        mesh.group(format!("room_{k}_ceiling"));
        mesh.rect(*lo, *hi, if is_hall { top } else { height }, false);
        if storeys > 1 && !is_hall {
            mesh.group(format!("room_{k}_upper_floor"));
            mesh.rect(*lo, *hi, top_of_ground, true);
            mesh.group(format!("room_{k}_upper_ceiling"));
            mesh.rect(*lo, *hi, top, false);
        }
    }
    // The stair: one box per step along the axis the layout chose.
    if let (Some((_, tread)), Some((a, b))) = (hall, stair_axis) {
        let u = (b - a) / (b - a).norm();
        let rise = top_of_ground / steps as f64;
        mesh.group("stair".to_string());
        for s in 0..steps {
            let (p, q) = (a + u * (s as f64 * tread), a + u * ((s + 1) as f64 * tread));
            mesh.wall_box(p, q, STAIR_WIDTH_M / 2.0, 0.0, (s + 1) as f64 * rise);
        }
    }
    let header = format!(
        "# A random building (omnitrack::desk::scenario::random, seed {seed}): {outline:?} outline, \
         {} rooms, {walls:?} walls, {storeys} storeys.\n# Metres, z up. Walls are independent boxes or \
         single faces; winding carries no meaning.\n",
        rects.len()
    );
    mesh.to_obj(&header, triangulated, flip_fraction, rng)
}
