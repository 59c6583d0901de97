//! Building the visibility table on the CPU (desk only): node validity, an exact software
//! cube-map rasteriser (face ids + perspective-correct depth) per node, Koch–Teller's segment
//! rule (Figure 9), optional merging with neighbour nodes, parallel over nodes with rayon.
//!
//! **Valid nodes** (free space inside the building, where a person could stand). From the
//! node, 26 rays (the directions of a 3×3×3 stencil) are cast against the model. The node is
//! valid when
//! 1. the ray straight down meets a face (something to stand on);
//! 2. at least 13 of the 26 rays meet a face (the others may leave through open doors and
//!    windows, so rooms with openings keep their nodes, while a point outside the building
//!    loses them: most rays escape);
//! 3. along each horizontal axis of the stencil the faces on either side are at least
//!    0.5 m apart and along one of them at least 1.2 m, and the faces below and above at
//!    least 1.2 m (the inside of a wall, a slab or a pillar is smaller than any room; a closed
//!    box 1.2 m or more across is a room, since winding cannot say it is solid);
//! 4. no face is nearer than `clearance_m` (exact point–triangle distance; default 0.2 m).
//!
//! Nothing reads the faces' winding (docs/interfaces.md, "Building model", gives it no
//! meaning): a wall may be one face seen from both sides, faces may be duplicated or overlap,
//! and a model may have no faces outside its rooms. The rule before this one counted the faces seen "from behind",
//! and kept 459 of 1,872 nodes of a building drawn with single-face walls wound either way
//! (issue 20).
//!
//! **Per valid node**: all triangles whose bounding box comes within `max_range_m` are
//! rasterised into six `res × res` cube faces (pixel centres, 1/z interpolated linearly in
//! screen space, near-plane clipping), nearest first, skipping a triangle strictly behind the
//! farthest depth drawn in every 8 × 8 block it covers; of equal depths the smaller face id
//! wins, so the buffers are those of drawing in file order. Visible faces are the ids left in
//! the buffers. Every
//! segment within range is a candidate (the paper takes only segments bounding a visible face;
//! that misses segments whose faces cover no pixel centre: door jambs far down a corridor, the
//! outer edge of a window seen through it). A candidate is rasterised per cube face (clipped to
//! the face's frustum, one sample per pixel along its major axis). A sample passes when the
//! segment is not farther than the surface at its pixel (relative tolerance 1e-3), or when one
//! of the segment's own faces shows at that pixel or a neighbour (the segment lies on its
//! faces' borders, half a pixel from the nearest pixel centre); it fails when the segment is
//! behind every surface of the 3×3 neighbourhood; otherwise (a silhouette or a grazing surface
//! within a pixel) an exact ray from the node to the segment's point decides. A segment with at
//! least `min_visible_pixels` passing pixels is visible (the paper's rule is 2).
//!
//! **Merging** ([`Merge`]): optional union with line-of-sight grid neighbours or with renders at
//! the cell's corners. Measured on `corridor` (benches/visibility.rs), it raises the recall of
//! segments > 2° at random positions from 97.2 % to 99.6 % but lowers precision from 88 % to
//! 73 %; the default is the paper's (none).

use super::{segment_vertex_ids, RawTable, TableHeader, VisibilityTable, FORMAT_VERSION, NO_NODE};
use nalgebra::{Point3, Vector3};
use omnitrack_config::VisibilityConfig;
use omnitrack_core::model::bvh::{Ray, Triangle, TriangleBvh};
use omnitrack_core::model::triangulate::triangulate_polygon;
use omnitrack_core::model::Model;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// Node validity (module doc): of the 26 stencil rays, at least this many must meet a face…
const MIN_ENCLOSING_HITS: usize = 13;
/// …the faces on both sides of every horizontal axis must be at least this far apart (m: a
/// person's shoulders; a corridor or a closet is wider, the inside of a wall thinner)…
const MIN_FREE_WIDTH_M: f64 = 0.5;
/// …at least this far along one of those axes (m: a closet is longer; the inside of a pillar
/// 0.8 m square, 1.13 m across its diagonal, is not)…
const MIN_ROOM_SPAN_M: f64 = 1.2;
/// …and the floor and ceiling this far (m: a slab or a ceiling void is thinner than a room is
/// high).
const MIN_FREE_HEIGHT_M: f64 = 1.2;

/// How to build a table.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildOptions {
    pub spacing_m: f64,
    /// Node layers above the model's lowest point.
    pub heights_m: Vec<f64>,
    pub cube_map_resolution: u32,
    pub min_visible_pixels: u32,
    /// Triangles whose bounding box is farther than this from a node are not rendered.
    pub max_range_m: f64,
    /// Minimum distance from a valid node to any face.
    pub clearance_m: f64,
    /// How a node's set is widened to cover its cell.
    pub merge: Merge,
    /// Segments shorter than this (m) enter no set.
    pub min_segment_length_m: f64,
    /// Show a progress bar on standard error.
    pub progress: bool,
}

/// Widening a node's visibility set to its cell (the paper's sets are those of the node only
/// and "not conservative").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Merge {
    /// The node's own render only (the paper).
    None,
    /// Union with the sets of the grid neighbours (±1 in x, y and layer) in line of sight.
    Neighbours,
    /// Union with renders at the four corners of the node's cell (at the node's height; shared
    /// by the four cells that meet there). A corner that is not free space or not in line of
    /// sight of the node is replaced by the point half-way to it, if that one is.
    CellCorners,
}

impl Merge {
    pub fn code(self) -> u8 {
        match self {
            Merge::None => 0,
            Merge::Neighbours => 1,
            Merge::CellCorners => 2,
        }
    }
}

/// Lookup cells per node cell along x and y.
pub const LOOKUP_SUBDIVISIONS: usize = 4;

/// Default maximum range of the visibility render, metres.
pub const DEFAULT_MAX_RANGE_M: f64 = 40.0;

impl BuildOptions {
    pub fn from_config(c: &VisibilityConfig) -> BuildOptions {
        BuildOptions {
            spacing_m: c.node_spacing_m,
            heights_m: c.node_heights_m.clone(),
            cube_map_resolution: c.cube_map_resolution,
            min_visible_pixels: c.min_visible_pixels,
            max_range_m: DEFAULT_MAX_RANGE_M,
            clearance_m: 0.2,
            merge: Merge::None,
            min_segment_length_m: c.min_segment_length_m,
            progress: false,
        }
    }
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions::from_config(&VisibilityConfig::default())
    }
}

/// A model triangle in f64 with its face.
#[derive(Debug, Clone, Copy)]
struct Tri {
    p: [[f64; 3]; 3],
    face: u32,
}

/// Side of a [`Bins`] cell, metres: small enough that a clearance test visits a cell or four,
/// large enough that a node's 40 m window is a few hundred cells.
const BIN_M: f64 = 5.0;
/// At most this many cells per axis (a model kilometres across gets coarser cells, not gigabytes
/// of empty ones).
const MAX_BINS_PER_AXIS: f64 = 2048.0;

/// Items (triangles, segments) binned by their x-y bounding boxes on a square grid, so that the
/// work at one position visits only what lies near it: a table's build time grows with the
/// model's area, not with its square (a 10⁵ m² campus, issue 20).
struct Bins {
    origin: [f64; 2],
    cell: f64,
    dims: [usize; 2],
    /// Per cell, its items are `items[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
    /// Per item, the cells its box covers: x0, y0, x1, y1 (inclusive).
    ranges: Vec<[u32; 4]>,
}

impl Bins {
    fn new(boxes: &[([f64; 3], [f64; 3])]) -> Bins {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (a, b) in boxes {
            for k in 0..2 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        }
        if boxes.is_empty() {
            (lo, hi) = ([0.0; 2], [0.0; 2]);
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell = BIN_M.max(extent / MAX_BINS_PER_AXIS);
        let dims = [0, 1].map(|k| ((hi[k] - lo[k]) / cell).floor() as usize + 1);
        let mut bins = Bins {
            origin: lo,
            cell,
            dims,
            start: Vec::new(),
            items: Vec::new(),
            ranges: Vec::with_capacity(boxes.len()),
        };
        let mut count = vec![0u32; dims[0] * dims[1] + 1];
        for (a, b) in boxes {
            let r = bins.cells([a[0], a[1]], [b[0], b[1]]);
            for y in r[1]..=r[3] {
                for x in r[0]..=r[2] {
                    count[y as usize * dims[0] + x as usize + 1] += 1;
                }
            }
            bins.ranges.push(r);
        }
        for c in 1..count.len() {
            count[c] += count[c - 1];
        }
        let mut fill = count.clone();
        bins.items = vec![0; *count.last().expect("at least one cell") as usize];
        for (i, r) in bins.ranges.iter().enumerate() {
            for y in r[1]..=r[3] {
                for x in r[0]..=r[2] {
                    let c = y as usize * dims[0] + x as usize;
                    bins.items[fill[c] as usize] = i as u32;
                    fill[c] += 1;
                }
            }
        }
        bins.start = count;
        bins
    }

    /// The cells an x-y box covers, clamped to the grid: x0, y0, x1, y1.
    fn cells(&self, lo: [f64; 2], hi: [f64; 2]) -> [u32; 4] {
        let at = |v: f64, k: usize| {
            (((v - self.origin[k]) / self.cell).floor().max(0.0) as usize).min(self.dims[k] - 1) as u32
        };
        [at(lo[0], 0), at(lo[1], 1), at(hi[0], 0), at(hi[1], 1)]
    }

    /// Puts in `out`, once each and in no particular order, the items whose boxes reach cells
    /// within `r` of `p` in x and y (a superset of those within `r`; callers test exactly).
    fn near(&self, p: [f64; 3], r: f64, out: &mut Vec<u32>) {
        out.clear();
        let q = self.cells([p[0] - r, p[1] - r], [p[0] + r, p[1] + r]);
        for y in q[1]..=q[3] {
            for x in q[0]..=q[2] {
                let c = y as usize * self.dims[0] + x as usize;
                for &i in &self.items[self.start[c] as usize..self.start[c + 1] as usize] {
                    // An item in several cells of the window is taken in the first of them.
                    let rg = self.ranges[i as usize];
                    if x == rg[0].max(q[0]) && y == rg[1].max(q[1]) {
                        out.push(i);
                    }
                }
            }
        }
    }
}

/// The model's faces as occluders, which every node's work shares: their triangles, a BVH for
/// exact rays and x-y bins for what lies near a position. (The renderer's `desk::render::Scene`
/// is another thing: surfaces with appearance, for pictures.)
pub struct Occluders<'m> {
    model: &'m Model,
    tris: Vec<Tri>,
    /// Per triangle: bounding box min, max.
    boxes: Vec<([f64; 3], [f64; 3])>,
    bvh: TriangleBvh,
    tri_bins: Bins,
    segment_bins: Bins,
}

impl<'m> Occluders<'m> {
    pub fn new(model: &'m Model) -> Occluders<'m> {
        let mut tris = Vec::new();
        for (fi, face) in model.faces.iter().enumerate() {
            let corners: Vec<Point3<f64>> = face.vertices.iter().map(|&v| model.vertices[v as usize]).collect();
            for t in triangulate_polygon(&corners, &face.normal) {
                let p = t.map(|i| [corners[i].x, corners[i].y, corners[i].z]);
                let area = cross(sub(p[1], p[0]), sub(p[2], p[0]));
                if dot(area, area) > 1e-20 {
                    tris.push(Tri { p, face: fi as u32 });
                }
            }
        }
        let boxes: Vec<([f64; 3], [f64; 3])> = tris
            .iter()
            .map(|t| {
                let mut lo = t.p[0];
                let mut hi = t.p[0];
                for q in &t.p[1..] {
                    for k in 0..3 {
                        lo[k] = lo[k].min(q[k]);
                        hi[k] = hi[k].max(q[k]);
                    }
                }
                (lo, hi)
            })
            .collect();
        let f32t: Vec<Triangle> = tris
            .iter()
            .map(|t| {
                let p = t.p.map(|q| q.map(|c| c as f32));
                Triangle::new(p[0], p[1], p[2])
            })
            .collect();
        let payload: Vec<u32> = tris.iter().map(|t| t.face).collect();
        let bvh = TriangleBvh::build(&f32t, &payload);
        let tri_bins = Bins::new(&boxes);
        let segment_boxes: Vec<([f64; 3], [f64; 3])> = model
            .segments
            .iter()
            .map(|s| {
                let (a, b) = (s.a.coords, s.b.coords);
                (
                    [a.x.min(b.x), a.y.min(b.y), a.z.min(b.z)],
                    [a.x.max(b.x), a.y.max(b.y), a.z.max(b.z)],
                )
            })
            .collect();
        let segment_bins = Bins::new(&segment_boxes);
        Occluders {
            model,
            tris,
            boxes,
            bvh,
            tri_bins,
            segment_bins,
        }
    }

    /// Closest hit from `o` along unit `d`: (face, distance).
    pub fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>, t_max: f64) -> Option<(u32, f64)> {
        let ray = Ray::new(
            [o.x as f32, o.y as f32, o.z as f32],
            [d.x as f32, d.y as f32, d.z as f32],
        );
        self.bvh.closest(&ray, 1e-4, t_max as f32).map(|(f, t)| (f, t as f64))
    }

    /// Whether the straight path from `a` to `b` crosses no face.
    pub fn clear_line(&self, a: &Point3<f64>, b: &Point3<f64>) -> bool {
        let d = b - a;
        let len = d.norm();
        if len < 1e-9 {
            return true;
        }
        self.cast(a, &(d / len), len - 1e-4).is_none()
    }

    /// The node-validity rule of the module doc: room for a person, read from where the
    /// faces are, never from which way they are wound.
    pub fn is_free(&self, p: &Point3<f64>, clearance_m: f64) -> bool {
        // Distance to the first face along each of the 26 stencil directions (∞: none).
        let mut reach = [[[f64::INFINITY; 3]; 3]; 3];
        let mut hits = 0;
        for (i, plane) in reach.iter_mut().enumerate() {
            for (j, row) in plane.iter_mut().enumerate() {
                for (k, r) in row.iter_mut().enumerate() {
                    if (i, j, k) == (1, 1, 1) {
                        continue;
                    }
                    let d = Vector3::new(i as f64 - 1.0, j as f64 - 1.0, k as f64 - 1.0).normalize();
                    if let Some((_, t)) = self.cast(p, &d, 1e6) {
                        *r = t;
                        hits += 1;
                    }
                }
            }
        }
        // 1. Something to stand on.
        if reach[1][1][0].is_infinite() {
            return false;
        }
        // 2. Inside the building's envelope.
        if hits < MIN_ENCLOSING_HITS {
            return false;
        }
        // 3. Wide and high enough for a person along every axis of the stencil that faces close
        //    on both sides: the inside of a wall or a slab is thinner than any room.
        //    A space closed all round and short along every axis (the inside of a pillar, or
        //    a closed box) is not a room either: without winding the two cannot be told apart.
        let mut longest: f64 = 0.0;
        for (i, j, k) in [(2, 1, 1), (1, 2, 1), (2, 2, 1), (2, 0, 1)] {
            let across = reach[i][j][k] + reach[2 - i][2 - j][2 - k];
            if across < MIN_FREE_WIDTH_M {
                return false;
            }
            longest = longest.max(across);
        }
        if longest < MIN_ROOM_SPAN_M {
            return false;
        }
        if reach[1][1][2] + reach[1][1][0] < MIN_FREE_HEIGHT_M {
            return false;
        }
        let c = [p.x, p.y, p.z];
        let r2 = clearance_m * clearance_m;
        NEAR_SCRATCH.with_borrow_mut(|near| {
            self.tri_bins.near(c, clearance_m, near);
            near.iter().all(|&i| {
                let (t, (lo, hi)) = (&self.tris[i as usize], &self.boxes[i as usize]);
                !(box_dist2(&c, lo, hi) < r2 && point_triangle_dist2(c, &t.p) < r2)
            })
        })
    }
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn box_dist2(c: &[f64; 3], lo: &[f64; 3], hi: &[f64; 3]) -> f64 {
    let mut d2 = 0.0;
    for k in 0..3 {
        let d = (lo[k] - c[k]).max(c[k] - hi[k]).max(0.0);
        d2 += d * d;
    }
    d2
}

/// Squared distance from `p` to triangle `t` (Ericson, Real-Time Collision Detection 5.1.5).
fn point_triangle_dist2(p: [f64; 3], t: &[[f64; 3]; 3]) -> f64 {
    let (a, b, c) = (t[0], t[1], t[2]);
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    let closest = |q: [f64; 3]| {
        let d = sub(p, q);
        dot(d, d)
    };
    let lerp = |x: [f64; 3], y: [f64; 3], s: f64| [x[0] + s * y[0], x[1] + s * y[1], x[2] + s * y[2]];
    if d1 <= 0.0 && d2 <= 0.0 {
        return closest(a);
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return closest(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return closest(lerp(a, ab, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return closest(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return closest(lerp(a, ac, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return closest(lerp(b, sub(c, b), w));
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    closest([
        a[0] + ab[0] * v + ac[0] * w,
        a[1] + ab[1] * v + ac[1] * w,
        a[2] + ab[2] * v + ac[2] * w,
    ])
}

const NEAR: f64 = 1e-3;

/// Cube face `f`: (major axis, sign, u axis, v axis).
#[inline]
fn cube_axes(f: usize) -> (usize, f64, usize, usize) {
    let a = f / 2;
    let s = if f % 2 == 0 { 1.0 } else { -1.0 };
    (a, s, (a + 1) % 3, (a + 2) % 3)
}

/// A worker's cube map: per face, `res²` pixels of 1/z (0 = nothing) and face id.
pub struct CubeMap {
    res: usize,
    inv_z: Vec<f32>,
    id: Vec<u32>,
    /// Per model face: the node stamp at which it was last seen.
    face_stamp: Vec<u32>,
    stamp: u32,
    poly: Vec<[f64; 3]>,
    clipped: Vec<[f64; 3]>,
    /// Scratch: the triangles, then the segments, near the node.
    near: Vec<u32>,
    /// Per `TILE`² block of pixels, filled on first use at each node.
    tiles: Vec<Tile>,
    /// Per `TILE`² block, no ring: the smallest 1/z, valid unless `depth_dirty` (hierarchical
    /// depth, to skip triangles that are behind everything drawn where they would be drawn).
    depth_min: Vec<f32>,
    depth_dirty: Vec<bool>,
    /// Scratch: the triangles near the node keyed by distance.
    order: Vec<u64>,
}

/// Side of a [`Tile`], pixels.
const TILE: usize = 8;

/// What the segment test needs to know of a block of pixels and the ring of pixels around it
/// (the 3 × 3 neighbourhoods of its pixels): the farthest surface in it and which faces it
/// shows. A segment sample behind that surface, none of whose faces the block shows, fails the
/// test without reading the pixels: most segments in a large building are hidden, and reading
/// every neighbourhood of every sample was a fifth of a build.
#[derive(Debug, Clone, Copy, Default)]
struct Tile {
    /// The node stamp it was filled at.
    stamp: u32,
    /// Smallest 1/z of the block and its ring.
    min_inv_z: f32,
    /// A 64-bit Bloom filter of the face ids shown (one bit per id).
    faces: u64,
}

/// Face `id`'s bit in [`Tile::faces`] (Fibonacci hashing: ids of neighbouring faces spread).
#[inline]
fn face_bit(id: u32) -> u64 {
    1u64 << (id.wrapping_mul(0x9E37_79B9) >> 26)
}

thread_local! {
    /// Scratch of [`Occluders::is_free`]'s clearance test, one per worker thread.
    static NEAR_SCRATCH: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl CubeMap {
    pub fn new(res: usize, faces: usize) -> CubeMap {
        CubeMap {
            res,
            inv_z: vec![0.0; 6 * res * res],
            id: vec![u32::MAX; 6 * res * res],
            face_stamp: vec![0; faces],
            stamp: 0,
            poly: Vec::with_capacity(8),
            clipped: Vec::with_capacity(8),
            near: Vec::new(),
            tiles: vec![Tile::default(); 6 * res.div_ceil(TILE).pow(2)],
            depth_min: vec![0.0; 6 * res.div_ceil(TILE).pow(2)],
            depth_dirty: vec![false; 6 * res.div_ceil(TILE).pow(2)],
            order: Vec::new(),
        }
    }

    /// The smallest 1/z of tile (tx, ty) of cube face `f` (no ring). Lane-wise over rows so that
    /// it compiles to packed minima: 1/z is never NaN.
    #[inline]
    fn tile_min(&self, f: usize, tx: usize, ty: usize) -> f32 {
        let res = self.res;
        let (x0, x1) = (tx * TILE, ((tx + 1) * TILE).min(res));
        let mut lanes = [f32::INFINITY; TILE];
        for y in ty * TILE..((ty + 1) * TILE).min(res) {
            let row = &self.inv_z[f * res * res + y * res + x0..f * res * res + y * res + x1];
            for (m, &v) in lanes.iter_mut().zip(row) {
                *m = if v < *m { v } else { *m };
            }
        }
        lanes.iter().fold(f32::INFINITY, |m, &v| if v < m { v } else { m })
    }

    /// Whether a triangle over the pixel box `[x0, x1, y0, y1]` of cube face `f`, its 1/z the
    /// plane `w = a x + b y + c`, would lose the depth test at every pixel: it is strictly
    /// farther than the farthest surface drawn in every block it touches. If it is not, the
    /// blocks are marked for a new minimum, as it is about to be drawn.
    fn hidden(&mut self, f: usize, [x0, x1, y0, y1]: [usize; 4], [wa, wb, wc]: [f64; 3]) -> bool {
        // The largest 1/z the raster loop can compute: the plane at the corners of the box, with
        // room for rounding (thin triangles have steep planes).
        let mut max_w = f64::NEG_INFINITY;
        for px in [x0 as f64 + 0.5, x1 as f64 + 0.5] {
            for py in [y0 as f64 + 0.5, y1 as f64 + 0.5] {
                max_w = max_w.max(wa * px + (wb * py + wc));
            }
        }
        let slack = 1e-9 * (wa.abs() * (x1 as f64 + 1.0) + wb.abs() * (y1 as f64 + 1.0) + wc.abs());
        // NaN compares false below: such a triangle is drawn, as the raster loop would.
        let max_w = (max_w + slack) as f32;
        let tn = self.res.div_ceil(TILE);
        let blocks = (y0 / TILE..=y1 / TILE).flat_map(|ty| (x0 / TILE..=x1 / TILE).map(move |tx| (tx, ty)));
        for (tx, ty) in blocks.clone() {
            let k = (f * tn + ty) * tn + tx;
            if self.depth_dirty[k] {
                self.depth_min[k] = self.tile_min(f, tx, ty);
                self.depth_dirty[k] = false;
            }
            // Strictly: at an equal depth a smaller face id would still win.
            let behind = max_w < self.depth_min[k];
            if !behind {
                for (tx, ty) in blocks {
                    self.depth_dirty[(f * tn + ty) * tn + tx] = true;
                }
                return false;
            }
        }
        true
    }

    /// The summary of tile (tx, ty) of cube face `f` at the current node.
    #[inline]
    fn tile(&mut self, f: usize, tx: usize, ty: usize) -> Tile {
        let (res, tn) = (self.res, self.res.div_ceil(TILE));
        let k = (f * tn + ty) * tn + tx;
        if self.tiles[k].stamp != self.stamp {
            let (x0, x1) = ((tx * TILE).saturating_sub(1), ((tx + 1) * TILE + 1).min(res));
            let (y0, y1) = ((ty * TILE).saturating_sub(1), ((ty + 1) * TILE + 1).min(res));
            let mut t = Tile {
                stamp: self.stamp,
                min_inv_z: f32::INFINITY,
                faces: 0,
            };
            for y in y0..y1 {
                let row = f * res * res + y * res;
                for j in row + x0..row + x1 {
                    t.min_inv_z = t.min_inv_z.min(self.inv_z[j]);
                    if self.id[j] != u32::MAX {
                        t.faces |= face_bit(self.id[j]);
                    }
                }
            }
            self.tiles[k] = t;
        }
        self.tiles[k]
    }

    /// Renders the scene around `eye`; returns the visible faces (sorted) and segments (sorted).
    pub fn visibility(&mut self, scene: &Occluders, eye: &Point3<f64>, opts: &BuildOptions) -> (Vec<u32>, Vec<u32>) {
        self.inv_z.fill(0.0);
        self.id.fill(u32::MAX);
        let e = [eye.x, eye.y, eye.z];
        let r2 = opts.max_range_m * opts.max_range_m;
        let mut near = std::mem::take(&mut self.near);
        scene.tri_bins.near(e, opts.max_range_m, &mut near);
        self.depth_min.fill(0.0);
        self.depth_dirty.fill(false);
        // Nearest first, so that the walls around the node fill the depth buffer before the
        // rest of the building is drawn behind them and mostly skipped (`hidden`). The order
        // changes nothing else: equal depths go to the smaller face id in any order.
        self.order.clear();
        self.order.extend(near.iter().filter_map(|&i| {
            let (lo, hi) = &scene.boxes[i as usize];
            let d = box_dist2(&e, lo, hi);
            // A non-negative f32's bits sort as the number.
            (d <= r2).then(|| u64::from((d as f32).to_bits()) << 32 | u64::from(i))
        }));
        self.order.sort_unstable();
        near.clear();
        near.extend(self.order.iter().map(|&k| k as u32));
        for &i in &near {
            let t = &scene.tris[i as usize];
            let q = t.p.map(|p| sub(p, e));
            for f in 0..6 {
                self.raster_triangle(f, &q, t.face);
            }
        }
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.face_stamp.fill(0);
            self.tiles.fill(Tile::default());
            self.stamp = 1;
        }
        let mut faces = Vec::new();
        for &id in &self.id {
            if id != u32::MAX && self.face_stamp[id as usize] != self.stamp {
                self.face_stamp[id as usize] = self.stamp;
                faces.push(id);
            }
        }
        faces.sort_unstable();
        let mut segments = Vec::new();
        scene.segment_bins.near(e, opts.max_range_m, &mut near);
        // Index order, so that the segment set comes out sorted.
        near.sort_unstable();
        for &si in &near {
            let seg = &scene.model.segments[si as usize];
            // Every segment within range is a candidate, not only those bounding a visible face
            // (the paper's rule): a segment can be visible while its faces cover no pixel centre
            // (a door jamb far down a corridor, the outer edge of a window seen through it).
            let candidate = seg.length() >= opts.min_segment_length_m
                && point_segment_dist2(e, [seg.a.x, seg.a.y, seg.a.z], [seg.b.x, seg.b.y, seg.b.z]) <= r2;
            if candidate && self.segment_visible(scene, &e, seg, opts.min_visible_pixels) {
                segments.push(si);
            }
        }
        self.near = near;
        (faces, segments)
    }

    /// Face id at pixel (x, y) of cube face `f` (`u32::MAX` = nothing).
    pub fn id_at(&self, f: usize, x: usize, y: usize) -> u32 {
        self.id[f * self.res * self.res + y * self.res + x]
    }

    /// World direction (not normalised) through the centre of pixel (x, y) of cube face `f`.
    pub fn pixel_direction(&self, f: usize, x: usize, y: usize) -> Vector3<f64> {
        let (a, s, ua, va) = cube_axes(f);
        let half = 0.5 * self.res as f64;
        let mut d = Vector3::zeros();
        d[ua] = (x as f64 + 0.5) / half - 1.0;
        d[va] = (y as f64 + 0.5) / half - 1.0;
        d[a] = s;
        d
    }

    fn raster_triangle(&mut self, f: usize, q: &[[f64; 3]; 3], face: u32) {
        let (a, s, ua, va) = cube_axes(f);
        let v = q.map(|p| [p[ua], p[va], s * p[a]]);
        // Outside the frustum when all vertices are beyond one of its planes.
        if v.iter().all(|p| p[2] <= NEAR)
            || v.iter().all(|p| p[0] > p[2])
            || v.iter().all(|p| -p[0] > p[2])
            || v.iter().all(|p| p[1] > p[2])
            || v.iter().all(|p| -p[1] > p[2])
        {
            return;
        }
        if v.iter().all(|p| p[2] > NEAR) {
            self.raster_clipped(f, v, face);
            return;
        }
        // Clip the polygon against z = NEAR.
        self.poly.clear();
        self.poly.extend_from_slice(&v);
        self.clipped.clear();
        for i in 0..3 {
            let (p, n) = (self.poly[i], self.poly[(i + 1) % 3]);
            let (ip, inn) = (p[2] > NEAR, n[2] > NEAR);
            if ip {
                self.clipped.push(p);
            }
            if ip != inn {
                let t = (NEAR - p[2]) / (n[2] - p[2]);
                self.clipped
                    .push([p[0] + t * (n[0] - p[0]), p[1] + t * (n[1] - p[1]), NEAR]);
            }
        }
        for i in 1..self.clipped.len().saturating_sub(1) {
            let tri = [self.clipped[0], self.clipped[i], self.clipped[i + 1]];
            self.raster_clipped(f, tri, face);
        }
    }

    /// Rasterises a triangle in face coordinates (x, y, z > 0) at pixel centres.
    fn raster_clipped(&mut self, f: usize, v: [[f64; 3]; 3], face: u32) {
        let res = self.res as f64;
        let half = 0.5 * res;
        let s = v.map(|p| {
            let w = 1.0 / p[2];
            [(p[0] * w + 1.0) * half, (p[1] * w + 1.0) * half, w]
        });
        let area = (s[1][0] - s[0][0]) * (s[2][1] - s[0][1]) - (s[2][0] - s[0][0]) * (s[1][1] - s[0][1]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let min_x = s.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        let max_x = s.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
        let min_y = s.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
        let max_y = s.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
        // Pixel centres c + 0.5 inside [min, max].
        let x0 = (min_x - 0.5).ceil().max(0.0);
        let x1 = (max_x - 0.5).floor().min(res - 1.0);
        let y0 = (min_y - 0.5).ceil().max(0.0);
        let y1 = (max_y - 0.5).floor().min(res - 1.0);
        if x0 > x1 || y0 > y1 {
            return;
        }
        let inv_area = 1.0 / area;
        // Edge functions e_i(x, y) = A_i x + B_i y + C_i, normalised so that they are the
        // barycentric weights of the opposite vertex.
        let edge = |a: [f64; 3], b: [f64; 3]| {
            let ea = (a[1] - b[1]) * inv_area;
            let eb = (b[0] - a[0]) * inv_area;
            let ec = (a[0] * b[1] - a[1] * b[0]) * inv_area;
            (ea, eb, ec)
        };
        let e0 = edge(s[1], s[2]);
        let e1 = edge(s[2], s[0]);
        let e2 = edge(s[0], s[1]);
        // 1/z as a plane over the screen.
        let wa = e0.0 * s[0][2] + e1.0 * s[1][2] + e2.0 * s[2][2];
        let wb = e0.1 * s[0][2] + e1.1 * s[1][2] + e2.1 * s[2][2];
        let wc = e0.2 * s[0][2] + e1.2 * s[1][2] + e2.2 * s[2][2];
        let base = f * self.res * self.res;
        let (x0, x1, y0, y1) = (x0 as usize, x1 as usize, y0 as usize, y1 as usize);
        if self.hidden(f, [x0, x1, y0, y1], [wa, wb, wc]) {
            return;
        }
        const EPS: f64 = -1e-9;
        for y in y0..=y1 {
            let py = y as f64 + 0.5;
            let row = base + y * self.res;
            let r0 = e0.1 * py + e0.2;
            let r1 = e1.1 * py + e1.2;
            let r2 = e2.1 * py + e2.2;
            let rw = wb * py + wc;
            // The span of x where all three edge functions are ≥ 0 (each is linear in x).
            let mut lo = x0 as f64 + 0.5;
            let mut hi = x1 as f64 + 0.5;
            for (a, r) in [(e0.0, r0), (e1.0, r1), (e2.0, r2)] {
                if a > 0.0 {
                    lo = lo.max((EPS - r) / a);
                } else if a < 0.0 {
                    hi = hi.min((EPS - r) / a);
                } else if r < EPS {
                    lo = f64::INFINITY;
                }
            }
            if lo > hi {
                continue;
            }
            // lo ≥ x0 + 0.5 and hi ≥ lo here, so both roundings see non-negative values.
            let xa = ceil_nonneg(lo - 0.5).max(x0);
            let xb = ((hi - 0.5) as usize).min(x1) as isize;
            if xb < xa as isize {
                continue;
            }
            // Branch-free and indexed by i32 so that the compiler vectorises it: this loop was
            // half of a build's time. `x as i32 as f64` is exact, so the depths are those of the
            // scalar loop to the bit.
            let span = row + xa..row + xb as usize + 1;
            let (zs, ids) = (&mut self.inv_z[span.clone()], &mut self.id[span]);
            for (k, (z, id)) in zs.iter_mut().zip(ids.iter_mut()).enumerate() {
                let w = (wa * ((xa + k) as i32 as f64 + 0.5) + rw) as f32;
                // Nearer wins; of equal depths the smaller face id, as drawing in index order
                // with a strict test would give, whatever the order (see `visibility`).
                let take = (w > *z) | ((w == *z) & (w > 0.0) & (face < *id));
                let keep = 0u32.wrapping_sub(!take as u32);
                *z = f32::from_bits((w.to_bits() & !keep) | (z.to_bits() & keep));
                *id = (face & !keep) | (*id & keep);
            }
        }
    }

    /// Koch–Teller's rule: at least `min_pixels` pixels of the segment pass the depth test.
    fn segment_visible(
        &mut self,
        scene: &Occluders,
        e: &[f64; 3],
        seg: &omnitrack_core::model::Segment,
        min_pixels: u32,
    ) -> bool {
        let own_faces = seg.faces.iter().fold(0, |m, &id| m | face_bit(id));
        let pa = sub([seg.a.x, seg.a.y, seg.a.z], *e);
        let pb = sub([seg.b.x, seg.b.y, seg.b.z], *e);
        let res = self.res as f64;
        let half = 0.5 * res;
        let mut passed = 0u32;
        for f in 0..6 {
            let (a, s, ua, va) = cube_axes(f);
            let p = [pa[ua], pa[va], s * pa[a]];
            let q = [pb[ua], pb[va], s * pb[a]];
            // Clip t ∈ [0, 1] to z ≥ NEAR, |x| ≤ z, |y| ≤ z (each plane g(t) ≥ 0, g linear).
            let (mut t0, mut t1) = (0.0f64, 1.0f64);
            let planes = [
                (p[2] - NEAR, q[2] - NEAR),
                (p[2] - p[0], q[2] - q[0]),
                (p[2] + p[0], q[2] + q[0]),
                (p[2] - p[1], q[2] - q[1]),
                (p[2] + p[1], q[2] + q[1]),
            ];
            let mut empty = false;
            for (g0, g1) in planes {
                if g0 < 0.0 && g1 < 0.0 {
                    empty = true;
                    break;
                }
                if g0 < 0.0 {
                    t0 = t0.max(g0 / (g0 - g1));
                } else if g1 < 0.0 {
                    t1 = t1.min(g0 / (g0 - g1));
                }
            }
            if empty || t0 >= t1 {
                continue;
            }
            let at = |t: f64| {
                let c = [
                    p[0] + t * (q[0] - p[0]),
                    p[1] + t * (q[1] - p[1]),
                    p[2] + t * (q[2] - p[2]),
                ];
                let w = 1.0 / c[2];
                [(c[0] * w + 1.0) * half, (c[1] * w + 1.0) * half, w]
            };
            let (s0, s1) = (at(t0), at(t1));
            let steps = (s1[0] - s0[0]).abs().max((s1[1] - s0[1]).abs()).ceil().max(1.0) as usize;
            let base = f * self.res * self.res;
            let mut last = usize::MAX;
            for k in 0..=steps {
                let u = k as f64 / steps as f64;
                let x = s0[0] + u * (s1[0] - s0[0]);
                let y = s0[1] + u * (s1[1] - s0[1]);
                let w = s0[2] + u * (s1[2] - s0[2]);
                // `as usize` floors non-negative values and saturates the rest to 0, as
                // `floor().max(0.0)` would, without a libm call per sample.
                let ix = (x as usize).min(self.res - 1);
                let iy = (y as usize).min(self.res - 1);
                let pix = iy * self.res + ix;
                if pix == last {
                    continue;
                }
                // What `sample_passes` would answer `Some(false)` to, from the tile alone.
                let tile = self.tile(f, ix / TILE, iy / TILE);
                if w * (1.0 + DEPTH_TOLERANCE) < tile.min_inv_z as f64 && tile.faces & own_faces == 0 {
                    continue;
                }
                let pass = match self.sample_passes(base, ix, iy, w, &seg.faces) {
                    Some(p) => p,
                    None => {
                        // Exact: a ray from the eye to the segment's point at this sample.
                        let z = 1.0 / w;
                        let mut q = [0.0; 3];
                        q[ua] = (x / half - 1.0) * z;
                        q[va] = (y / half - 1.0) * z;
                        q[a] = s * z;
                        let dist = dot(q, q).sqrt();
                        let k = 1.0 - 1e-3 / dist.max(1e-3);
                        let eye = Point3::new(e[0], e[1], e[2]);
                        scene.clear_line(&eye, &Point3::new(e[0] + k * q[0], e[1] + k * q[1], e[2] + k * q[2]))
                    }
                };
                if pass {
                    last = pix;
                    passed += 1;
                    if passed >= min_pixels {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// The depth test of one segment sample: `Some(true)` passes, `Some(false)` fails, `None`
    /// when only an exact ray can tell (the segment is behind the surface at its own pixel but
    /// not behind the farthest surface around it: a silhouette or a grazing surface within a
    /// pixel).
    #[inline]
    fn sample_passes(&self, base: usize, ix: usize, iy: usize, w: f64, faces: &[u32]) -> Option<bool> {
        // Not farther than the surface at this pixel (1/z not smaller), 1e-3 relative.
        let i = base + iy * self.res + ix;
        if w * (1.0 + DEPTH_TOLERANCE) >= self.inv_z[i] as f64 {
            return Some(true);
        }
        // Or one of the segment's own faces is what the pixel or a neighbour shows: the segment
        // lies on its faces' borders, half a pixel from the nearest pixel centre.
        let (xa, xb) = (ix.saturating_sub(1), (ix + 1).min(self.res - 1));
        let (ya, yb) = (iy.saturating_sub(1), (iy + 1).min(self.res - 1));
        let mut min_w = f32::INFINITY;
        for y in ya..=yb {
            for x in xa..=xb {
                let j = base + y * self.res + x;
                let id = self.id[j];
                if id != u32::MAX && faces.contains(&id) {
                    return Some(true);
                }
                min_w = min_w.min(self.inv_z[j]);
            }
        }
        if w * (1.0 + DEPTH_TOLERANCE) >= min_w as f64 {
            None
        } else {
            Some(false)
        }
    }
}

/// `v.ceil()` for 0 ≤ v < 2⁵³: x86-64's baseline has no rounding instruction, and a libm call
/// per raster row was 5 % of a build.
#[inline]
fn ceil_nonneg(v: f64) -> usize {
    let t = v as usize;
    if (t as f64) < v {
        t + 1
    } else {
        t
    }
}

/// Relative depth tolerance of the segment test.
const DEPTH_TOLERANCE: f64 = 1e-3;

fn point_segment_dist2(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let t = (dot(sub(p, a), ab) / dot(ab, ab).max(1e-300)).clamp(0.0, 1.0);
    let c = [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]];
    let d = sub(p, c);
    dot(d, d)
}

/// The node grid over a model's bounds.
fn grid(model: &Model, opts: &BuildOptions) -> ([f64; 3], [u32; 3]) {
    let (lo, hi) = model.bounds().unwrap_or((Point3::origin(), Point3::origin()));
    let s = opts.spacing_m;
    let n = |a: f64, b: f64| (((b - a) / s).ceil().max(1.0)) as u32;
    let (nx, ny) = (n(lo.x, hi.x), n(lo.y, hi.y));
    // Centre the nodes: the grid spans (n·s) around the bounds' centre.
    let ox = 0.5 * (lo.x + hi.x) - 0.5 * (nx as f64 - 1.0) * s;
    let oy = 0.5 * (lo.y + hi.y) - 0.5 * (ny as f64 - 1.0) * s;
    ([ox, oy, lo.z], [nx, ny, opts.heights_m.len() as u32])
}

/// Summary of a build, for logs and the benchmark.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildStats {
    pub cells: usize,
    pub nodes: usize,
    pub seconds_nodes: f64,
    pub seconds_render: f64,
    pub mean_faces: f64,
    pub mean_segments: f64,
}

/// Builds the raw per-node sets (the table before packing); `model_path` is recorded in the
/// header. Parallel over nodes on the current rayon pool.
///
/// Panics when `spacing_m` is not positive, `heights_m` is empty or the resolution is 0
/// ([`run_build`] checks these and returns errors).
pub fn build_raw(model: &Model, model_path: &str, opts: &BuildOptions) -> (RawTable, BuildStats) {
    assert!(opts.spacing_m > 0.0 && !opts.heights_m.is_empty() && opts.cube_map_resolution > 0);
    let mut heights = opts.heights_m.clone();
    heights.sort_by(f64::total_cmp);
    let opts = &BuildOptions {
        heights_m: heights.clone(),
        ..opts.clone()
    };
    let t0 = Instant::now();
    let scene = Occluders::new(model);
    let (origin, dims) = grid(model, opts);
    let (nx, ny, nz) = (dims[0] as usize, dims[1] as usize, dims[2] as usize);
    let cells = nx * ny * nz;
    let pos = |c: usize| {
        let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
        Point3::new(
            origin[0] + i as f64 * opts.spacing_m,
            origin[1] + j as f64 * opts.spacing_m,
            origin[2] + heights[k],
        )
    };
    let valid: Vec<bool> = (0..cells)
        .into_par_iter()
        .map(|c| scene.is_free(&pos(c), opts.clearance_m))
        .collect();
    let node_cell: Vec<u32> = (0..cells).filter(|&c| valid[c]).map(|c| c as u32).collect();
    let mut cell_node = vec![NO_NODE; cells];
    for (n, &c) in node_cell.iter().enumerate() {
        cell_node[c as usize] = n as u32;
    }
    let seconds_nodes = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let bar = if opts.progress {
        let bar = indicatif::ProgressBar::with_draw_target(
            Some(node_cell.len() as u64),
            indicatif::ProgressDrawTarget::stderr(),
        );
        bar.set_style(
            indicatif::ProgressStyle::with_template("visibility {bar:40} {pos}/{len} nodes, {elapsed} (eta {eta})")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    } else {
        indicatif::ProgressBar::hidden()
    };
    let res = opts.cube_map_resolution as usize;
    let sets: Vec<(Vec<u32>, Vec<u32>)> = node_cell
        .par_iter()
        .map_init(
            || CubeMap::new(res, model.faces.len()),
            |cube, &c| {
                let r = cube.visibility(&scene, &pos(c as usize), opts);
                bar.inc(1);
                r
            },
        )
        .collect();
    let (mut node_faces, mut node_segments): (Vec<Vec<u32>>, Vec<Vec<u32>>) = sets.into_iter().unzip();

    if opts.merge == Merge::CellCorners {
        let (cx, cy) = (nx + 1, ny + 1);
        let corner_pos = |ci: usize| {
            let (i, j, k) = (ci % cx, (ci / cx) % cy, ci / (cx * cy));
            Point3::new(
                origin[0] + (i as f64 - 0.5) * opts.spacing_m,
                origin[1] + (j as f64 - 0.5) * opts.spacing_m,
                origin[2] + heights[k],
            )
        };
        let corners_of = |c: usize| {
            let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
            [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(a, b)| (k * cy + j + b) * cx + i + a)
        };
        let mut needed = vec![false; cx * cy * nz];
        for &c in &node_cell {
            for ci in corners_of(c as usize) {
                needed[ci] = true;
            }
        }
        let wanted: Vec<usize> = (0..needed.len()).filter(|&ci| needed[ci]).collect();
        let free: Vec<bool> = wanted
            .par_iter()
            .map(|&ci| scene.is_free(&corner_pos(ci), opts.clearance_m))
            .collect();
        let rendered: Vec<usize> = wanted
            .iter()
            .zip(&free)
            .filter(|(_, &f)| f)
            .map(|(&ci, _)| ci)
            .collect();
        bar.set_length((node_cell.len() + rendered.len()) as u64);
        let corner_sets: Vec<(Vec<u32>, Vec<u32>)> = rendered
            .par_iter()
            .map_init(
                || CubeMap::new(res, model.faces.len()),
                |cube, &ci| {
                    let r = cube.visibility(&scene, &corner_pos(ci), opts);
                    bar.inc(1);
                    r
                },
            )
            .collect();
        let mut corner_set = vec![NO_NODE; cx * cy * nz];
        for (k, &ci) in rendered.iter().enumerate() {
            corner_set[ci] = k as u32;
        }
        let merged: Vec<(Vec<u32>, Vec<u32>)> = node_cell
            .par_iter()
            .enumerate()
            .map_init(
                || CubeMap::new(res, model.faces.len()),
                |cube, (n, &c)| {
                    let here = pos(c as usize);
                    let mut f = node_faces[n].clone();
                    let mut s = node_segments[n].clone();
                    for ci in corners_of(c as usize) {
                        let corner = corner_pos(ci);
                        if corner_set[ci] != NO_NODE && scene.clear_line(&here, &corner) {
                            let (cf, cs) = &corner_sets[corner_set[ci] as usize];
                            f.extend_from_slice(cf);
                            s.extend_from_slice(cs);
                            continue;
                        }
                        let half = here + 0.5 * (corner - here);
                        if scene.is_free(&half, opts.clearance_m) && scene.clear_line(&here, &half) {
                            let (cf, cs) = cube.visibility(&scene, &half, opts);
                            f.extend(cf);
                            s.extend(cs);
                        }
                    }
                    f.sort_unstable();
                    f.dedup();
                    s.sort_unstable();
                    s.dedup();
                    (f, s)
                },
            )
            .collect();
        (node_faces, node_segments) = merged.into_iter().unzip();
    }
    if opts.merge == Merge::Neighbours {
        let merged: Vec<(Vec<u32>, Vec<u32>)> = node_cell
            .par_iter()
            .map(|&c| {
                let c = c as usize;
                let (i, j, k) = ((c % nx) as i64, ((c / nx) % ny) as i64, (c / (nx * ny)) as i64);
                let me = cell_node[c] as usize;
                let mut f = node_faces[me].clone();
                let mut s = node_segments[me].clone();
                let here = pos(c);
                for (di, dj, dk) in [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)] {
                    let (a, b, d) = (i + di, j + dj, k + dk);
                    if a < 0 || b < 0 || d < 0 || a >= nx as i64 || b >= ny as i64 || d >= nz as i64 {
                        continue;
                    }
                    let nc = (d as usize * ny + b as usize) * nx + a as usize;
                    let other = cell_node[nc];
                    if other == NO_NODE || !scene.clear_line(&here, &pos(nc)) {
                        continue;
                    }
                    f.extend_from_slice(&node_faces[other as usize]);
                    s.extend_from_slice(&node_segments[other as usize]);
                }
                f.sort_unstable();
                f.dedup();
                s.sort_unstable();
                s.dedup();
                (f, s)
            })
            .collect();
        (node_faces, node_segments) = merged.into_iter().unzip();
    }
    bar.finish_and_clear();
    let seconds_render = t1.elapsed().as_secs_f64();

    // Every lookup cell (node cells split `m × m` in x, y): the nearest valid node in line of
    // sight of its centre among the node cells within two cells; else the nearest of those; else
    // the nearest valid node (rings of growing Chebyshev radius over all layers, stopping once
    // the ring is farther than the best so far).
    let column_has_node: Vec<bool> = (0..nx * ny)
        .map(|col| (0..nz).any(|k| cell_node[k * nx * ny + col] != NO_NODE))
        .collect();
    let column_distance = chessboard_distance(&column_has_node, nx, ny);
    let m = LOOKUP_SUBDIVISIONS;
    let (lx, ly) = (nx * m, ny * m);
    let nearest: Vec<u32> = (0..lx * ly * nz)
        .into_par_iter()
        .map(|lc| {
            if node_cell.is_empty() {
                return NO_NODE;
            }
            let (li, lj, k) = (lc % lx, (lc / lx) % ly, lc / (lx * ly));
            let p = Point3::new(
                origin[0] - 0.5 * opts.spacing_m + (li as f64 + 0.5) * opts.spacing_m / m as f64,
                origin[1] - 0.5 * opts.spacing_m + (lj as f64 + 0.5) * opts.spacing_m / m as f64,
                origin[2] + heights[k],
            );
            let (i, j) = ((li / m) as i64, (lj / m) as i64);
            let mut near: Vec<(f64, u32, usize)> = Vec::new();
            for b in (j - 2)..=(j + 2) {
                for a in (i - 2)..=(i + 2) {
                    if a < 0 || b < 0 || a >= nx as i64 || b >= ny as i64 {
                        continue;
                    }
                    for kk in 0..nz {
                        let nc = (kk * ny + b as usize) * nx + a as usize;
                        if cell_node[nc] != NO_NODE {
                            near.push(((pos(nc) - p).norm_squared(), cell_node[nc], nc));
                        }
                    }
                }
            }
            near.sort_by(|x, y| x.0.total_cmp(&y.0));
            for &(_, n, nc) in &near {
                if scene.clear_line(&p, &pos(nc)) {
                    return n;
                }
            }
            if let Some(&(_, n, _)) = near.first() {
                return n;
            }
            let mut best = (f64::INFINITY, NO_NODE);
            // Rings nearer than the nearest column with a node are empty: start at it. A ring is
            // walked in the order of its bounding square (rows up, columns along), so that ties
            // go to the same node as a scan of the whole square would give them.
            let start = i64::from(column_distance[j as usize * nx + i as usize].max(1));
            for r in start..=(nx.max(ny) as i64) {
                if (r as f64 - 2.0) * opts.spacing_m > best.0.sqrt() {
                    break;
                }
                for b in (j - r)..=(j + r) {
                    if b < 0 || b >= ny as i64 {
                        continue;
                    }
                    let step = if (b - j).abs() == r { 1 } else { 2 * r };
                    for a in ((i - r)..=(i + r)).step_by(step as usize) {
                        if a < 0 || a >= nx as i64 || !column_has_node[b as usize * nx + a as usize] {
                            continue;
                        }
                        for kk in 0..nz {
                            let nc = (kk * ny + b as usize) * nx + a as usize;
                            if cell_node[nc] != NO_NODE {
                                let d2 = (pos(nc) - p).norm_squared();
                                if d2 < best.0 {
                                    best = (d2, cell_node[nc]);
                                }
                            }
                        }
                    }
                }
            }
            best.1
        })
        .collect();

    let n = node_cell.len().max(1) as f64;
    let stats = BuildStats {
        cells,
        nodes: node_cell.len(),
        seconds_nodes,
        seconds_render,
        mean_faces: node_faces.iter().map(Vec::len).sum::<usize>() as f64 / n,
        mean_segments: node_segments.iter().map(Vec::len).sum::<usize>() as f64 / n,
    };
    let header = TableHeader {
        format_version: FORMAT_VERSION,
        model_hash: super::model_hash(model),
        model_path: model_path.to_string(),
        vertex_count: model.vertices.len() as u32,
        face_count: model.faces.len() as u32,
        segment_count: model.segments.len() as u32,
        origin,
        dims,
        spacing_m: opts.spacing_m,
        heights_m: heights,
        cube_map_resolution: opts.cube_map_resolution,
        min_visible_pixels: opts.min_visible_pixels,
        max_range_m: opts.max_range_m,
        merge: opts.merge.code(),
        node_count: node_cell.len() as u32,
        lookup_subdivisions: m as u32,
        clearance_m: opts.clearance_m,
        min_segment_length_m: opts.min_segment_length_m,
    };
    let raw = RawTable {
        header,
        cell_node: nearest,
        node_cell,
        node_faces,
        node_segments,
        segment_vertices: segment_vertex_ids(model),
    };
    (raw, stats)
}

/// Per cell of an `nx × ny` grid, the chessboard (Chebyshev) distance in cells to the nearest
/// `true` cell (`u32::MAX / 2` when there is none): two chamfer passes with unit steps to all
/// eight neighbours, which is exact for this metric.
fn chessboard_distance(set: &[bool], nx: usize, ny: usize) -> Vec<u32> {
    const FAR: u32 = u32::MAX / 2;
    let mut d: Vec<u32> = set.iter().map(|&s| if s { 0 } else { FAR }).collect();
    let at = |d: &[u32], i: i64, j: i64| {
        if i < 0 || j < 0 || i >= nx as i64 || j >= ny as i64 {
            FAR
        } else {
            d[j as usize * nx + i as usize]
        }
    };
    for j in 0..ny as i64 {
        for i in 0..nx as i64 {
            let n = [
                at(&d, i - 1, j),
                at(&d, i - 1, j - 1),
                at(&d, i, j - 1),
                at(&d, i + 1, j - 1),
            ];
            let c = j as usize * nx + i as usize;
            d[c] = d[c].min(n.iter().min().map_or(FAR, |&v| v.saturating_add(1)));
        }
    }
    for j in (0..ny as i64).rev() {
        for i in (0..nx as i64).rev() {
            let n = [
                at(&d, i + 1, j),
                at(&d, i + 1, j + 1),
                at(&d, i, j + 1),
                at(&d, i - 1, j + 1),
            ];
            let c = j as usize * nx + i as usize;
            d[c] = d[c].min(n.iter().min().map_or(FAR, |&v| v.saturating_add(1)));
        }
    }
    d
}

/// Builds a packed table.
pub fn build_table(model: &Model, model_path: &str, opts: &BuildOptions) -> VisibilityTable {
    VisibilityTable::from_raw(build_raw(model, model_path, opts).0)
}

/// `omnitrack visibility build --model M --out V [--spacing-m S]`: loads the model, builds the
/// table with `config` (spacing overridden by `spacing_m`), with a progress bar on standard
/// error, and writes it. Returns the one-line summary to log.
pub fn run_build(
    model_path: &Path,
    out: &Path,
    spacing_m: Option<f64>,
    config: &VisibilityConfig,
) -> Result<String, super::VisibilityError> {
    let model = Model::load(model_path).map_err(|e| super::VisibilityError::Invalid {
        file: model_path.display().to_string(),
        message: format!("cannot use model: {}", e.message),
    })?;
    if model.faces.is_empty() {
        return Err(super::VisibilityError::Invalid {
            file: model_path.display().to_string(),
            message: "model has no faces: nothing to build a visibility table from".into(),
        });
    }
    let mut opts = BuildOptions::from_config(config);
    if let Some(s) = spacing_m {
        if !(s.is_finite() && s > 0.0) {
            return Err(super::VisibilityError::Invalid {
                file: out.display().to_string(),
                message: format!("--spacing-m {s} must be a positive number of metres"),
            });
        }
        opts.spacing_m = s;
    }
    if opts.heights_m.is_empty() || opts.cube_map_resolution == 0 {
        return Err(super::VisibilityError::Invalid {
            file: out.display().to_string(),
            message: "[visibility] needs node_heights_m and a cube_map_resolution > 0".into(),
        });
    }
    opts.progress = true;
    let recorded = std::fs::canonicalize(model_path).unwrap_or_else(|_| model_path.to_path_buf());
    let start = Instant::now();
    let (raw, stats) = build_raw(&model, &recorded.display().to_string(), &opts);
    let table = VisibilityTable::from_raw(raw);
    table.save(out)?;
    let bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    Ok(format!(
        "{}: {} valid nodes of {} grid cells, {:.0} faces and {:.0} segments visible per node on average, {} distinct sets, {:.1} MB, built in {:.1} s",
        out.display(),
        stats.nodes,
        stats.cells,
        stats.mean_faces,
        stats.mean_segments,
        table.set_count(),
        bytes as f64 / 1e6,
        start.elapsed().as_secs_f64()
    ))
}
