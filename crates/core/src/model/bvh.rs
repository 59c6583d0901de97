//! Bounding-volume hierarchy over axis-aligned boxes (binned SAH, flattened nodes) and the
//! ray–triangle test the renderer uses with it.
//!
//! In: the bounds of N primitives. Out: a [`Bvh`] whose leaves list primitives by *slot*: the
//! primitive at slot `s` is `order[s]` of the input, so a caller that permutes its primitive
//! array by [`Bvh::order`] finds each leaf's primitives contiguous.

// Three-vectors read most clearly with an axis index.
#![allow(clippy::needless_range_loop)]

/// A ray in single precision: origin, direction (need not be unit; `t` is in its units) and the
/// reciprocal direction for slab tests.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    pub origin: [f32; 3],
    pub dir: [f32; 3],
    pub inv_dir: [f32; 3],
}

impl Ray {
    pub fn new(origin: [f32; 3], dir: [f32; 3]) -> Ray {
        Ray {
            origin,
            dir,
            inv_dir: [1.0 / dir[0], 1.0 / dir[1], 1.0 / dir[2]],
        }
    }
    pub fn at(&self, t: f32) -> [f32; 3] {
        [
            self.origin[0] + t * self.dir[0],
            self.origin[1] + t * self.dir[1],
            self.origin[2] + t * self.dir[2],
        ]
    }
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    pub fn of_points(points: &[[f32; 3]]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in points {
            b.grow_point(p);
        }
        b
    }
    pub fn grow_point(&mut self, p: &[f32; 3]) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(p[k]);
            self.max[k] = self.max[k].max(p[k]);
        }
    }
    pub fn grow(&mut self, o: &Aabb) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(o.min[k]);
            self.max[k] = self.max[k].max(o.max[k]);
        }
    }
    pub fn centre(&self, k: usize) -> f32 {
        0.5 * (self.min[k] + self.max[k])
    }
    pub fn half_area(&self) -> f32 {
        let d = [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ];
        if d[0] < 0.0 {
            return 0.0;
        }
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
    /// Entry distance of the ray into the box if it enters before `t_max`.
    #[inline]
    pub fn hit(&self, ray: &Ray, t_max: f32) -> Option<f32> {
        let mut t0 = 0.0f32;
        let mut t1 = t_max;
        for k in 0..3 {
            let a = (self.min[k] - ray.origin[k]) * ray.inv_dir[k];
            let b = (self.max[k] - ray.origin[k]) * ray.inv_dir[k];
            // min/max with NaN (0 × ∞) pick the other operand, so a ray lying in a slab plane
            // keeps its interval.
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1).then_some(t0)
    }
}

/// One node of the flattened tree: a leaf when `count > 0` (primitive slots `first..first+count`),
/// else an interior node whose children are `first` and `first + 1`.
#[derive(Debug, Clone, Copy)]
pub struct Node {
    pub bounds: Aabb,
    pub first: u32,
    pub count: u32,
}

/// A bounding-volume hierarchy; node 0 is the root.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    pub nodes: Vec<Node>,
    /// Slot → input primitive index.
    pub order: Vec<u32>,
}

const BINS: usize = 12;
const MAX_LEAF: usize = 4;

impl Bvh {
    /// Builds the tree with binned surface-area heuristic splits on primitive centroids.
    pub fn build(bounds: &[Aabb]) -> Bvh {
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * bounds.len().max(1)),
            order: (0..bounds.len() as u32).collect(),
        };
        if bounds.is_empty() {
            return bvh;
        }
        let centroids: Vec<[f32; 3]> = bounds.iter().map(|b| [b.centre(0), b.centre(1), b.centre(2)]).collect();
        bvh.nodes.push(Node {
            bounds: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        // Explicit stack of (node index, slot range).
        let mut stack = vec![(0usize, 0usize, bounds.len())];
        while let Some((node, lo, hi)) = stack.pop() {
            let mut nb = Aabb::EMPTY;
            let mut cb = Aabb::EMPTY;
            for &p in &bvh.order[lo..hi] {
                nb.grow(&bounds[p as usize]);
                cb.grow_point(&centroids[p as usize]);
            }
            bvh.nodes[node].bounds = nb;
            let n = hi - lo;
            let leaf = |bvh: &mut Bvh| {
                bvh.nodes[node].first = lo as u32;
                bvh.nodes[node].count = n as u32;
            };
            if n <= MAX_LEAF {
                leaf(&mut bvh);
                continue;
            }
            // Best split over the three axes.
            let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, first bin on the right)
            for axis in 0..3 {
                let (cmin, cmax) = (cb.min[axis], cb.max[axis]);
                let extent = cmax - cmin;
                if extent.is_nan() || extent <= 0.0 {
                    continue;
                }
                let mut counts = [0usize; BINS];
                let mut boxes = [Aabb::EMPTY; BINS];
                let scale = BINS as f32 / extent;
                for &p in &bvh.order[lo..hi] {
                    let b = (((centroids[p as usize][axis] - cmin) * scale) as usize).min(BINS - 1);
                    counts[b] += 1;
                    boxes[b].grow(&bounds[p as usize]);
                }
                // Sweep: left sums from the front, right sums from the back.
                let mut right_area = [0.0f32; BINS];
                let mut right_count = [0usize; BINS];
                let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
                for b in (1..BINS).rev() {
                    acc.grow(&boxes[b]);
                    cnt += counts[b];
                    right_area[b] = acc.half_area();
                    right_count[b] = cnt;
                }
                let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
                for b in 0..BINS - 1 {
                    acc.grow(&boxes[b]);
                    cnt += counts[b];
                    if cnt == 0 || right_count[b + 1] == 0 {
                        continue;
                    }
                    let cost = acc.half_area() * cnt as f32 + right_area[b + 1] * right_count[b + 1] as f32;
                    if best.is_none_or(|(c, _, _)| cost < c) {
                        best = Some((cost, axis, b + 1));
                    }
                }
            }
            let leaf_cost = nb.half_area() * n as f32;
            let split = match best {
                Some((cost, axis, bin)) if cost < leaf_cost || n > 4 * MAX_LEAF => Some((axis, bin)),
                _ => None,
            };
            // No split: all centroids coincide (or a leaf is cheaper).
            let Some((axis, split_bin)) = split else {
                leaf(&mut bvh);
                continue;
            };
            // Partition slots by bin (same arithmetic as the binning).
            let (cmin, extent) = (cb.min[axis], cb.max[axis] - cb.min[axis]);
            let scale = BINS as f32 / extent;
            let slice = &mut bvh.order[lo..hi];
            let mut i = 0;
            let mut j = slice.len();
            while i < j {
                let b = (((centroids[slice[i] as usize][axis] - cmin) * scale) as usize).min(BINS - 1);
                if b < split_bin {
                    i += 1;
                } else {
                    j -= 1;
                    slice.swap(i, j);
                }
            }
            let mid = if i == 0 || i == slice.len() { slice.len() / 2 } else { i };
            let left = bvh.nodes.len();
            bvh.nodes.push(Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            });
            bvh.nodes.push(Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            });
            bvh.nodes[node].first = left as u32;
            bvh.nodes[node].count = 0;
            stack.push((left + 1, lo + mid, hi));
            stack.push((left, lo, lo + mid));
        }
        bvh
    }

    /// Whether `test(slot)` holds for any primitive whose box the ray meets before `t_max`: an
    /// occlusion query, which stops at the first hit instead of looking for the closest.
    #[inline]
    pub fn any(&self, ray: &Ray, t_max: f32, mut test: impl FnMut(u32) -> bool) -> bool {
        if self.nodes.is_empty() || self.nodes[0].bounds.hit(ray, t_max).is_none() {
            return false;
        }
        let mut stack = [0u32; 128];
        let mut sp = 0usize;
        let mut node = 0usize;
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                if (n.first..n.first + n.count).any(&mut test) {
                    return true;
                }
            } else {
                let (l, r) = (n.first as usize, n.first as usize + 1);
                let hl = self.nodes[l].bounds.hit(ray, t_max).is_some();
                let hr = self.nodes[r].bounds.hit(ray, t_max).is_some();
                match (hl, hr) {
                    (true, true) => {
                        if sp < stack.len() {
                            stack[sp] = r as u32;
                            sp += 1;
                        }
                        node = l;
                        continue;
                    }
                    (true, false) => {
                        node = l;
                        continue;
                    }
                    (false, true) => {
                        node = r;
                        continue;
                    }
                    (false, false) => {}
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            node = stack[sp] as usize;
        }
    }

    /// Closest hit before `t_max`: `test(slot, t_best)` returns the primitive's hit distance if
    /// it is hit before `t_best`. Returns (slot, t).
    #[inline]
    pub fn closest(&self, ray: &Ray, t_max: f32, mut test: impl FnMut(u32, f32) -> Option<f32>) -> Option<(u32, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: Option<(u32, f32)> = None;
        let mut t_best = t_max;
        let mut stack = [0u32; 128];
        let mut sp = 0usize;
        self.nodes[0].bounds.hit(ray, t_best)?;
        let mut node = 0usize;
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                for slot in n.first..n.first + n.count {
                    if let Some(t) = test(slot, t_best) {
                        if t < t_best {
                            t_best = t;
                            best = Some((slot, t));
                        }
                    }
                }
            } else {
                let (l, r) = (n.first as usize, n.first as usize + 1);
                let hl = self.nodes[l].bounds.hit(ray, t_best);
                let hr = self.nodes[r].bounds.hit(ray, t_best);
                match (hl, hr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b { (l, r) } else { (r, l) };
                        if sp < stack.len() {
                            stack[sp] = far as u32;
                            sp += 1;
                        }
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop, skipping nodes that can no longer beat the best hit.
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                let cand = stack[sp] as usize;
                if self.nodes[cand].bounds.hit(ray, t_best).is_some() {
                    node = cand;
                    break;
                }
            }
        }
    }
}

/// A triangle ready for intersection: vertex `p0` and edges `e1 = p1 − p0`, `e2 = p2 − p0`.
#[derive(Debug, Clone, Copy)]
pub struct Triangle {
    pub p0: [f32; 3],
    pub e1: [f32; 3],
    pub e2: [f32; 3],
}

#[inline]
fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Barycentric slack so that rays through a shared edge never slip between its two triangles.
const EDGE_SLACK: f32 = 1e-6;
/// A hit this far (barycentric) inside a triangle's edges is one no box holding the triangle
/// can miss by rounding ([`TriangleBvh::occludes_inside`]); rays nearer an edge are left to a
/// traversal.
pub const OCCLUDER_MARGIN: f32 = 1e-3;

impl Triangle {
    pub fn new(p0: [f32; 3], p1: [f32; 3], p2: [f32; 3]) -> Triangle {
        Triangle {
            p0,
            e1: sub(p1, p0),
            e2: sub(p2, p0),
        }
    }
    pub fn vertices(&self) -> [[f32; 3]; 3] {
        let p = self.p0;
        [
            p,
            [p[0] + self.e1[0], p[1] + self.e1[1], p[2] + self.e1[2]],
            [p[0] + self.e2[0], p[1] + self.e2[1], p[2] + self.e2[2]],
        ]
    }
    pub fn bounds(&self) -> Aabb {
        Aabb::of_points(&self.vertices())
    }
    /// Twice the area.
    pub fn area2(&self) -> f32 {
        let c = cross(self.e1, self.e2);
        dot(c, c).sqrt()
    }
    /// Möller–Trumbore, two-sided: the hit distance in `(t_min, t_max)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<f32> {
        self.intersect_within(ray, t_min, t_max, EDGE_SLACK)
    }

    /// [`Self::intersect`] where the hit must lie at least `margin` (barycentric) inside every
    /// edge: such a hit lies well inside the triangle's box and every box holding it, so a
    /// traversal of a BVH that holds the triangle finds it too.
    #[inline]
    pub fn intersect_inside(&self, ray: &Ray, t_min: f32, t_max: f32, margin: f32) -> Option<f32> {
        self.intersect_within(ray, t_min, t_max, -margin)
    }

    /// Möller–Trumbore with the barycentric bounds widened by `slack` (narrowed when negative).
    #[inline]
    fn intersect_within(&self, ray: &Ray, t_min: f32, t_max: f32, slack: f32) -> Option<f32> {
        let p = cross(ray.dir, self.e2);
        let det = dot(self.e1, p);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let s = sub(ray.origin, self.p0);
        let u = dot(s, p) * inv;
        if !(-slack..=1.0 + slack).contains(&u) {
            return None;
        }
        let q = cross(s, self.e1);
        let v = dot(ray.dir, q) * inv;
        if v < -slack || u + v > 1.0 + slack {
            return None;
        }
        let t = dot(self.e2, q) * inv;
        (t > t_min && t < t_max).then_some(t)
    }
}

/// Closest triangle hit by testing every triangle (the reference the BVH must agree with).
pub fn brute_force_closest(tris: &[Triangle], ray: &Ray, t_min: f32, t_max: f32) -> Option<(u32, f32)> {
    let mut best = None;
    let mut t_best = t_max;
    for (i, tri) in tris.iter().enumerate() {
        if let Some(t) = tri.intersect(ray, t_min, t_best) {
            t_best = t;
            best = Some((i as u32, t));
        }
    }
    best
}

/// A BVH over triangles stored in leaf order, with each triangle's payload (an index the
/// caller chooses, e.g. its surface or its input number).
#[derive(Debug, Clone, Default)]
pub struct TriangleBvh {
    pub bvh: Bvh,
    /// In slot order.
    pub triangles: Vec<Triangle>,
    /// In slot order.
    pub payload: Vec<u32>,
}

impl TriangleBvh {
    pub fn build(triangles: &[Triangle], payload: &[u32]) -> TriangleBvh {
        assert_eq!(triangles.len(), payload.len());
        let bounds: Vec<Aabb> = triangles.iter().map(Triangle::bounds).collect();
        let bvh = Bvh::build(&bounds);
        let tris = bvh.order.iter().map(|&i| triangles[i as usize]).collect();
        let pay = bvh.order.iter().map(|&i| payload[i as usize]).collect();
        TriangleBvh {
            bvh,
            triangles: tris,
            payload: pay,
        }
    }

    /// Whether any triangle is hit in `(t_min, t_max)`.
    #[inline]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.occluder(ray, t_min, t_max).is_some()
    }

    /// The slot of a triangle hit in `(t_min, t_max)`, if any: the first one found, not the
    /// closest. A caller casting many rays past the same wall tries it first
    /// ([`Self::occludes_inside`]).
    #[inline]
    pub fn occluder(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<u32> {
        let mut found = None;
        self.bvh.any(ray, t_max, |slot| {
            let hit = self.triangles[slot as usize].intersect(ray, t_min, t_max).is_some();
            if hit {
                found = Some(slot);
            }
            hit
        });
        found
    }

    /// Whether the triangle in `slot` is hit in `(t_min, t_max)` at least
    /// [`OCCLUDER_MARGIN`] inside its edges ([`Triangle::intersect_inside`]): then
    /// [`Self::occluded`] holds too, without a traversal. `false` says nothing.
    #[inline]
    pub fn occludes_inside(&self, slot: u32, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.triangles
            .get(slot as usize)
            .is_some_and(|t| t.intersect_inside(ray, t_min, t_max, OCCLUDER_MARGIN).is_some())
    }

    /// Closest hit in `(t_min, t_max)`: (payload, t).
    #[inline]
    pub fn closest(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(u32, f32)> {
        self.bvh
            .closest(ray, t_max, |slot, t_best| {
                self.triangles[slot as usize].intersect(ray, t_min, t_best)
            })
            .map(|(slot, t)| (self.payload[slot as usize], t))
    }
}

/// All triangles of a model as the renderer builds them (ear-clipped faces, degenerate ones
/// dropped), with the index of the face each came from.
pub fn model_triangles(model: &super::Model) -> Vec<(Triangle, u32)> {
    let mut out = Vec::new();
    for (fi, face) in model.faces.iter().enumerate() {
        let corners: Vec<nalgebra::Point3<f64>> = face.vertices.iter().map(|&v| model.vertices[v as usize]).collect();
        for t in super::triangulate::triangulate_polygon(&corners, &face.normal) {
            let p = |i: usize| [corners[i].x as f32, corners[i].y as f32, corners[i].z as f32];
            let tri = Triangle::new(p(t[0]), p(t[1]), p(t[2]));
            if tri.area2() > 1e-10 {
                out.push((tri, fi as u32));
            }
        }
    }
    out
}
