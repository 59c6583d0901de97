//! From polygons to model segments (Koch–Teller §1: "we extract 3D model segments from the
//! boundaries of each polygon in the input model").
//!
//! Every face edge is grouped with all the edges on the same 3D line, the line is cut at every
//! vertex on it, and each piece is classified by the faces that touch it: a piece is a segment
//! unless exactly the faces of one flat surface meet there from both sides (a triangulation
//! diagonal, a seam between coplanar faces). Consecutive kept pieces merge, so collinear edges
//! become one segment, T-junctions need no special case, and an edge shared by several faces
//! appears once with all of them.

use super::{Face, Segment};
use nalgebra::{Point3, Unit, Vector3};
use std::collections::HashMap;

/// Tolerances of the geometric tests, in metres and radians.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentTolerances {
    /// Vertices closer than this are one vertex.
    pub weld_m: f64,
    /// A face whose vertices stray further than this from its plane is not planar.
    pub planar_m: f64,
    /// Faces meeting at less than this angle from flat are one surface (no segment between).
    pub coplanar_rad: f64,
    /// Edges whose directions differ by less than this lie on one line.
    pub collinear_rad: f64,
}

impl Default for SegmentTolerances {
    fn default() -> Self {
        // 10 µm welds survive f32 coordinates of buildings a few hundred metres across; a 0.06°
        // crease is invisible to a 512-pixel fisheye sensor.
        Self {
            weld_m: 1e-5,
            planar_m: 1e-4,
            coplanar_rad: 1e-3,
            collinear_rad: 1e-4,
        }
    }
}

/// Merges vertices closer than `tol` (each into an earlier kept vertex within `tol`; which one, if
/// several are, is unspecified). Returns the
/// kept vertices and, for every input vertex, its index among them.
pub(super) fn weld(points: &[Point3<f64>], tol: f64) -> (Vec<Point3<f64>>, Vec<u32>) {
    // Cells of side 2·tol: a neighbour within tol lies in at most two cells per axis.
    let cell = (2.0 * tol).max(f64::MIN_POSITIVE);
    let key = |c: [f64; 3]| c.map(|x| (x / cell).floor() as i64);
    let mut heads: HashMap<[i64; 3], u32> = HashMap::with_capacity(points.len());
    let mut next: Vec<u32> = Vec::with_capacity(points.len());
    let mut kept: Vec<Point3<f64>> = Vec::with_capacity(points.len());
    let mut remap = Vec::with_capacity(points.len());
    let tol2 = tol * tol;
    for p in points {
        let lo = key([p.x - tol, p.y - tol, p.z - tol]);
        let hi = key([p.x + tol, p.y + tol, p.z + tol]);
        let mut found = None;
        'search: for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    let mut i = heads.get(&[x, y, z]).copied().unwrap_or(u32::MAX);
                    while i != u32::MAX {
                        if (kept[i as usize] - p).norm_squared() <= tol2 {
                            found = Some(i);
                            break 'search;
                        }
                        i = next[i as usize];
                    }
                }
            }
        }
        let index = found.unwrap_or_else(|| {
            let i = kept.len() as u32;
            kept.push(*p);
            let head = heads.entry(key(p.coords.into())).or_insert(u32::MAX);
            next.push(*head);
            *head = i;
            i
        });
        remap.push(index);
    }
    (kept, remap)
}

pub(super) enum FaceShape {
    Degenerate,
    Planar(Face),
    /// A non-planar polygon as a fan of triangles.
    Split(Vec<Face>),
}

/// Validates one polygon (welded indices): drops repeated corners, measures its plane by Newell's
/// method, and splits it into a triangle fan if it is not planar.
pub(super) fn make_faces(vertices: &[Point3<f64>], idx: &[u32], tol: &SegmentTolerances) -> FaceShape {
    let mut corners: Vec<u32> = Vec::with_capacity(idx.len());
    for &i in idx {
        if corners.last() != Some(&i) {
            corners.push(i);
        }
    }
    while corners.len() > 1 && corners.first() == corners.last() {
        corners.pop();
    }
    if corners.len() < 3 {
        return FaceShape::Degenerate;
    }
    let pts: Vec<Point3<f64>> = corners.iter().map(|&i| vertices[i as usize]).collect();
    let centroid = pts.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / pts.len() as f64;
    let mut newell = Vector3::zeros();
    let mut perimeter = 0.0;
    for k in 0..pts.len() {
        let a = pts[k].coords - centroid;
        let b = pts[(k + 1) % pts.len()].coords - centroid;
        newell += a.cross(&b);
        perimeter += (b - a).norm();
    }
    let twice_area = newell.norm();
    // Not finite: coordinates so large that the products overflow (the reader bounds them).
    if !twice_area.is_finite() || twice_area <= 1e-12 * perimeter * perimeter || twice_area <= tol.weld_m * tol.weld_m {
        return FaceShape::Degenerate;
    }
    let normal = Unit::new_unchecked(newell / twice_area);
    let offset = normal.dot(&centroid);
    let planar = pts
        .iter()
        .all(|p| (normal.dot(&p.coords) - offset).abs() <= tol.planar_m);
    // A triangle is planar by definition: one that tests otherwise has lost its plane to rounding,
    // and splitting it again would never end.
    if planar || corners.len() == 3 {
        return FaceShape::Planar(Face {
            vertices: corners,
            normal,
            offset,
            obj_number: 0,
            object: 0,
            group: 0,
            material: 0,
        });
    }
    let triangles: Vec<Face> = (1..corners.len() - 1)
        .filter_map(
            |k| match make_faces(vertices, &[corners[0], corners[k], corners[k + 1]], tol) {
                FaceShape::Planar(f) => Some(f),
                _ => None,
            },
        )
        .collect();
    if triangles.is_empty() {
        FaceShape::Degenerate
    } else {
        FaceShape::Split(triangles)
    }
}

const FREE: u32 = u32::MAX;

struct Edge {
    a: u32,
    b: u32,
    /// The face this edge bounds, or FREE for an `l` record.
    face: u32,
    /// Unit vector in the face's plane, perpendicular to the edge, pointing into the face.
    inward: Vector3<f64>,
}

struct UnionFind(Vec<u32>);

impl UnionFind {
    fn find(&mut self, mut i: u32) -> u32 {
        while self.0[i as usize] != i {
            let parent = self.0[i as usize];
            self.0[i as usize] = self.0[parent as usize];
            i = parent;
        }
        i
    }
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// Hash keys of the line through `p` along `d`: (direction, moment) rounded to 1e-4, with the
/// direction's sign fixed by its largest component. Where a value lies within 2 % of a cell
/// from a rounding boundary, or two components tie for largest (a 45° line), every alternative
/// key is produced too, so that two edges of one line always share at least one key however
/// their rounding errors fall.
fn line_keys(d: &Vector3<f64>, p: &Vector3<f64>, out: &mut Vec<[i64; 6]>) {
    const CELL: f64 = 1e4;
    const SLACK: f64 = 0.02;
    out.clear();
    let largest = d.amax();
    let k = d.iamax();
    let mut signs = [if d[k] < 0.0 { -1.0 } else { 1.0 }, 0.0];
    // The first other component that ties for largest with the opposite sign may flip the choice.
    if let Some(j) = (0..3).find(|&j| j != k && d[j].abs() > largest - 1e-6 && d[j].signum() != d[k].signum()) {
        signs[1] = if d[j] < 0.0 { -1.0 } else { 1.0 };
    }
    for &sign in signs.iter().filter(|s| **s != 0.0) {
        let dir = d * sign;
        let m = p.cross(&dir);
        let values = [dir.x, dir.y, dir.z, m.x, m.y, m.z];
        let start = out.len();
        out.push([0; 6]);
        for (c, v) in values.iter().enumerate() {
            let scaled = v * CELL;
            let r = scaled.round();
            let frac = scaled - r;
            let alt = if frac > 0.5 - SLACK {
                Some(r as i64 + 1)
            } else if frac < -0.5 + SLACK {
                Some(r as i64 - 1)
            } else {
                None
            };
            let n = out.len();
            for key in &mut out[start..n] {
                key[c] = r as i64;
            }
            if let Some(a) = alt {
                for i in start..n {
                    let mut key = out[i];
                    key[c] = a;
                    out.push(key);
                }
            }
        }
    }
}

pub(super) fn extract(
    vertices: &[Point3<f64>],
    faces: &[Face],
    free_edges: &[[u32; 2]],
    tol: &SegmentTolerances,
) -> Vec<Segment> {
    let mut edges: Vec<Edge> = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        let n = face.vertices.len();
        for k in 0..n {
            let (a, b) = (face.vertices[k], face.vertices[(k + 1) % n]);
            let dir = vertices[b as usize] - vertices[a as usize];
            // Counter-clockwise about the normal, the face lies to the left of each edge.
            let inward = face.normal.cross(&dir).normalize();
            edges.push(Edge {
                a,
                b,
                face: f as u32,
                inward,
            });
        }
    }
    edges.extend(free_edges.iter().map(|&[a, b]| Edge {
        a,
        b,
        face: FREE,
        inward: Vector3::zeros(),
    }));
    let unit_dir = |e: &Edge| (vertices[e.b as usize] - vertices[e.a as usize]).normalize();

    // Group the edges by supporting line: edges meeting at a vertex in line, and edges whose
    // (direction, moment) agree to 1e-4 (overlapping collinear edges that share no vertex).
    let mut uf = UnionFind((0..edges.len() as u32).collect());
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); vertices.len()];
    for (i, e) in edges.iter().enumerate() {
        incident[e.a as usize].push(i as u32);
        incident[e.b as usize].push(i as u32);
    }
    let sin_tol = tol.collinear_rad.sin();
    for (v, list) in incident.iter().enumerate() {
        let away: Vec<Vector3<f64>> = list
            .iter()
            .map(|&i| {
                let e = &edges[i as usize];
                let other = if e.a as usize == v { e.b } else { e.a };
                (vertices[other as usize] - vertices[v]).normalize()
            })
            .collect();
        for i in 0..list.len() {
            for j in i + 1..list.len() {
                if away[i].cross(&away[j]).norm() < sin_tol {
                    uf.union(list[i], list[j]);
                }
            }
        }
    }
    let mut by_line: HashMap<[i64; 6], u32> = HashMap::with_capacity(edges.len());
    let mut keys: Vec<[i64; 6]> = Vec::new();
    for (i, e) in edges.iter().enumerate() {
        line_keys(&unit_dir(e), &vertices[e.a as usize].coords, &mut keys);
        for key in &keys {
            match by_line.entry(*key) {
                std::collections::hash_map::Entry::Occupied(o) => uf.union(i as u32, *o.get()),
                std::collections::hash_map::Entry::Vacant(v) => {
                    v.insert(i as u32);
                }
            }
        }
    }

    let mut group_of_root: HashMap<u32, usize> = HashMap::new();
    let mut groups: Vec<Vec<u32>> = Vec::new();
    for i in 0..edges.len() as u32 {
        let root = uf.find(i);
        let g = *group_of_root.entry(root).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push(i);
    }

    let mut segments = Vec::new();
    let mut cover: Vec<(u32, u32)> = Vec::new();
    for group in &groups {
        split_line(vertices, &edges, group, tol, &mut cover, &mut segments);
    }
    segments
}

/// Cuts one line's edges at every vertex on it, classifies the pieces and merges the kept ones.
fn split_line(
    vertices: &[Point3<f64>],
    edges: &[Edge],
    group: &[u32],
    tol: &SegmentTolerances,
    cover: &mut Vec<(u32, u32)>,
    out: &mut Vec<Segment>,
) {
    let pos = |v: u32| vertices[v as usize];
    let longest = *group
        .iter()
        .max_by(|&&i, &&j| {
            let li = (pos(edges[i as usize].b) - pos(edges[i as usize].a)).norm_squared();
            let lj = (pos(edges[j as usize].b) - pos(edges[j as usize].a)).norm_squared();
            li.total_cmp(&lj)
        })
        .expect("groups are never empty");
    let origin = pos(edges[longest as usize].a);
    let dir = (pos(edges[longest as usize].b) - origin).normalize();
    let s = |v: u32| (pos(v) - origin).dot(&dir);

    // Breakpoints: every edge end on the line, clustered within the weld tolerance.
    let mut ends: Vec<(f64, u32)> = group
        .iter()
        .flat_map(|&i| [edges[i as usize].a, edges[i as usize].b])
        .map(|v| (s(v), v))
        .collect();
    ends.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut cuts: Vec<(f64, u32)> = Vec::with_capacity(ends.len());
    for e in ends {
        match cuts.last() {
            Some(last) if e.0 - last.0 <= tol.weld_m => {}
            _ => cuts.push(e),
        }
    }
    let cut_index = |x: f64| -> usize {
        let i = cuts.partition_point(|c| c.0 < x - tol.weld_m);
        i.min(cuts.len() - 1)
    };

    cover.clear();
    for &i in group {
        let e = &edges[i as usize];
        let (p, q) = (cut_index(s(e.a)), cut_index(s(e.b)));
        for piece in p.min(q)..p.max(q) {
            cover.push((piece as u32, i));
        }
    }
    cover.sort_unstable();

    let sin_flat = tol.coplanar_rad.sin();
    let is_flat = |edge_ids: &[(u32, u32)]| -> bool {
        if edge_ids.len() < 2 {
            return false;
        }
        let w0 = edges[edge_ids[0].1 as usize].inward;
        let mut both_sides = false;
        for &(_, i) in edge_ids {
            let e = &edges[i as usize];
            if e.face == FREE || e.inward.cross(&w0).norm() > sin_flat {
                return false;
            }
            both_sides |= e.inward.dot(&w0) < 0.0;
        }
        both_sides
    };

    // Walk the pieces in order, extending a run while pieces are kept and adjacent.
    let mut run: Option<(usize, usize, Vec<u32>)> = None;
    let mut k = 0;
    while k < cover.len() {
        let piece = cover[k].0 as usize;
        let mut end = k;
        while end < cover.len() && cover[end].0 as usize == piece {
            end += 1;
        }
        let here = &cover[k..end];
        if !is_flat(here) {
            let faces = here.iter().map(|&(_, i)| edges[i as usize].face).filter(|&f| f != FREE);
            match &mut run {
                Some((_, last, fs)) if *last == piece => {
                    *last = piece + 1;
                    fs.extend(faces);
                }
                _ => {
                    if let Some(r) = run.take() {
                        out.push(finish(&cuts, vertices, r));
                    }
                    run = Some((piece, piece + 1, faces.collect()));
                }
            }
        }
        k = end;
    }
    if let Some(r) = run {
        out.push(finish(&cuts, vertices, r));
    }
}

fn finish(
    cuts: &[(f64, u32)],
    vertices: &[Point3<f64>],
    (first, last, mut faces): (usize, usize, Vec<u32>),
) -> Segment {
    faces.sort_unstable();
    faces.dedup();
    Segment {
        a: vertices[cuts[first].1 as usize],
        b: vertices[cuts[last].1 as usize],
        faces,
    }
}
