//! One worker's cube map around a node: the six faces rasterised exactly (face ids and
//! perspective-correct 1/z, near-plane clipping, hierarchical depth per 8 × 8 tile) and the
//! segment test of Koch–Teller Figure 9 with our sample rules (the parent module's doc, "Per
//! valid node").
//!
//! In: the [`Occluders`], a node position, [`BuildOptions`]. Out: the ids of the faces and the
//! segments visible from the node. All buffers are the worker's, reused node after node.

use super::occluders::{box_dist2, dot, sub, Occluders};
use super::BuildOptions;
use nalgebra::{Point3, Vector3};

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

impl CubeMap {
    /// Bytes its buffers hold on the heap now (for a build's memory estimate).
    pub fn heap_bytes(&self) -> usize {
        fn bytes<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        bytes(&self.inv_z)
            + bytes(&self.id)
            + bytes(&self.face_stamp)
            + bytes(&self.poly)
            + bytes(&self.clipped)
            + bytes(&self.near)
            + bytes(&self.tiles)
            + bytes(&self.depth_min)
            + bytes(&self.depth_dirty)
            + bytes(&self.order)
    }

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
