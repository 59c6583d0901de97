//! VIS(T) refined at the pose itself (beyond the paper).
//!
//! In: a position T, the [`Model`], its [`VisibilityTable`]. Out: the segments seen from T, each
//! with the fraction of it in sight and which of its sampled points are ([`PoseVisibility::at`],
//! [`sample_point`]): a caller that knows the rig's rotation can keep the points its sensors
//! image (`omnitrack_core::rig::ViewMap`).
//!
//! **Why.** Koch & Teller serve every position from the set of the node nearest it, rendered at
//! the node (§4.3). With nodes a metre apart that set is seen from up to 0.7 m away, and where
//! that crosses a wall it is another room's: in a closet, a bathroom or a hallway narrower than
//! the node spacing, the serving node stands outside, its set predicts the other side of the wall
//! and misses the walls around the rig. Scoring a candidate pose against such a set penalises
//! the truth for lines it cannot see (measured on the real ZInD tour: the search's first
//! candidate was the truth for 19 of 32 panoramas with the nodes' sets, 24 with nodes four times
//! as dense).
//!
//! **How.** The candidates are the union of the sets of the nodes serving T and the 26 positions
//! a node spacing away around it (in x, y and z), so every segment a nearby node sees is tried.
//! Each is sampled at [`SAMPLES`] points spread along it; a point is in sight when the ray from T
//! to it meets no face of the model before it (the last `END_SLACK_M` excepted: the point lies
//! on its own faces' borders). The fraction in sight is the share of sampled points in sight;
//! segments with none are dropped.
//!
//! Fixed memory: the model's triangles in a BVH and per-segment buffers are built in
//! [`PoseVisibility::new`]; [`PoseVisibility::at`] allocates nothing. Its time is bounded by
//! [`SAMPLES`] occlusion rays per candidate segment, and the answer for the last position is
//! kept, so asking again at the same place costs nothing. A thread that ranks segments from a
//! shared value ([`PoseVisibility::widest_with`]) brings its own [`SightBuffers`], sized as
//! the value's own.

use super::VisibilityTable;
use nalgebra::Point3;
use omnitrack_core::memory::resident;
use omnitrack_core::model::bvh::{model_triangles, Ray, TriangleBvh};
use omnitrack_core::model::Model;

/// Points sampled along each segment.
pub const SAMPLES: usize = 8;
const _: () = assert!(SAMPLES <= 8, "a SeenSegment mask holds one bit per sample");
/// A ray to a sampled point may meet faces this close before the point without hiding it (m):
/// the point lies on the border of the faces that make the segment.
const END_SLACK_M: f64 = 0.02;
/// A query this close to the last one (m) is answered with the last one's segments: the
/// polish and the climbs ask again after every step of a few centimetres, and what a few
/// centimetres change (a segment grazing an occluder's edge gaining or losing one of its
/// [`SAMPLES`] points) does not move a score.
pub const REUSE_M: f64 = 0.05;
/// Rays start this far from T (m), clear of a face T might touch.
const START_SLACK_M: f32 = 1e-3;
/// A ray tried against the last occluder costs this fraction of a traversal of the model's BVH
/// ([`PoseVisibility::rays_cast`] counts it so): on FZK-Haus (13,340 triangles) 16.5 million
/// rays from 4,576 grid positions took 11–16 s as traversals, and 2.3–2.9 s tried against the
/// last occluder first, 1.8 million of them traversing (load 4.5; the positions' gathering
/// 0.3–0.5 s of either).
pub const TRIED_PER_TRAVERSAL: u64 = 10;

/// A segment of the model seen from a position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeenSegment {
    /// Index into `Model::segments`.
    pub segment: u32,
    /// Share of the segment in sight, in (0, 1].
    pub fraction: f32,
    /// Which of the [`SAMPLES`] points along it ([`sample_point`]) are in sight: bit k for
    /// point k.
    pub mask: u8,
}

/// The `k`-th of the [`SAMPLES`] points sampled along the segment a–b (k < [`SAMPLES`]).
#[inline]
pub fn sample_point(a: &Point3<f64>, b: &Point3<f64>, k: usize) -> Point3<f64> {
    a + (b - a) * ((k as f64 + 0.5) / SAMPLES as f64)
}

/// Exact visibility of the model's segments from any position, by ray casting.
pub struct PoseVisibility {
    bvh: TriangleBvh,
    /// The buffers of this value's own queries.
    own: SightBuffers,
    seen: Vec<SeenSegment>,
    /// Where `seen` was computed (`None`: not yet).
    last: Option<Point3<f64>>,
}

/// The buffers one query of [`PoseVisibility::widest_with`] works in, apart from the model's
/// triangles: threads that query one [`PoseVisibility`] at once each bring their own (sized
/// once, like the rest).
pub struct SightBuffers {
    /// Per segment: the query that last took it as a candidate.
    stamp: Vec<u32>,
    query: u32,
    /// The candidates of a query: (the angle the whole segment spans, index).
    ranked: Vec<(f64, u32)>,
    rays: Rays,
}

/// The occlusion rays of a [`SightBuffers`]' queries.
#[derive(Debug, Default)]
struct Rays {
    /// Rays cast that traversed the model's BVH: what a caller charges for a query.
    cast: u64,
    /// The slot of the triangle that hid the last hidden point: the next ray tries it first.
    occluder: Option<u32>,
    /// Rays tried, with or without a traversal.
    tried: u64,
}

impl Rays {
    /// The rays' cost in traversals ([`PoseVisibility::rays_cast`]).
    fn cost(&self) -> u64 {
        self.cast + self.tried / TRIED_PER_TRAVERSAL
    }
}

impl SightBuffers {
    /// Room for all of `model`'s segments.
    pub fn new(model: &Model) -> SightBuffers {
        SightBuffers {
            stamp: resident(vec![0; model.segments.len()]),
            query: 0,
            ranked: resident(Vec::with_capacity(model.segments.len())),
            rays: Rays::default(),
        }
    }

    /// Occlusion rays cast so far with these buffers ([`PoseVisibility::rays_cast`]).
    pub fn rays_cast(&self) -> u64 {
        self.rays.cost()
    }

    /// `self.ranked` ← the candidates for what `at` sees, each once (angle 0): the union of the
    /// sets of the nodes serving `at` and the 26 positions a node spacing away around it.
    fn gather(&mut self, table: &VisibilityTable, at: &Point3<f64>) {
        self.query = self.query.wrapping_add(1);
        if self.query == 0 {
            // The stamps wrapped: forget them all once in 4 billion queries.
            self.stamp.fill(0);
            self.query = 1;
        }
        self.ranked.clear();
        let step = table.header.spacing_m;
        for dz in [0.0, -step, step] {
            for dy in [0.0, -step, step] {
                for dx in [0.0, -step, step] {
                    let p = Point3::new(at.x + dx, at.y + dy, at.z + dz);
                    let Some(set) = table.query(&p) else { continue };
                    for &s in set.segments {
                        let Some(mark) = self.stamp.get_mut(s as usize) else {
                            continue;
                        };
                        if *mark == self.query || self.ranked.len() == self.ranked.capacity() {
                            continue;
                        }
                        *mark = self.query;
                        self.ranked.push((0.0, s));
                    }
                }
            }
        }
    }
}

impl PoseVisibility {
    /// The model's triangles in a BVH, and buffers for all of its segments.
    pub fn new(model: &Model) -> PoseVisibility {
        let (tris, faces): (Vec<_>, Vec<_>) = model_triangles(model).into_iter().unzip();
        PoseVisibility {
            bvh: TriangleBvh::build(&tris, &faces),
            own: SightBuffers::new(model),
            seen: resident(Vec::with_capacity(model.segments.len())),
            last: None,
        }
    }

    /// Occlusion rays cast so far by [`Self::at`] and [`Self::widest`], counted in traversals
    /// of the model's BVH (a ray settled by the last occluder counts
    /// 1/[`TRIED_PER_TRAVERSAL`]): a query's cost is the difference before and after it (a few
    /// hundred nanoseconds a traversal on a model of 10⁴ triangles), so a caller with a work
    /// budget charges what a query did, not what a typical one does. (Those of
    /// [`Self::widest_with`] count in the buffers given to it.)
    pub fn rays_cast(&self) -> u64 {
        self.own.rays.cost()
    }

    /// The `keep` segments seen from `at` that span the largest angle in sight (the angle the
    /// segment spans from `at` × the share of it in sight), as (that angle, the segment as
    /// [`Self::at`] sees it: its points in sight) pairs in no particular order, into `out`
    /// (cleared first). The same segments, points and angles as ranking all of [`Self::at`] by
    /// that angle and keeping the `keep` largest, ties apart.
    ///
    /// **Why ranked.** The cost of [`Self::at`] follows the model's detail: every candidate
    /// segment costs [`SAMPLES`] rays, and a storey of an architect's model offers thousands
    /// (window sashes, stair nosings, column casings). What a grid position is scored by is a
    /// few dozen of the widest. The whole angle a segment spans from `at` bounds the angle it
    /// spans in sight, so the candidates are taken widest first and rays are cast only until
    /// no candidate left could enter the kept: the cost follows `keep` and what is in view,
    /// not the model's segment count.
    pub fn widest(
        &mut self,
        model: &Model,
        table: &VisibilityTable,
        at: &Point3<f64>,
        keep: usize,
        out: &mut Vec<(f64, SeenSegment)>,
    ) {
        widest(&self.bvh, &mut self.own, model, table, at, keep, out);
    }

    /// [`Self::widest`] in `buffers` (sized for the same model) rather than this value's own:
    /// the same answer, and this value is only read, so several threads can ask at once.
    pub fn widest_with(
        &self,
        buffers: &mut SightBuffers,
        model: &Model,
        table: &VisibilityTable,
        at: &Point3<f64>,
        keep: usize,
        out: &mut Vec<(f64, SeenSegment)>,
    ) {
        widest(&self.bvh, buffers, model, table, at, keep, out);
    }

    /// The model's triangles in a BVH: for other ray casts against the model (the step onto a
    /// floor, `tracker::floor`), so that it is built once.
    pub fn solid(&self) -> &TriangleBvh {
        &self.bvh
    }

    /// The segments seen from `at` with the share of each in sight (empty outside the table), or
    /// those of the last query when it was within [`REUSE_M`] of `at`.
    /// `model` and `table` must be the ones given to [`Self::new`] and the table built for it.
    pub fn at(&mut self, model: &Model, table: &VisibilityTable, at: &Point3<f64>) -> &[SeenSegment] {
        if self.last.is_some_and(|l| (l - at).norm() <= REUSE_M) {
            return &self.seen;
        }
        self.last = Some(*at);
        self.seen.clear();
        self.own.gather(table, at);
        for &(_, s) in &self.own.ranked {
            let seg = &model.segments[s as usize];
            let mask = in_sight(&self.bvh, at, &seg.a, &seg.b, &mut self.own.rays);
            if mask != 0 {
                self.seen.push(SeenSegment {
                    segment: s,
                    fraction: mask.count_ones() as f32 / SAMPLES as f32,
                    mask,
                });
            }
        }
        &self.seen
    }
}

/// [`PoseVisibility::widest`] against `bvh` in `buffers`.
fn widest(
    bvh: &TriangleBvh,
    buffers: &mut SightBuffers,
    model: &Model,
    table: &VisibilityTable,
    at: &Point3<f64>,
    keep: usize,
    out: &mut Vec<(f64, SeenSegment)>,
) {
    out.clear();
    if keep == 0 {
        return;
    }
    buffers.gather(table, at);
    for r in &mut buffers.ranked {
        let seg = &model.segments[r.1 as usize];
        r.0 = spanned_angle(at, &seg.a, &seg.b);
    }
    buffers.ranked.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
    // The kept, and the least of them once there are `keep`.
    let mut least = (f64::NEG_INFINITY, 0usize);
    for &(bound, s) in &buffers.ranked {
        if out.len() == keep && bound <= least.0 {
            break;
        }
        // Once the kept are full, a segment enters only with more than `least / bound` of its
        // points in sight: its rays stop at the hidden point that settles that it cannot (on a
        // detailed model most candidates are another room's, hidden whole). A point short of
        // that share is given up only one point beyond it, so rounding never drops one that
        // would have entered: the answer is the full test's.
        let hidden_allowed = if out.len() == keep {
            let needed = (SAMPLES as f64 * least.0 / bound).floor() as u32;
            SAMPLES as u32 - needed.min(SAMPLES as u32)
        } else {
            SAMPLES as u32
        };
        let seg = &model.segments[s as usize];
        let mask = in_sight_until(bvh, at, &seg.a, &seg.b, hidden_allowed, &mut buffers.rays);
        let Some(mask) = mask.filter(|&m| m != 0) else {
            continue;
        };
        let angle = bound * f64::from(mask.count_ones()) / SAMPLES as f64;
        let seen = SeenSegment {
            segment: s,
            fraction: mask.count_ones() as f32 / SAMPLES as f32,
            mask,
        };
        if out.len() < keep {
            if out.len() < out.capacity() {
                out.push((angle, seen));
            }
            if out.len() == keep {
                least = least_of(out);
            }
        } else if angle > least.0 {
            out[least.1] = (angle, seen);
            least = least_of(out);
        }
    }
}

/// The angle the segment a–b spans seen from `at` (rad).
#[inline]
pub fn spanned_angle(at: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let (u, v) = (a - at, b - at);
    u.cross(&v).norm().atan2(u.dot(&v))
}

/// The least of `kept` (angle, index into `kept`).
fn least_of(kept: &[(f64, SeenSegment)]) -> (f64, usize) {
    kept.iter()
        .enumerate()
        .fold((f64::INFINITY, 0), |m, (i, k)| if k.0 < m.0 { (k.0, i) } else { m })
}

/// Which sampled points of the segment a–b the ray from `at` reaches unobstructed (bit k for
/// [`sample_point`] k), the rays counted in `rays`.
fn in_sight(bvh: &TriangleBvh, at: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, rays: &mut Rays) -> u8 {
    in_sight_until(bvh, at, a, b, SAMPLES as u32, rays).unwrap_or(0)
}

/// [`in_sight`], given up (`None`) at the first hidden point beyond `hidden_allowed`.
///
/// Each ray first tries the triangle that hid the last hidden point (`rays.occluder`): the
/// points of a segment hidden by a wall, and the next segments behind it, are mostly hidden by
/// the same triangle, and a ray tested against one triangle costs a hundredth of a traversal
/// of a detailed model's BVH. Only a hit well inside that triangle counts
/// ([`TriangleBvh::occludes_inside`]), one every traversal would find too: the answer is the
/// traversal's. Only traversals are counted as rays cast.
fn in_sight_until(
    bvh: &TriangleBvh,
    at: &Point3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    hidden_allowed: u32,
    rays: &mut Rays,
) -> Option<u8> {
    let origin = [at.x as f32, at.y as f32, at.z as f32];
    let mut clear = 0u8;
    let mut hidden = 0;
    for k in 0..SAMPLES {
        let p = sample_point(a, b, k);
        let d = p - at;
        let dist = d.norm();
        if dist <= END_SLACK_M {
            clear |= 1 << k;
            continue;
        }
        // Unit direction: `t` of the ray is in metres.
        let u = d / dist;
        let ray = Ray::new(origin, [u.x as f32, u.y as f32, u.z as f32]);
        let t_max = (dist - END_SLACK_M) as f32;
        rays.tried += 1;
        let cached = rays
            .occluder
            .is_some_and(|slot| bvh.occludes_inside(slot, &ray, START_SLACK_M, t_max));
        let hit = cached || {
            rays.cast += 1;
            let found = bvh.occluder(&ray, START_SLACK_M, t_max);
            if found.is_some() {
                rays.occluder = found;
            }
            found.is_some()
        };
        if !hit {
            clear |= 1 << k;
        } else {
            hidden += 1;
            if hidden > hidden_allowed {
                return None;
            }
        }
    }
    Some(clear)
}

#[cfg(test)]
mod tests {
    use super::*;
    use omnitrack_core::model::Model;

    /// Two rooms side by side (x in [0, 4] and [4, 8], y in [0, 3], z in [0, 2.5]) with a solid
    /// wall between them, as an OBJ.
    fn two_rooms() -> Model {
        let mut obj = String::new();
        let mut v = 0;
        let mut quad = |obj: &mut String, p: [[f64; 3]; 4]| {
            for q in p {
                obj.push_str(&format!("v {} {} {}\n", q[0], q[1], q[2]));
            }
            obj.push_str(&format!("f {} {} {} {}\n", v + 1, v + 2, v + 3, v + 4));
            v += 4;
        };
        for (x0, x1) in [(0.0, 4.0), (4.0, 8.0)] {
            // Floor, ceiling, the walls at y = 0 and y = 3, at x = x0 and x = x1.
            for q in [
                [[x0, 0.0, 0.0], [x1, 0.0, 0.0], [x1, 3.0, 0.0], [x0, 3.0, 0.0]],
                [[x0, 0.0, 2.5], [x0, 3.0, 2.5], [x1, 3.0, 2.5], [x1, 0.0, 2.5]],
                [[x0, 0.0, 0.0], [x0, 0.0, 2.5], [x1, 0.0, 2.5], [x1, 0.0, 0.0]],
                [[x0, 3.0, 0.0], [x1, 3.0, 0.0], [x1, 3.0, 2.5], [x0, 3.0, 2.5]],
                [[x0, 0.0, 0.0], [x0, 3.0, 0.0], [x0, 3.0, 2.5], [x0, 0.0, 2.5]],
                [[x1, 0.0, 0.0], [x1, 0.0, 2.5], [x1, 3.0, 2.5], [x1, 3.0, 0.0]],
            ] {
                quad(&mut obj, q);
            }
        }
        Model::from_obj_str(&obj, "two_rooms.obj").expect("a valid model")
    }

    #[test]
    fn segments_behind_a_wall_are_hidden_and_those_around_are_whole() {
        let model = two_rooms();
        let bvh = PoseVisibility::new(&model).bvh;
        let mut rays = Rays::default();
        let at = Point3::new(2.0, 1.5, 1.5);
        for seg in &model.segments {
            let mid = seg.a + (seg.b - seg.a) * 0.5;
            let f = in_sight(&bvh, &at, &seg.a, &seg.b, &mut rays).count_ones() as f32 / SAMPLES as f32;
            let (lo, hi) = (seg.a.x.min(seg.b.x), seg.a.x.max(seg.b.x));
            if lo >= 4.0 - 1e-9 && hi > 4.0 + 1e-9 {
                assert_eq!(f, 0.0, "a segment of the other room at {mid:?}");
            } else if hi <= 4.0 + 1e-9 {
                assert_eq!(f, 1.0, "a segment of this room at {mid:?}");
            } else {
                // A line along both rooms (their floors and ceilings are one plane each).
                assert_eq!(f, 0.5, "a segment through both rooms at {mid:?}");
            }
        }
    }

    /// Each point tested on its own by a traversal, as [`in_sight`] did before it tried the last
    /// occluder first.
    fn traversed(bvh: &TriangleBvh, at: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> u8 {
        let mut clear = 0;
        for k in 0..SAMPLES {
            let d = sample_point(a, b, k) - at;
            let dist = d.norm();
            let u = d / dist;
            let ray = Ray::new(
                [at.x as f32, at.y as f32, at.z as f32],
                [u.x as f32, u.y as f32, u.z as f32],
            );
            if dist <= END_SLACK_M || !bvh.occluded(&ray, START_SLACK_M, (dist - END_SLACK_M) as f32) {
                clear |= 1 << k;
            }
        }
        clear
    }

    #[test]
    fn trying_the_last_occluder_first_gives_the_traversals_answer_for_a_fraction_of_them() {
        let model = two_rooms();
        let bvh = PoseVisibility::new(&model).bvh;
        let mut rays = Rays::default();
        let (mut points, mut clear) = (0, 0);
        for ix in 0..16 {
            for iy in 0..6 {
                for z in [0.4, 1.3, 2.2] {
                    let at = Point3::new(0.25 + 0.5 * ix as f64, 0.25 + 0.5 * iy as f64, z);
                    for seg in &model.segments {
                        let want = traversed(&bvh, &at, &seg.a, &seg.b);
                        assert_eq!(in_sight(&bvh, &at, &seg.a, &seg.b, &mut rays), want, "{at:?} {seg:?}");
                        points += SAMPLES as u64;
                        clear += u64::from(want.count_ones());
                    }
                }
            }
        }
        assert_eq!(rays.tried, points);
        // A point in sight always costs a traversal; the other room's, hidden by the wall
        // between, mostly by the triangle that hid the point before.
        let hidden = points - clear;
        assert!(hidden > points / 3, "{hidden} of {points} points hidden");
        let hidden_traversed = rays.cast - clear;
        assert!(
            hidden_traversed * 10 < hidden,
            "{hidden_traversed} traversals for {hidden} hidden points"
        );
    }

    #[test]
    fn a_segment_half_behind_an_edge_on_obstacle_is_half_in_sight() {
        // A floor line from x = 0 to x = 8 at y = 0 seen from (2, 1.5, 1.5) past a wall across
        // the room at x = 4 that stands from y = 0.5 to y = 3: half of it is hidden.
        let obj = "v 0 0 0\nv 8 0 0\nv 8 -1 0\nv 0 -1 0\nf 1 2 3 4\n\
                   v 4 0.5 0\nv 4 3 0\nv 4 3 2.5\nv 4 0.5 2.5\nf 5 6 7 8\n";
        let model = Model::from_obj_str(obj, "screen.obj").expect("a valid model");
        let bvh = PoseVisibility::new(&model).bvh;
        let at = Point3::new(2.0, 1.5, 1.5);
        // The line y = 0, z = 0 from x = 0 to 8: points beyond the screen's shadow are hidden.
        let mask = in_sight(
            &bvh,
            &at,
            &Point3::new(0.0, 0.0, 0.0),
            &Point3::new(8.0, 0.0, 0.0),
            &mut Rays::default(),
        );
        let f = mask.count_ones() as f32 / SAMPLES as f32;
        assert!(f > 0.3 && f < 0.8, "in sight {f}");
        // The points in sight are the near end's, in order from x = 0.
        assert_eq!(mask, ((1u32 << mask.count_ones()) - 1) as u8, "mask {mask:08b}");
    }
}
