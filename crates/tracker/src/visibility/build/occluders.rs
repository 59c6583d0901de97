//! The model's faces as occluders, shared read-only by every node's work: triangles in f64, a
//! BVH for exact rays, x-y bins for what lies near a position, and the node validity test
//! (the parent module's doc, "Valid nodes": the 26 stencil rays and the clearance).
//!
//! In: a [`Model`]. Out: [`Occluders`], which answers rays (`cast`), lines of sight
//! (`clear_line`), free space (`is_free`) and the triangles and segments near a point.

use nalgebra::{Point3, Vector3};
use omnitrack_core::model::bvh::{Ray, Triangle, TriangleBvh};
use omnitrack_core::model::triangulate::triangulate_polygon;
use omnitrack_core::model::Model;

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

/// A model triangle in f64 with its face.
#[derive(Debug, Clone, Copy)]
pub(super) struct Tri {
    pub(super) p: [[f64; 3]; 3],
    pub(super) face: u32,
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
pub(super) struct Bins {
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
    pub(super) fn new(boxes: &[([f64; 3], [f64; 3])]) -> Bins {
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
    pub(super) fn cells(&self, lo: [f64; 2], hi: [f64; 2]) -> [u32; 4] {
        let at = |v: f64, k: usize| {
            (((v - self.origin[k]) / self.cell).floor().max(0.0) as usize).min(self.dims[k] - 1) as u32
        };
        [at(lo[0], 0), at(lo[1], 1), at(hi[0], 0), at(hi[1], 1)]
    }

    /// Puts in `out`, once each and in no particular order, the items whose boxes reach cells
    /// within `r` of `p` in x and y (a superset of those within `r`; callers test exactly).
    pub(super) fn near(&self, p: [f64; 3], r: f64, out: &mut Vec<u32>) {
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
    pub(super) model: &'m Model,
    pub(super) tris: Vec<Tri>,
    /// Per triangle: bounding box min, max.
    pub(super) boxes: Vec<([f64; 3], [f64; 3])>,
    bvh: TriangleBvh,
    pub(super) tri_bins: Bins,
    pub(super) segment_bins: Bins,
}

impl<'m> Occluders<'m> {
    /// Bytes its buffers hold on the heap (for a build's memory estimate).
    pub fn heap_bytes(&self) -> usize {
        fn bytes<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        let bins = |b: &Bins| bytes(&b.start) + bytes(&b.items) + bytes(&b.ranges);
        bytes(&self.tris)
            + bytes(&self.boxes)
            + bytes(&self.bvh.bvh.nodes)
            + bytes(&self.bvh.bvh.order)
            + bytes(&self.bvh.triangles)
            + bytes(&self.bvh.payload)
            + bins(&self.tri_bins)
            + bins(&self.segment_bins)
    }

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
pub(super) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub(super) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
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
pub(super) fn box_dist2(c: &[f64; 3], lo: &[f64; 3], hi: &[f64; 3]) -> f64 {
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

thread_local! {
    /// Scratch of [`Occluders::is_free`]'s clearance test, one per worker thread.
    static NEAR_SCRATCH: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
}
