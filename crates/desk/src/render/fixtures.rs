//! What real rooms have and building models leave out: trims around openings, baseboards,
//! built-in cabinets, closed doors, window blinds and rugs, and walls built a few cm off the
//! drawing. They exist only in the images, never in the model the tracker is given.
//!
//! In: a [`Model`], an [`Appearance`] (the levels `trims`, `built_ins`, `closed_doors`,
//! `blinds`, `floor_pattern` for rugs, `wall_offset_m`), keep-out points (the trajectory), and
//! ray queries on the rendered model (its displaced walls). Out: [`displaced_vertices`] (where
//! the rendered model's vertices are) and [`Fixtures`]: pieces of geometry, each one surface,
//! plus the boxes that clutter must keep out of.
//!
//! Openings are found from the geometry alone, so any model the OBJ rules allow works: the
//! vertical faces are grouped by plane; in each plane, a face edge with no face of the plane
//! just beyond it bounds the plane's area; a point just beyond such an edge that has faces of
//! the plane to its left, its right and above it is in an opening (a window if faces are below
//! it too, else a door when it is door-sized). A model without openings, walls or floors gets
//! no fixtures of that kind.

use super::appearance::{hash64, hsv, Appearance, Rng};
use super::scene::{box_triangles, quad_triangles, Pattern, Surface, SurfaceKind};
use nalgebra::{Point3, Vector3};
use omnitrack_core::model::bvh::{Ray, Triangle, TriangleBvh};
use omnitrack_core::model::{Face, Model};
use std::collections::HashMap;

/// Vertical planes: a face counts as vertical when its normal's z is below this.
const VERTICAL_Z: f64 = 1e-3;
/// Spacing of the samples along face edges that find the planes' boundaries (m).
const SAMPLE_M: f64 = 0.05;
/// How far beyond a boundary the opening test looks (m): gaps narrower are seams or slivers.
const PROBE_M: f64 = 0.03;

/// A face's plane, oriented so that coplanar faces facing either way agree: (normal, offset,
/// key). The key is the plane quantised (normal to 1e-3, offset to 1 cm).
pub fn oriented_plane(face: &Face) -> (Vector3<f64>, f64, [i64; 4]) {
    let n = face.normal.into_inner();
    let sign = if n.x > 1e-9 || n.x.abs() <= 1e-9 && (n.y > 1e-9 || n.y.abs() <= 1e-9 && n.z > 0.0) {
        1.0
    } else {
        -1.0
    };
    let q = |x: f64, scale: f64| (sign * x * scale).round() as i64;
    (
        n * sign,
        face.offset * sign,
        [q(n.x, 1e3), q(n.y, 1e3), q(n.z, 1e3), q(face.offset, 1e2)],
    )
}

/// The seeded shift (m, in [−max, max]) of a vertical plane along its oriented normal; 0 for
/// any other plane (floors and ceilings stay, so the trajectory's height above them holds).
pub fn plane_shift(seed: u64, normal: &Vector3<f64>, key: &[i64; 4], max_m: f64) -> f64 {
    if max_m <= 0.0 || normal.z.abs() >= 0.1 {
        return 0.0;
    }
    let mut h = seed ^ 0x000F_F5E7_u64 << 24;
    for k in key {
        h = hash64(h ^ *k as u64);
    }
    let unit = (h >> 11) as f64 / (1u64 << 53) as f64;
    max_m * (2.0 * unit - 1.0)
}

/// Where the model's vertices are in the rendered world when every vertical plane is shifted
/// along its normal by [`plane_shift`] (`Appearance::wall_offset_m`). A vertex on several
/// planes takes the smallest move that shifts each of them by its amount (least squares where
/// they disagree, then scaled so that no plane moves more than `max_m` there): faces that met
/// still meet, so no crack opens at a corner. Returns the model's own vertices when `max_m` ≤ 0.
pub fn displaced_vertices(model: &Model, max_m: f64, seed: u64) -> Vec<Point3<f64>> {
    if max_m <= 0.0 {
        return model.vertices.clone();
    }
    let mut planes: Vec<Vec<(Vector3<f64>, f64)>> = vec![Vec::new(); model.vertices.len()];
    for face in &model.faces {
        let (n, _, key) = oriented_plane(face);
        let shift = plane_shift(seed, &n, &key, max_m);
        for &v in &face.vertices {
            let list = &mut planes[v as usize];
            // Planes within ~10° of one already listed add nothing but ill-conditioning.
            if list.iter().all(|(m, _)| m.dot(&n).abs() < 0.985) {
                list.push((n, shift));
            }
        }
    }
    model
        .vertices
        .iter()
        .zip(&planes)
        .map(|(p, list)| {
            if list.iter().all(|(_, s)| *s == 0.0) {
                return *p;
            }
            let a = nalgebra::DMatrix::from_fn(list.len(), 3, |r, c| list[r].0[c]);
            let b = nalgebra::DVector::from_iterator(list.len(), list.iter().map(|(_, s)| *s));
            let Ok(d) = a.svd(true, true).solve(&b, 0.1) else {
                return *p;
            };
            let mut d = Vector3::new(d[0], d[1], d[2]);
            let worst = list.iter().map(|(n, _)| n.dot(&d).abs()).fold(0.0, f64::max);
            if worst > max_m {
                d *= max_m / worst;
            }
            p + d
        })
        .collect()
}

/// Ray queries on the rendered model.
pub(super) struct Probe<'a> {
    pub bvh: &'a TriangleBvh,
}

impl Probe<'_> {
    /// Free distance from `o` along unit `d` (capped at `max`).
    pub fn free(&self, o: [f64; 3], d: [f64; 3], max: f64) -> f64 {
        let ray = Ray::new(
            [o[0] as f32, o[1] as f32, o[2] as f32],
            [d[0] as f32, d[1] as f32, d[2] as f32],
        );
        self.bvh.closest(&ray, 1e-4, max as f32).map_or(max, |(_, t)| t as f64)
    }
}

/// A vertical plane of the model with its faces as polygons in plane coordinates: `u`
/// horizontal along the plane, `w` = normal × u (up).
struct WallPlane {
    normal: Vector3<f64>,
    /// Oriented offset plus the plane's shift in the rendered world.
    offset: f64,
    u: Vector3<f64>,
    w: Vector3<f64>,
    polys: Vec<Vec<[f64; 2]>>,
}

impl WallPlane {
    /// The world point at plane coordinates (a, b), `h` along `side` (a unit normal, ±normal).
    fn at(&self, a: f64, b: f64, side: &Vector3<f64>, h: f64) -> [f64; 3] {
        let p = self.normal * self.offset + self.u * a + self.w * b + side * h;
        [p.x, p.y, p.z]
    }

    fn inside(&self, q: [f64; 2]) -> bool {
        self.polys.iter().any(|poly| inside_polygon(poly, q))
    }

    /// Distance from `q` along unit `d` to the first edge of any face of the plane.
    fn ray(&self, q: [f64; 2], d: [f64; 2], max: f64) -> Option<f64> {
        let cross = |a: [f64; 2], b: [f64; 2]| a[0] * b[1] - a[1] * b[0];
        let mut best = max;
        for poly in &self.polys {
            for i in 0..poly.len() {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                let e = [b[0] - a[0], b[1] - a[1]];
                let denom = cross(d, e);
                if denom.abs() < 1e-12 {
                    continue;
                }
                let wv = [a[0] - q[0], a[1] - q[1]];
                let (t, s) = (cross(wv, e) / denom, cross(wv, d) / denom);
                if t > 1e-9 && t < best && (0.0..=1.0).contains(&s) {
                    best = t;
                }
            }
        }
        (best < max).then_some(best)
    }
}

fn inside_polygon(poly: &[[f64; 2]], q: [f64; 2]) -> bool {
    let mut c = false;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if (a[1] > q[1]) != (b[1] > q[1]) {
            let x = a[0] + (q[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if q[0] < x {
                c = !c;
            }
        }
    }
    c
}

/// An opening of a wall plane: [u0, u1] × [v0, v1] in plane coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opening {
    plane: usize,
    pub u0: f64,
    pub u1: f64,
    pub v0: f64,
    pub v1: f64,
    /// Reaches the floor (no face of the plane below it).
    pub door: bool,
}

/// A stretch of a wall's foot: plane, [u0, u1] at height v.
#[derive(Debug, Clone, Copy)]
struct Foot {
    plane: usize,
    u0: f64,
    u1: f64,
    v: f64,
}

/// The model's vertical planes (reveals excluded: they are the openings' sides), the openings
/// in them and the stretches of their bottom edges.
struct Walls {
    planes: Vec<WallPlane>,
    openings: Vec<Opening>,
    feet: Vec<Foot>,
}

fn find_walls(model: &Model, vertices: &[Point3<f64>], kinds: &[SurfaceKind], appearance: &Appearance) -> Walls {
    let mut planes: Vec<WallPlane> = Vec::new();
    let mut index: HashMap<[i64; 4], usize> = HashMap::new();
    for (face, kind) in model.faces.iter().zip(kinds) {
        if face.normal.z.abs() >= VERTICAL_Z || matches!(kind, SurfaceKind::DoorReveal | SurfaceKind::WindowReveal) {
            continue;
        }
        let (n, offset, key) = oriented_plane(face);
        let k = *index.entry(key).or_insert_with(|| {
            let u = Vector3::new(-n.y, n.x, 0.0).normalize();
            let shift = plane_shift(appearance.seed, &n, &key, appearance.wall_offset_m);
            planes.push(WallPlane {
                normal: n,
                offset: offset + shift,
                u,
                w: n.cross(&u),
                polys: Vec::new(),
            });
            planes.len() - 1
        });
        let pl = &mut planes[k];
        // Plane coordinates from the model's own vertices: openings are where the model has them.
        let poly = face
            .vertices
            .iter()
            .map(|&v| {
                let p = vertices[v as usize].coords;
                [p.dot(&pl.u), p.dot(&pl.w)]
            })
            .collect();
        pl.polys.push(poly);
    }
    let mut openings: Vec<Opening> = Vec::new();
    let mut feet = Vec::new();
    for (pi, pl) in planes.iter().enumerate() {
        for poly in &pl.polys {
            let area2: f64 = (0..poly.len())
                .map(|i| {
                    let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                    a[0] * b[1] - a[1] * b[0]
                })
                .sum();
            for i in 0..poly.len() {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                let e = [b[0] - a[0], b[1] - a[1]];
                let len = e[0].hypot(e[1]);
                if len < 0.02 {
                    continue;
                }
                let out = if area2 > 0.0 {
                    [e[1] / len, -e[0] / len]
                } else {
                    [-e[1] / len, e[0] / len]
                };
                let steps = (len / SAMPLE_M).ceil() as usize;
                let bottom = out[1] < -0.99;
                let mut run: Option<(f64, f64)> = None;
                for s in 0..steps {
                    let f = (s as f64 + 0.5) / steps as f64;
                    let p = [a[0] + f * e[0], a[1] + f * e[1]];
                    let beyond = |d: f64| [p[0] + d * out[0], p[1] + d * out[1]];
                    let boundary = !pl.inside(beyond(0.01));
                    if bottom {
                        match (&mut run, boundary) {
                            (Some(r), true) => r.1 = p[0],
                            (None, true) => run = Some((p[0], p[0])),
                            (Some(_), false) => {
                                let (x, y) = run.take().expect("a run");
                                feet.push(foot(pi, x, y, p[1], len / steps as f64));
                            }
                            (None, false) => {}
                        }
                    }
                    if !boundary {
                        continue;
                    }
                    let q = beyond(PROBE_M);
                    if pl.inside(q) {
                        continue;
                    }
                    let ray = |d: [f64; 2]| pl.ray(q, d, 6.0);
                    let (Some(left), Some(right), Some(up)) = (ray([-1.0, 0.0]), ray([1.0, 0.0]), ray([0.0, 1.0]))
                    else {
                        continue;
                    };
                    let down = ray([0.0, -1.0]);
                    let (u0, u1, v1) = (q[0] - left, q[0] + right, q[1] + up);
                    let v0 = match down {
                        Some(d) => q[1] - d,
                        // The jambs' faces reach down to where the door's floor is.
                        None => jamb_foot(pl, u0, u1).unwrap_or(q[1]),
                    };
                    if !(0.3..=4.0).contains(&(u1 - u0)) || v1 - v0 < 0.3 {
                        continue;
                    }
                    let o = Opening {
                        plane: pi,
                        u0,
                        u1,
                        v0,
                        v1,
                        door: down.is_none(),
                    };
                    let same = |x: &Opening| {
                        x.plane == pi
                            && (x.u0 - u0).abs() < 0.02
                            && (x.u1 - u1).abs() < 0.02
                            && (x.v0 - v0).abs() < 0.02
                            && (x.v1 - v1).abs() < 0.02
                    };
                    if !openings.iter().any(same) {
                        openings.push(o);
                    }
                }
                if let Some((x, y)) = run {
                    feet.push(foot(pi, x, y, a[1], len / steps as f64));
                }
            }
        }
    }
    Walls { planes, openings, feet }
}

/// A foot run from sample centres `x`..`y`, widened by half a sample step at each end.
fn foot(plane: usize, x: f64, y: f64, v: f64, step: f64) -> Foot {
    Foot {
        plane,
        u0: x.min(y) - step / 2.0,
        u1: x.max(y) + step / 2.0,
        v,
    }
}

/// The lowest point of the plane's faces touching either jamb of [u0, u1].
fn jamb_foot(pl: &WallPlane, u0: f64, u1: f64) -> Option<f64> {
    pl.polys
        .iter()
        .flatten()
        .filter(|p| (p[0] - u0).abs() < 0.02 || (p[0] - u1).abs() < 0.02)
        .map(|p| p[1])
        .reduce(f64::min)
}

/// One surface of image-only geometry.
pub struct Piece {
    pub surface: Surface,
    pub triangles: Vec<Triangle>,
}

/// Everything this module adds to a scene.
#[derive(Default)]
pub struct Fixtures {
    pub pieces: Vec<Piece>,
    /// World boxes (min, max) of built-ins and closed doors, which clutter must not enter.
    pub blockers: Vec<([f64; 3], [f64; 3])>,
    /// Openings found, doors closed, windows with blinds, trims' and baseboards' boxes,
    /// built-in units, rugs.
    pub counts: FixtureCounts,
}

#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct FixtureCounts {
    pub openings: usize,
    pub closed_doors: usize,
    pub blinds: usize,
    pub trims: usize,
    pub built_ins: usize,
    pub rugs: usize,
}

/// A box spanning [a0, a1] × [b0, b1] along the plane and [h0, h1] along `side`.
fn plane_box(pl: &WallPlane, side: &Vector3<f64>, a: [f64; 2], b: [f64; 2], h: [f64; 2], out: &mut Vec<Triangle>) {
    let c = pl.at(0.5 * (a[0] + a[1]), 0.5 * (b[0] + b[1]), side, 0.5 * (h[0] + h[1]));
    let v = |axis: Vector3<f64>, half: f64| [axis.x * half, axis.y * half, axis.z * half];
    box_triangles(
        c,
        [
            v(pl.u, 0.5 * (a[1] - a[0])),
            v(pl.w, 0.5 * (b[1] - b[0])),
            v(*side, 0.5 * (h[1] - h[0])),
        ],
        out,
    );
}

fn world_bounds(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

fn overlaps(a: &([f64; 3], [f64; 3]), b: &([f64; 3], [f64; 3])) -> bool {
    (0..3).all(|k| a.0[k] < b.1[k] && b.0[k] < a.1[k])
}

/// Whether any keep-out point is within `margin` of the box.
pub(super) fn near_keep_out(keep_out: &[[f64; 3]], lo: [f64; 3], hi: [f64; 3], margin: f64) -> bool {
    keep_out
        .iter()
        .any(|p| (0..3).all(|k| p[k] >= lo[k] - margin && p[k] <= hi[k] + margin))
}

/// Builds the fixtures. `kinds` are the model faces' surface kinds; `vertices` the model's own
/// (undisplaced) vertices; `floor` samples points on the floor (area-weighted) and gives its
/// total area.
pub(super) fn build(
    model: &Model,
    kinds: &[SurfaceKind],
    appearance: &Appearance,
    keep_out: &[[f64; 3]],
    probe: &Probe,
    floor: &dyn Fn(&mut Rng) -> Option<[f64; 3]>,
    floor_area: f64,
) -> Fixtures {
    let mut fx = Fixtures::default();
    let a = appearance;
    if a.trims <= 0.0 && a.built_ins <= 0.0 && a.closed_doors <= 0.0 && a.blinds <= 0.0 && a.floor_pattern <= 0.0 {
        return fx;
    }
    let walls = find_walls(model, &model.vertices, kinds, a);
    fx.counts.openings = walls.openings.len();
    let sat = a.colour.clamp(0.0, 1.0);
    let mut rng = Rng::new(a.seed ^ 0xF1C5_u64 << 40);
    // One trim colour per building, as real houses have: painted white or stained wood.
    let trim_colour = if rng.unit() < 0.6 {
        hsv(0.12, 0.08 * sat, 0.92)
    } else {
        hsv(0.07, 0.55 * sat, 0.45)
    };
    let push = |fx: &mut Fixtures, kind: SurfaceKind, colour: [f32; 3], pattern: Pattern, triangles: Vec<Triangle>| {
        if !triangles.is_empty() {
            fx.pieces.push(Piece {
                surface: Surface { kind, colour, pattern },
                triangles,
            });
        }
    };
    let grain = Pattern::grain(a.clutter_texture);
    // The sides of a plane at (a, b) with free space in front (both for a wall without thickness).
    let free_sides = |pl: &WallPlane, u: f64, v: f64| -> Vec<Vector3<f64>> {
        [pl.normal, -pl.normal]
            .into_iter()
            .filter(|s| probe.free(pl.at(u, v, s, 0.005), [s.x, s.y, s.z], 0.3) > 0.06)
            .collect()
    };

    // Closed doors and blinds first: their openings are decided once per opening, whichever of
    // a thick wall's two faces found it.
    let mut decided: Vec<[f64; 3]> = Vec::new();
    for o in &walls.openings {
        let pl = &walls.planes[o.plane];
        let (um, vm) = (0.5 * (o.u0 + o.u1), 0.5 * (o.v0 + o.v1));
        let centre = pl.at(um, vm, &pl.normal, 0.0);
        if decided
            .iter()
            .any(|c| (c[0] - centre[0]).hypot(c[1] - centre[1]) < 0.6 && (c[2] - centre[2]).abs() < 0.5)
        {
            continue;
        }
        decided.push(centre);
        // The side to dress: the first free one beside the opening.
        let beside = if pl.inside([o.u0 - 0.05, vm]) {
            o.u0 - 0.05
        } else {
            o.u1 + 0.05
        };
        let sides = free_sides(pl, beside, vm);
        let Some(side) = sides.first().copied() else {
            continue;
        };
        // The wall's thickness behind that face, for the recess (0 for a wall without one).
        let depth = if sides.len() > 1 {
            0.0
        } else {
            probe.free(pl.at(beside, vm, &side, -0.005), [-side.x, -side.y, -side.z], 0.5)
        };
        let roll = rng.unit();
        let recess = rng.range(0.0, 0.04).min((depth - 0.01).max(0.0));
        let (width, height) = (o.u1 - o.u0, o.v1 - o.v0);
        if o.door && width <= 2.0 && height >= 1.5 && roll < a.closed_doors {
            let corners = [
                pl.at(o.u0, o.v0, &side, -recess - 0.05),
                pl.at(o.u1, o.v1, &side, -recess + 0.05),
            ];
            let (lo, hi) = world_bounds(&corners);
            if near_keep_out(keep_out, lo, hi, 0.6) {
                continue;
            }
            let wood = rng.unit() < 0.5;
            let colour = if wood {
                hsv(rng.range(0.05, 0.1), 0.55 * sat, rng.range(0.3, 0.55))
            } else {
                hsv(0.1, 0.06 * sat, rng.range(0.8, 0.95))
            };
            let mut slab = Vec::new();
            let c = pl.at(um, vm + 0.002, &side, -recess);
            let v = |axis: Vector3<f64>, half: f64| [axis.x * half, axis.y * half, axis.z * half];
            quad_triangles(
                c,
                v(pl.u, 0.5 * width - 0.003),
                v(pl.w, 0.5 * height - 0.004),
                &mut slab,
            );
            push(
                &mut fx,
                SurfaceKind::Door,
                colour,
                if wood { grain } else { Pattern::None },
                slab,
            );
            let mut handle = Vec::new();
            let hu = if rng.unit() < 0.5 { o.u0 + 0.08 } else { o.u1 - 0.14 };
            let hb = (o.v0 + 1.0).min(o.v1 - 0.1);
            plane_box(
                pl,
                &side,
                [hu, hu + 0.06],
                [hb, hb + 0.02],
                [-recess, -recess + 0.06],
                &mut handle,
            );
            push(
                &mut fx,
                SurfaceKind::Door,
                hsv(0.1, 0.1 * sat, 0.7),
                Pattern::None,
                handle,
            );
            fx.blockers.push((lo, hi));
            fx.counts.closed_doors += 1;
        } else if !o.door && roll < a.blinds {
            // A blind hangs from the head, lowered over 40–100 % of the window.
            let drop = rng.range(0.4, 1.0) * height;
            let r = recess.max(0.01).min((depth - 0.005).max(0.0));
            let mut blind = Vec::new();
            let c = pl.at(um, o.v1 - 0.5 * drop, &side, -r);
            let v = |axis: Vector3<f64>, half: f64| [axis.x * half, axis.y * half, axis.z * half];
            quad_triangles(c, v(pl.u, 0.5 * width - 0.005), v(pl.w, 0.5 * drop), &mut blind);
            let colour = hsv(rng.range(0.08, 0.14), 0.15 * sat, rng.range(0.75, 0.95));
            push(&mut fx, SurfaceKind::Blind, colour, Pattern::Slats, blind);
            fx.counts.blinds += 1;
        }
    }

    // Trims around every opening, on each dressed side; they stop where the wall does (an
    // opening next to a corner gets a narrower casing there, or none).
    if a.trims > 0.0 {
        let (w, d) = (0.07 * a.trims, 0.015 * a.trims);
        for o in &walls.openings {
            let pl = &walls.planes[o.plane];
            let vm = 0.5 * (o.v0 + o.v1);
            let beside = if pl.inside([o.u0 - 0.05, vm]) {
                o.u0 - 0.05
            } else {
                o.u1 + 0.05
            };
            let head = pl.inside([0.5 * (o.u0 + o.u1), o.v1 + 0.9 * w]);
            let top = if head { o.v1 + w } else { o.v1 };
            let bottom = if o.door { o.v0 } else { o.v0 - 0.6 * w };
            let fits = |u: f64| [bottom + 0.01, vm, top - 0.01].iter().all(|&v| pl.inside([u, v]));
            let width = |sign: f64, edge: f64| {
                (1..=7)
                    .rev()
                    .map(|k| w * k as f64 / 7.0)
                    .find(|&x| fits(edge + sign * 0.97 * x))
            };
            let mut tris = Vec::new();
            for side in free_sides(pl, beside, vm) {
                let h = [0.0005, d];
                if let Some(x) = width(-1.0, o.u0) {
                    plane_box(pl, &side, [o.u0 - x, o.u0], [bottom, top], h, &mut tris);
                }
                if let Some(x) = width(1.0, o.u1) {
                    plane_box(pl, &side, [o.u1, o.u1 + x], [bottom, top], h, &mut tris);
                }
                if head {
                    plane_box(pl, &side, [o.u0, o.u1], [o.v1, o.v1 + w], h, &mut tris);
                }
                if !o.door && pl.inside([0.5 * (o.u0 + o.u1), o.v0 - 0.9 * w]) {
                    // The sill sticks out further than the casing, as real ones do.
                    plane_box(
                        pl,
                        &side,
                        [o.u0 - 0.02, o.u1 + 0.02],
                        [o.v0 - 0.6 * w, o.v0],
                        [0.0005, 2.0 * d],
                        &mut tris,
                    );
                }
                fx.counts.trims += 1;
            }
            push(&mut fx, SurfaceKind::Trim, trim_colour, Pattern::None, tris);
        }
    }

    // The feet of the walls with a floor in front: baseboards, and the runs built-ins stand on.
    let mut runs: Vec<(Foot, Vector3<f64>)> = Vec::new();
    for f in &walls.feet {
        if f.u1 - f.u0 < 0.1 {
            continue;
        }
        let pl = &walls.planes[f.plane];
        let um = 0.5 * (f.u0 + f.u1);
        for side in free_sides(pl, um, f.v + 0.1) {
            let above = pl.at(um, f.v + 0.05, &side, 0.03);
            if probe.free(above, [0.0, 0.0, -1.0], 0.3) < 0.1 {
                runs.push((*f, side));
            }
        }
    }
    if a.trims > 0.0 {
        let mut tris = Vec::new();
        for (f, side) in &runs {
            let pl = &walls.planes[f.plane];
            plane_box(
                pl,
                side,
                [f.u0, f.u1],
                [f.v, f.v + 0.08 * a.trims],
                [0.0005, 0.012 * a.trims],
                &mut tris,
            );
            fx.counts.trims += 1;
        }
        push(&mut fx, SurfaceKind::Trim, trim_colour, Pattern::None, tris);
    }

    // Built-in units on the longer feet: base units with a worktop, often wall units above.
    let long: Vec<&(Foot, Vector3<f64>)> = runs.iter().filter(|(f, _)| f.u1 - f.u0 >= 1.0).collect();
    let want = (a.built_ins.max(0.0) * floor_area / 20.0).round() as usize;
    let total: f64 = long.iter().map(|(f, _)| f.u1 - f.u0).sum();
    let mut brng = Rng::new(a.seed ^ 0xB0_1175u64 << 16);
    for _ in 0..want * 20 {
        if fx.counts.built_ins >= want || total <= 0.0 {
            break;
        }
        let mut x = brng.unit() * total;
        let Some((f, side)) = long.iter().copied().find(|(f, _)| {
            x -= f.u1 - f.u0;
            x < 0.0
        }) else {
            break;
        };
        let pl = &walls.planes[f.plane];
        let len = brng.range(0.9, 2.7).min(f.u1 - f.u0 - 0.02);
        let u0 = brng.range(f.u0 + 0.01, f.u1 - 0.01 - len);
        let (u1, v) = (u0 + len, f.v);
        let backed = [u0 + 0.02, u0 + 0.5 * len, u1 - 0.02]
            .iter()
            .all(|&u| [v + 0.2, v + 0.85].iter().all(|&b| pl.inside([u, b])));
        let room = [u0 + 0.05, u0 + 0.5 * len, u1 - 0.05].iter().all(|&u| {
            [v + 0.3, v + 0.8]
                .iter()
                .all(|&b| probe.free(pl.at(u, b, side, 0.02), [side.x, side.y, side.z], 1.5) > 0.75)
        });
        let (lo, hi) = world_bounds(&[pl.at(u0, v, side, 0.0), pl.at(u1, v + 0.9, side, 0.65)]);
        if !backed
            || !room
            || near_keep_out(keep_out, lo, hi, 0.6)
            || fx.blockers.iter().any(|b| overlaps(b, &(lo, hi)))
        {
            continue;
        }
        let body = hsv(brng.unit(), 0.35 * sat, brng.range(0.35, 0.85));
        let front = body.map(|c| (c * 1.12).min(1.0));
        let top = hsv(brng.unit(), 0.15 * sat, if brng.unit() < 0.5 { 0.2 } else { 0.85 });
        let mut tris = Vec::new();
        plane_box(pl, side, [u0, u1], [v, v + 0.1], [0.0, 0.52], &mut tris);
        plane_box(pl, side, [u0, u1], [v + 0.1, v + 0.86], [0.0, 0.58], &mut tris);
        push(
            &mut fx,
            SurfaceKind::BuiltIn,
            body.map(|c| c * 0.6),
            Pattern::None,
            std::mem::take(&mut tris),
        );
        plane_box(
            pl,
            side,
            [u0 - 0.01, u1 + 0.01],
            [v + 0.86, v + 0.9],
            [0.0, 0.62],
            &mut tris,
        );
        push(
            &mut fx,
            SurfaceKind::BuiltIn,
            top,
            Pattern::None,
            std::mem::take(&mut tris),
        );
        // Door fronts about 50 cm wide with 3 mm gaps: the seams real cabinets show.
        let doors = (len / 0.5).round().max(1.0) as usize;
        let dw = len / doors as f64;
        for k in 0..doors {
            let (a0, a1) = (u0 + k as f64 * dw + 0.0015, u0 + (k + 1) as f64 * dw - 0.0015);
            plane_box(pl, side, [a0, a1], [v + 0.115, v + 0.845], [0.58, 0.6], &mut tris);
        }
        let wall_units = brng.unit() < 0.6
            && [u0 + 0.02, u1 - 0.02]
                .iter()
                .all(|&u| [v + 1.45, v + 2.15].iter().all(|&b| pl.inside([u, b])))
            && probe.free(
                pl.at(u0 + 0.5 * len, v + 1.5, side, 0.02),
                [side.x, side.y, side.z],
                1.0,
            ) > 0.45;
        if wall_units {
            for k in 0..doors {
                let (a0, a1) = (u0 + k as f64 * dw + 0.0015, u0 + (k + 1) as f64 * dw - 0.0015);
                plane_box(pl, side, [a0, a1], [v + 1.45, v + 2.15], [0.0, 0.35], &mut tris);
            }
        }
        push(&mut fx, SurfaceKind::BuiltIn, front, grain, tris);
        fx.blockers.push((lo, hi));
        fx.counts.built_ins += 1;
    }

    // Rugs: a field and an inset border of another colour, 6 and 7 mm above the floor, laid
    // along the longest wall's direction as real rugs are.
    let axis = walls
        .planes
        .iter()
        .max_by(|p, q| plane_area(p).total_cmp(&plane_area(q)))
        .map_or(Vector3::x(), |p| p.u);
    let side = Vector3::new(-axis.y, axis.x, 0.0);
    let want = (a.floor_pattern.max(0.0) * floor_area / 25.0).round() as usize;
    let mut rrng = Rng::new(a.seed ^ 0x0072_0675u64 << 8);
    for _ in 0..want * 20 {
        if fx.counts.rugs >= want {
            break;
        }
        let Some(p) = floor(&mut rrng) else {
            break;
        };
        let (hx, hy) = (rrng.range(0.5, 1.3), rrng.range(0.4, 0.9));
        let corner = |sx: f64, sy: f64| {
            let c = Vector3::new(p[0], p[1], p[2]) + axis * (sx * hx) + side * (sy * hy);
            [c.x, c.y, c.z]
        };
        let flat = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .all(|&(sx, sy)| {
                let c = corner(sx, sy);
                let d = [c[0] - p[0], c[1] - p[1], 0.0];
                let r = d[0].hypot(d[1]);
                probe.free([c[0], c[1], c[2] + 0.05], [0.0, 0.0, -1.0], 0.3) < 0.07
                    && probe.free([p[0], p[1], p[2] + 0.05], [d[0] / r, d[1] / r, 0.0], 5.0) > r + 0.05
            });
        let (lo, hi) = world_bounds(&[
            corner(-1.0, -1.0),
            corner(1.0, 1.0),
            corner(1.0, -1.0),
            corner(-1.0, 1.0),
        ]);
        if !flat
            || fx
                .blockers
                .iter()
                .any(|b| overlaps(b, &(lo, [hi[0], hi[1], hi[2] + 0.1])))
        {
            continue;
        }
        let hue = rrng.unit();
        for (k, (inset, lift)) in [(0.0, 0.006), (0.1, 0.007)].into_iter().enumerate() {
            let mut tris = Vec::new();
            let c = [p[0], p[1], p[2] + lift];
            let v = |axis: Vector3<f64>, half: f64| [axis.x * half, axis.y * half, axis.z * half];
            quad_triangles(c, v(axis, hx - inset), v(side, hy - inset), &mut tris);
            let colour = hsv(hue + 0.5 * k as f64, 0.5 * sat, rrng.range(0.2, 0.75));
            push(&mut fx, SurfaceKind::Rug, colour, Pattern::None, tris);
        }
        fx.counts.rugs += 1;
    }
    fx
}

fn plane_area(p: &WallPlane) -> f64 {
    p.polys
        .iter()
        .map(|poly| {
            (0..poly.len())
                .map(|i| {
                    let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                    a[0] * b[1] - a[1] * b[0]
                })
                .sum::<f64>()
                .abs()
                / 2.0
        })
        .sum()
}

/// The openings found in a model's walls (world corners: bottom-left, top-right in plane
/// coordinates, on the model's own planes), for tests and reports.
pub fn openings(model: &Model) -> Vec<(Opening, [Point3<f64>; 2])> {
    let mid_z = model.bounds().map_or(0.0, |(lo, hi)| 0.5 * (lo.z + hi.z));
    let kinds: Vec<SurfaceKind> = model
        .faces
        .iter()
        .map(|f| super::scene::kind_of(model, f, mid_z))
        .collect();
    let walls = find_walls(model, &model.vertices, &kinds, &Appearance::plain());
    walls
        .openings
        .iter()
        .map(|o| {
            let pl = &walls.planes[o.plane];
            let p = |a: f64, b: f64| Point3::from(pl.at(a, b, &pl.normal, 0.0));
            (*o, [p(o.u0, o.v0), p(o.u1, o.v1)])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::scene::Scene;

    /// A 4 m × 3 m room, 2.5 m high, walls without thickness: a door (x 1.0–1.9, up to 2.1 m)
    /// in the wall y = 0 and a window (x 1.5–2.5, 0.9–2.0 m) in the wall y = 3, each wall cut
    /// into panels around its opening as the floor-plan extruder does.
    fn room(with_floor: bool, with_openings: bool) -> Model {
        let h = 2.5;
        let mut quads: Vec<[[f64; 3]; 4]> = Vec::new();
        let mut wall_y = |y: f64, x0: f64, x1: f64, z0: f64, z1: f64| {
            quads.push([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]]);
        };
        if with_openings {
            wall_y(0.0, 0.0, 1.0, 0.0, h);
            wall_y(0.0, 1.9, 4.0, 0.0, h);
            wall_y(0.0, 1.0, 1.9, 2.1, h);
            wall_y(3.0, 0.0, 1.5, 0.0, h);
            wall_y(3.0, 2.5, 4.0, 0.0, h);
            wall_y(3.0, 1.5, 2.5, 0.0, 0.9);
            wall_y(3.0, 1.5, 2.5, 2.0, h);
        } else {
            wall_y(0.0, 0.0, 4.0, 0.0, h);
            wall_y(3.0, 0.0, 4.0, 0.0, h);
        }
        for x in [0.0, 4.0] {
            quads.push([[x, 0.0, 0.0], [x, 3.0, 0.0], [x, 3.0, h], [x, 0.0, h]]);
        }
        if with_floor {
            for z in [0.0, h] {
                quads.push([[0.0, 0.0, z], [4.0, 0.0, z], [4.0, 3.0, z], [0.0, 3.0, z]]);
            }
        }
        // No names: the kinds come from the faces' orientations, as for any unnamed model.
        let mut text = String::new();
        for (k, q) in quads.iter().enumerate() {
            for p in q {
                text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
            }
            let b = 4 * k + 1;
            text += &format!("f {} {} {} {}\n", b, b + 1, b + 2, b + 3);
        }
        Model::from_obj_str(&text, "room.obj").unwrap()
    }

    fn keep() -> Vec<Point3<f64>> {
        vec![Point3::new(2.8, 1.5, 1.2)]
    }

    /// First surface kind hit from `from` towards `to`, and the distance.
    fn hit(scene: &Scene, from: [f64; 3], to: [f64; 3]) -> Option<(SurfaceKind, f64)> {
        let d = Vector3::new(to[0] - from[0], to[1] - from[1], to[2] - from[2]).normalize();
        let ray = Ray::new(
            [from[0] as f32, from[1] as f32, from[2] as f32],
            [d.x as f32, d.y as f32, d.z as f32],
        );
        scene
            .geometry
            .closest(&ray, 1e-4, f32::INFINITY)
            .map(|(sid, t)| (scene.surfaces[sid as usize].kind, t as f64))
    }

    #[test]
    fn openings_are_found_from_the_geometry() {
        let found = openings(&room(true, true));
        assert_eq!(found.len(), 2, "{found:?}");
        let door = found.iter().find(|(o, _)| o.door).expect("a door");
        let window = found.iter().find(|(o, _)| !o.door).expect("a window");
        let near = |p: &Point3<f64>, q: [f64; 3]| (p - Point3::from(q)).norm() < 1e-6;
        let corners = |c: &[Point3<f64>; 2], a: [f64; 3], b: [f64; 3]| {
            (near(&c[0], a) && near(&c[1], b)) || (near(&c[0], [b[0], b[1], a[2]]) && near(&c[1], [a[0], a[1], b[2]]))
        };
        assert!(corners(&door.1, [1.0, 0.0, 0.0], [1.9, 0.0, 2.1]), "{door:?}");
        assert!(corners(&window.1, [1.5, 3.0, 0.9], [2.5, 3.0, 2.0]), "{window:?}");
        assert!(openings(&room(true, false)).is_empty());
        assert!(openings(&room(false, false)).is_empty());
    }

    #[test]
    fn trims_frame_an_opening_and_leave_it_open() {
        let trims = Appearance {
            trims: 1.0,
            ..Appearance::plain()
        };
        let scene = Scene::build(&room(true, true), &trims, &keep());
        let eye = [2.8, 1.5, 1.2];
        // Just outside the door's left jamb, the casing stands 1.5 cm proud of the wall.
        let (kind, t) = hit(&scene, eye, [0.97, 0.0, 1.2]).unwrap();
        let wall_t = Vector3::<f64>::new(0.97 - 2.8, -1.5, 0.0).norm();
        assert_eq!(kind, SurfaceKind::Trim);
        assert!(t < wall_t - 0.005 && t > wall_t - 0.05, "{t} vs the wall at {wall_t}");
        // Through the opening's middle nothing is hit; 10 cm inside the jamb neither.
        for x in [1.45, 1.1, 1.8] {
            assert_eq!(hit(&scene, eye, [x, 0.0, 1.2]), None, "x {x}");
        }
        // The window has casings and a sill, and stays open.
        assert_eq!(hit(&scene, eye, [1.47, 3.0, 1.5]).map(|h| h.0), Some(SurfaceKind::Trim));
        assert_eq!(hit(&scene, eye, [2.0, 3.0, 1.5]), None);
        // Baseboards run along the foot of the walls.
        assert_eq!(hit(&scene, eye, [4.0, 1.0, 0.04]).map(|h| h.0), Some(SurfaceKind::Trim));
        assert_eq!(hit(&scene, eye, [4.0, 1.0, 0.5]).map(|h| h.0), Some(SurfaceKind::Wall));
        // Off, the scene is the model alone.
        let plain = Scene::build(&room(true, true), &Appearance::plain(), &keep());
        assert_eq!(plain.geometry.triangles.len(), plain.model_triangles);
        assert_eq!(hit(&plain, eye, [0.97, 0.0, 1.2]).map(|h| h.0), Some(SurfaceKind::Wall));
    }

    #[test]
    fn a_closed_door_occludes_its_opening_unless_the_path_goes_through() {
        let shut = Appearance {
            closed_doors: 1.0,
            ..Appearance::plain()
        };
        let scene = Scene::build(&room(true, true), &shut, &keep());
        assert_eq!(scene.fixture_counts.closed_doors, 1);
        let eye = [2.8, 1.5, 1.2];
        let (kind, t) = hit(&scene, eye, [1.45, 0.0, 1.2]).expect("the door");
        assert_eq!(kind, SurfaceKind::Door);
        let wall_t = Vector3::<f64>::new(1.45 - 2.8, -1.5, 0.0).norm();
        assert!((t - wall_t).abs() < 0.06, "{t} vs {wall_t}");
        // A trajectory through the doorway keeps it open.
        let through = vec![Point3::new(1.45, 0.2, 1.2), Point3::new(2.8, 1.5, 1.2)];
        let open = Scene::build(&room(true, true), &shut, &through);
        assert_eq!(open.fixture_counts.closed_doors, 0);
        assert_eq!(hit(&open, eye, [1.45, 0.0, 1.2]), None);
    }

    #[test]
    fn displaced_walls_move_at_most_the_offset_and_stay_closed() {
        let model = room(true, true);
        let max = 0.03;
        let moved = displaced_vertices(&model, max, 7);
        let mut largest: f64 = 0.0;
        for face in &model.faces {
            let n = face.normal.into_inner();
            for &v in &face.vertices {
                let d = moved[v as usize] - model.vertices[v as usize];
                let along = n.dot(&d).abs();
                if n.z.abs() > 0.9 {
                    assert!(along < 1e-12, "floors and ceilings stay: {along}");
                } else {
                    assert!(along <= max + 1e-9, "{along}");
                    largest = largest.max(along);
                }
            }
        }
        assert!(largest > 0.3 * max, "walls moved only {largest}");
        // Every vertical plane moved by one amount: its face stays planar and parallel.
        for face in model.faces.iter().filter(|f| f.normal.z.abs() < 0.1) {
            let n = face.normal.into_inner();
            let shifts: Vec<f64> = face
                .vertices
                .iter()
                .map(|&v| n.dot(&(moved[v as usize] - model.vertices[v as usize])))
                .collect();
            assert!(shifts.iter().all(|s| (s - shifts[0]).abs() < 1e-9), "{shifts:?}");
        }
        assert_eq!(displaced_vertices(&model, 0.0, 7), model.vertices);
    }

    #[test]
    fn odd_models_build_without_panicking() {
        let all = Appearance::realistic();
        for model in [room(true, false), room(false, false), room(false, true)] {
            let floorless = !model.faces.iter().any(|f| f.normal.z.abs() > 0.9);
            let scene = Scene::build(&model, &all, &keep());
            if floorless {
                assert_eq!(scene.fixture_counts.rugs + scene.fixture_counts.built_ins, 0);
            }
        }
        // No vertices at all.
        let empty = Model::from_obj_str("", "empty.obj");
        if let Ok(empty) = empty {
            let _ = Scene::build(&empty, &all, &[]);
        }
    }
}
