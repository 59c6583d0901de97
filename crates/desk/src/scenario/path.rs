//! Walkable paths through a floor plan's free space, and the check that a path never passes
//! through a wall.
//!
//! Free space is the union of the plan's room polygons minus every wall panel (a wall axis piece
//! with its passable door openings cut out) inflated by half the wall's thickness plus
//! [`BODY_CLEARANCE_M`]. A tour visits rooms along the graph of rooms joined by doors, then is
//! rounded at every corner with an arc whose radius the clearance allows, and sampled by arc
//! length at a walking speed.

use crate::floorplan::{FloorPlan, OpeningKind};
pub use crate::render::appearance::Rng;
use nalgebra::{Point2, Vector2};
use omnitrack_core::trajectory::Stamped;
use std::collections::BinaryHeap;

type P2 = Point2<f64>;
type V2 = Vector2<f64>;

/// Half the width of the body carrying the rig: how far from a wall's face the rig centre stays.
pub const BODY_CLEARANCE_M: f64 = 0.25;
/// Extra clearance the straight legs of a tour keep beyond [`BODY_CLEARANCE_M`] (door crossings
/// excepted), so that rounding corners has room to cut them.
const PLAN_SLACK_M: f64 = 0.25;
/// Extra clearance a rounded corner keeps beyond [`BODY_CLEARANCE_M`].
const ARC_SLACK_M: f64 = 0.05;
/// Room points tested either side of a door, along its normal, to find the rooms it joins.
const DOOR_PROBE_M: f64 = 0.6;
/// Approach points before and after a door, along its normal.
const DOOR_APPROACH_M: f64 = 0.8;
/// Tour waypoints inside rooms keep this much from every inflated wall.
const INTERIOR_MARGIN_M: f64 = 0.6;
/// Largest corner radius.
const MAX_TURN_RADIUS_M: f64 = 1.5;
/// Grid cell of the planner used when a straight leg is blocked inside a room.
const GRID_M: f64 = 0.2;
/// A point within this of a room's outline counts as inside it (door centres lie on outlines).
const ROOM_TOLERANCE_M: f64 = 0.02;

/// A straight piece of wall the rig must keep `radius` away from (axis distance).
#[derive(Debug, Clone)]
pub struct Panel {
    pub a: P2,
    pub b: P2,
    /// Half the wall's thickness plus [`BODY_CLEARANCE_M`].
    pub radius: f64,
    /// The wall's feature index in the plan.
    pub wall_feature: usize,
}

/// A door wide enough to walk through.
#[derive(Debug, Clone)]
pub struct Door {
    pub feature: usize,
    pub ends: [P2; 2],
    pub centre: P2,
    /// Unit normal of the door's wall.
    pub normal: V2,
}

fn seg_point_dist(a: P2, b: P2, p: P2) -> f64 {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).norm()
}

fn cross(a: V2, b: V2) -> f64 {
    a.x * b.y - a.y * b.x
}

fn segments_intersect(a: P2, b: P2, c: P2, d: P2) -> bool {
    let d1 = cross(b - a, c - a);
    let d2 = cross(b - a, d - a);
    let d3 = cross(d - c, a - c);
    let d4 = cross(d - c, b - c);
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// Distance between two 2D segments.
fn seg_seg_dist(a: P2, b: P2, c: P2, d: P2) -> f64 {
    if segments_intersect(a, b, c, d) {
        return 0.0;
    }
    seg_point_dist(a, b, c)
        .min(seg_point_dist(a, b, d))
        .min(seg_point_dist(c, d, a))
        .min(seg_point_dist(c, d, b))
}

fn point_in_polygon(poly: &[P2], p: P2) -> bool {
    let mut inside = false;
    let n = poly.len();
    let mut j = n - 1;
    for i in 0..n {
        let (pi, pj) = (poly[i], poly[j]);
        if (pi.y > p.y) != (pj.y > p.y) && p.x < (pj.x - pi.x) * (p.y - pi.y) / (pj.y - pi.y) + pi.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

fn polygon_boundary_dist(poly: &[P2], p: P2) -> f64 {
    (0..poly.len())
        .map(|i| seg_point_dist(poly[i], poly[(i + 1) % poly.len()], p))
        .fold(f64::INFINITY, f64::min)
}

/// Area of a simple polygon (shoelace), positive whatever the orientation.
pub fn polygon_area(poly: &[P2]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| cross(poly[i].coords, poly[(i + 1) % n].coords))
        .sum::<f64>()
        .abs()
        / 2.0
}

/// The straight pieces of each wall's axis (a closed wall includes its closing piece).
fn wall_pieces(plan: &FloorPlan) -> Vec<(usize, P2, P2)> {
    let mut out = Vec::new();
    for (wi, w) in plan.walls.iter().enumerate() {
        let n = w.axis.len();
        let count = if w.closed { n } else { n - 1 };
        for i in 0..count {
            out.push((wi, w.axis[i], w.axis[(i + 1) % n]));
        }
    }
    out
}

/// The wall pieces minus the doors wide enough to pass (width above twice the inflated
/// half-thickness), as panels; and those doors.
pub fn panels_and_doors(plan: &FloorPlan) -> (Vec<Panel>, Vec<Door>) {
    let pieces = wall_pieces(plan);
    // Cuts per piece: intervals along the piece, in metres from its start.
    let mut cuts: Vec<Vec<(f64, f64)>> = vec![Vec::new(); pieces.len()];
    let mut doors = Vec::new();
    for o in plan.openings.iter().filter(|o| o.kind == OpeningKind::Door) {
        // The nearest piece holding both ends, as the extruder does.
        let best = pieces
            .iter()
            .enumerate()
            .map(|(k, &(_, a, b))| (k, seg_point_dist(a, b, o.ends[0]).max(seg_point_dist(a, b, o.ends[1]))))
            .min_by(|x, y| x.1.total_cmp(&y.1));
        let Some((k, _)) = best else { continue };
        let (wi, a, b) = pieces[k];
        let t = plan.walls[wi].thickness_m;
        let width = (o.ends[1] - o.ends[0]).norm();
        if width <= 2.0 * (t / 2.0 + BODY_CLEARANCE_M) {
            continue; // too narrow to pass: it stays a wall
        }
        let dir = (b - a).normalize();
        let u0 = (o.ends[0] - a).dot(&dir);
        let u1 = (o.ends[1] - a).dot(&dir);
        cuts[k].push((u0.min(u1), u0.max(u1)));
        let e0 = a + dir * u0.min(u1);
        let e1 = a + dir * u0.max(u1);
        doors.push(Door {
            feature: o.feature,
            ends: [e0, e1],
            centre: nalgebra::center(&e0, &e1),
            normal: V2::new(-dir.y, dir.x),
        });
    }
    let mut panels = Vec::new();
    for (k, &(wi, a, b)) in pieces.iter().enumerate() {
        let w = &plan.walls[wi];
        let len = (b - a).norm();
        let dir = (b - a) / len;
        let mut c = cuts[k].clone();
        c.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut start = 0.0;
        let mut push = |u0: f64, u1: f64| {
            if u1 - u0 > 1e-9 {
                panels.push(Panel {
                    a: a + dir * u0,
                    b: a + dir * u1,
                    radius: w.thickness_m / 2.0 + BODY_CLEARANCE_M,
                    wall_feature: w.feature,
                });
            }
        };
        for (u0, u1) in c {
            push(start, u0);
            start = start.max(u1);
        }
        push(start, len);
    }
    (panels, doors)
}

fn in_rooms(outlines: &[Vec<P2>], p: P2) -> bool {
    outlines
        .iter()
        .any(|o| point_in_polygon(o, p) || polygon_boundary_dist(o, p) < ROOM_TOLERANCE_M)
}

/// Checks that a trajectory stays in the plan's free space: every position inside a room, and
/// every step (2D segment between consecutive positions) at least the inflated radius away from
/// every wall panel. `Err` names the first offending frame.
pub fn check_path(plan: &FloorPlan, trajectory: &[Stamped]) -> Result<(), String> {
    let (panels, _) = panels_and_doors(plan);
    let outlines: Vec<Vec<P2>> = plan.rooms.iter().map(|r| r.outline.clone()).collect();
    let xy = |s: &Stamped| P2::new(s.pose.translation.x, s.pose.translation.y);
    for (i, s) in trajectory.iter().enumerate() {
        let p = xy(s);
        if !p.x.is_finite() || !p.y.is_finite() {
            return Err(format!("frame {i}: position is not finite"));
        }
        if !in_rooms(&outlines, p) {
            return Err(format!("frame {i}: ({:.3}, {:.3}) is in no room", p.x, p.y));
        }
        if i == 0 {
            continue;
        }
        let q = xy(&trajectory[i - 1]);
        if !in_rooms(&outlines, nalgebra::center(&p, &q)) {
            return Err(format!("step {}→{i}: its midpoint is in no room", i - 1));
        }
        let (lo, hi) = (p.coords.inf(&q.coords), p.coords.sup(&q.coords));
        for w in &panels {
            let r = w.radius;
            let (wlo, whi) = (w.a.coords.inf(&w.b.coords), w.a.coords.sup(&w.b.coords));
            if wlo.x > hi.x + r || wlo.y > hi.y + r || whi.x < lo.x - r || whi.y < lo.y - r {
                continue;
            }
            let d = seg_seg_dist(q, p, w.a, w.b);
            if d < r - 1e-9 {
                return Err(format!(
                    "step {}→{i}: ({:.3}, {:.3})→({:.3}, {:.3}) passes {d:.3} m from the axis of wall features[{}] \
                     (needs {r:.3} m)",
                    i - 1,
                    q.x,
                    q.y,
                    p.x,
                    p.y,
                    w.wall_feature
                ));
            }
        }
    }
    Ok(())
}

/// How many times the trajectory crosses a passable door's opening.
pub fn doorways_passed(plan: &FloorPlan, trajectory: &[Stamped]) -> usize {
    let (_, doors) = panels_and_doors(plan);
    let xy = |s: &Stamped| P2::new(s.pose.translation.x, s.pose.translation.y);
    let mut n = 0;
    for w in trajectory.windows(2) {
        let (p, q) = (xy(&w[0]), xy(&w[1]));
        for d in &doors {
            let sp = (p - d.centre).dot(&d.normal);
            let sq = (q - d.centre).dot(&d.normal);
            if (sp < 0.0) == (sq < 0.0) {
                continue;
            }
            let x = p + (q - p) * (sp / (sp - sq));
            let along = (d.ends[1] - d.ends[0]).normalize();
            let u = (x - d.ends[0]).dot(&along);
            if (0.0..=(d.ends[1] - d.ends[0]).norm()).contains(&u) {
                n += 1;
            }
        }
    }
    n
}

/// A door seen from one room: which door, the room behind it, and the approach points on this
/// side and the other.
#[derive(Debug, Clone, Copy)]
struct Exit {
    door: usize,
    to: usize,
    here: P2,
    there: P2,
}

/// The plan prepared for planning: panels, doors, rooms and the room graph.
pub struct Space {
    panels: Vec<Panel>,
    doors: Vec<Door>,
    outlines: Vec<Vec<P2>>,
    exits: Vec<Vec<Exit>>,
}

impl Space {
    pub fn new(plan: &FloorPlan) -> Self {
        let (panels, doors) = panels_and_doors(plan);
        let outlines: Vec<Vec<P2>> = plan.rooms.iter().map(|r| r.outline.clone()).collect();
        let room_of = |p: P2| outlines.iter().position(|o| point_in_polygon(o, p));
        let mut exits = vec![Vec::new(); outlines.len()];
        for (di, d) in doors.iter().enumerate() {
            let plus = room_of(d.centre + d.normal * DOOR_PROBE_M);
            let minus = room_of(d.centre - d.normal * DOOR_PROBE_M);
            if let (Some(p), Some(m)) = (plus, minus) {
                if p != m {
                    let ap = d.centre + d.normal * DOOR_APPROACH_M;
                    let am = d.centre - d.normal * DOOR_APPROACH_M;
                    exits[p].push(Exit {
                        door: di,
                        to: m,
                        here: ap,
                        there: am,
                    });
                    exits[m].push(Exit {
                        door: di,
                        to: p,
                        here: am,
                        there: ap,
                    });
                }
            }
        }
        Space {
            panels,
            doors,
            outlines,
            exits,
        }
    }

    /// The room graph: one `(door feature, room index, room index)` per door joining two rooms
    /// (room indices into `plan.rooms`).
    pub fn room_links(&self) -> Vec<(usize, usize, usize)> {
        let mut out: Vec<(usize, usize, usize)> = (0..self.exits.len())
            .flat_map(|r| {
                self.exits[r]
                    .iter()
                    .filter(move |e| r < e.to)
                    .map(move |e| (e.door, r, e.to))
            })
            .map(|(d, a, b)| (self.doors[d].feature, a, b))
            .collect();
        out.sort();
        out
    }

    /// Distance from p to the surface of the nearest inflated panel (negative inside one).
    fn clearance(&self, p: P2) -> f64 {
        self.panels
            .iter()
            .map(|w| seg_point_dist(w.a, w.b, p) - w.radius)
            .fold(f64::INFINITY, f64::min)
    }

    fn in_room(&self, p: P2) -> bool {
        in_rooms(&self.outlines, p)
    }

    /// True when the segment a→b stays `slack` beyond every inflated panel and inside the rooms.
    fn clear(&self, a: P2, b: P2, slack: f64) -> bool {
        let (lo, hi) = (a.coords.inf(&b.coords), a.coords.sup(&b.coords));
        for w in &self.panels {
            let r = w.radius + slack;
            let (wlo, whi) = (w.a.coords.inf(&w.b.coords), w.a.coords.sup(&w.b.coords));
            if wlo.x > hi.x + r || wlo.y > hi.y + r || whi.x < lo.x - r || whi.y < lo.y - r {
                continue;
            }
            if seg_seg_dist(a, b, w.a, w.b) < r {
                return false;
            }
        }
        let n = ((b - a).norm() / 0.25).ceil().max(1.0) as usize;
        (0..=n).all(|i| self.in_room(a + (b - a) * (i as f64 / n as f64)))
    }

    /// A random point of room `room` at least [`INTERIOR_MARGIN_M`] from every inflated wall.
    fn interior_point(&self, room: usize, rng: &mut Rng) -> Option<P2> {
        let o = &self.outlines[room];
        let (mut lo, mut hi) = (o[0].coords, o[0].coords);
        for p in o {
            lo = lo.inf(&p.coords);
            hi = hi.sup(&p.coords);
        }
        for _ in 0..2000 {
            let p = P2::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y));
            if point_in_polygon(o, p)
                && polygon_boundary_dist(o, p) > INTERIOR_MARGIN_M + BODY_CLEARANCE_M
                && self.clearance(p) > INTERIOR_MARGIN_M
            {
                return Some(p);
            }
        }
        None
    }

    /// A route from a to b (excluding a, including b): straight when clear, otherwise A* on a grid
    /// of free cells, shortened by line of sight.
    fn route(&self, a: P2, b: P2) -> Option<Vec<P2>> {
        if self.clear(a, b, PLAN_SLACK_M) {
            return Some(vec![b]);
        }
        let pad = 6.0;
        let lo = a.coords.inf(&b.coords) - V2::new(pad, pad);
        let hi = a.coords.sup(&b.coords) + V2::new(pad, pad);
        let nx = ((hi.x - lo.x) / GRID_M).ceil() as usize + 1;
        let ny = ((hi.y - lo.y) / GRID_M).ceil() as usize + 1;
        let centre = |i: usize, j: usize| P2::new(lo.x + i as f64 * GRID_M, lo.y + j as f64 * GRID_M);
        let free: Vec<bool> = (0..nx * ny)
            .map(|k| {
                let p = centre(k % nx, k / nx);
                self.in_room(p) && self.clearance(p) > PLAN_SLACK_M
            })
            .collect();
        let cell_of = |p: P2| {
            let i = ((p.x - lo.x) / GRID_M).round() as usize;
            let j = ((p.y - lo.y) / GRID_M).round() as usize;
            // The nearest free cell in a small neighbourhood.
            let mut best = None;
            let mut best_d = f64::INFINITY;
            for dj in -3i64..=3 {
                for di in -3i64..=3 {
                    let (ci, cj) = (i as i64 + di, j as i64 + dj);
                    if ci < 0 || cj < 0 || ci >= nx as i64 || cj >= ny as i64 {
                        continue;
                    }
                    let k = cj as usize * nx + ci as usize;
                    let d = (centre(ci as usize, cj as usize) - p).norm();
                    if free[k] && d < best_d {
                        best_d = d;
                        best = Some(k);
                    }
                }
            }
            best
        };
        let (s, g) = (cell_of(a)?, cell_of(b)?);
        // A*: costs in millimetres as integers for a total order.
        let mut dist = vec![u64::MAX; nx * ny];
        let mut prev = vec![usize::MAX; nx * ny];
        let h = |k: usize| ((centre(k % nx, k / nx) - centre(g % nx, g / nx)).norm() * 1000.0) as u64;
        let mut heap = BinaryHeap::new();
        dist[s] = 0;
        heap.push(std::cmp::Reverse((h(s), s)));
        while let Some(std::cmp::Reverse((_, k))) = heap.pop() {
            if k == g {
                break;
            }
            let (i, j) = ((k % nx) as i64, (k / nx) as i64);
            for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)] {
                let (ci, cj) = (i + di, j + dj);
                if ci < 0 || cj < 0 || ci >= nx as i64 || cj >= ny as i64 {
                    continue;
                }
                let n = cj as usize * nx + ci as usize;
                if !free[n] {
                    continue;
                }
                let step = if di != 0 && dj != 0 { 283 } else { 200 };
                let nd = dist[k] + step;
                if nd < dist[n] {
                    dist[n] = nd;
                    prev[n] = k;
                    heap.push(std::cmp::Reverse((nd + h(n), n)));
                }
            }
        }
        if dist[g] == u64::MAX {
            return None;
        }
        let mut cells = vec![g];
        while *cells.last().unwrap() != s {
            cells.push(prev[*cells.last().unwrap()]);
        }
        cells.reverse();
        let mut raw = vec![a];
        raw.extend(cells.iter().map(|&k| centre(k % nx, k / nx)));
        raw.push(b);
        // Line-of-sight shortening.
        let mut out = Vec::new();
        let mut i = 0;
        while i + 1 < raw.len() {
            let mut j = raw.len() - 1;
            while j > i + 1 && !self.clear(raw[i], raw[j], PLAN_SLACK_M) {
                j -= 1;
            }
            out.push(raw[j]);
            i = j;
        }
        Some(out)
    }
}

fn turn_angle(a: P2, b: P2, c: P2) -> f64 {
    let (u, v) = (b - a, c - b);
    if u.norm() < 1e-9 || v.norm() < 1e-9 {
        return 0.0;
    }
    cross(u, v).atan2(u.dot(&v)).abs()
}

/// Pushes a route to `to`, keeping the tour's polyline free of zero-length legs.
fn push_route(tour: &mut Vec<P2>, route: Vec<P2>) {
    for p in route {
        if (p - *tour.last().unwrap()).norm() > 1e-6 {
            tour.push(p);
        }
    }
}

fn length(poly: &[P2]) -> f64 {
    poly.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}

/// A random tour of at least `min_length_m` through the plan, as a polyline: rooms joined by doors
/// (through approach points before and after each door centre), random interior points in rooms
/// with few doors, door to door across rooms with many (corridors).
pub fn tour(space: &Space, min_length_m: f64, rng: &mut Rng) -> Vec<P2> {
    // Start in the room with the most doors (the corridor; the only room of the lab).
    let mut room = (0..space.outlines.len())
        .max_by_key(|&r| (space.exits[r].len(), std::cmp::Reverse(r)))
        .expect("a plan with rooms");
    let start = space.interior_point(room, rng).expect("the start room has free space");
    let mut tour = vec![start];
    let mut came: Option<usize> = None;
    let mut visited = vec![0usize; space.outlines.len()];
    visited[room] += 1;
    let mut guard = 0;
    while length(&tour) < min_length_m && guard < 100_000 {
        guard += 1;
        let exits = &space.exits[room];
        let is_hub = exits.len() >= 3;
        // Next door, chosen first so that the walk inside the room can lead to it: not back the
        // way we came unless it is the only one; near and unvisited rooms preferred.
        let chosen: Option<Exit> = if exits.is_empty() {
            None
        } else {
            let here = *tour.last().unwrap();
            let candidates: Vec<&Exit> = exits
                .iter()
                .filter(|e| exits.len() == 1 || Some(e.door) != came)
                .collect();
            let weights: Vec<f64> = candidates
                .iter()
                .map(|e| {
                    let d = (e.here - here).norm();
                    let novelty = if visited[e.to] == 0 { 1.0 } else { 0.15 };
                    novelty / (1.0 + (d / 12.0).powi(2))
                })
                .collect();
            let total: f64 = weights.iter().sum();
            let mut pick = rng.unit() * total;
            let mut chosen = *candidates[candidates.len() - 1];
            for (e, w) in candidates.iter().zip(&weights) {
                if pick < *w {
                    chosen = **e;
                    break;
                }
                pick -= w;
            }
            Some(chosen)
        };
        // Interior points: the whole tour of a closed room, two in a room with few doors (a loop
        // in and out of an office), none across a corridor.
        let interior = match (&chosen, is_hub) {
            (None, _) => 1,
            (Some(_), true) => 0,
            (Some(_), false) => 2,
        };
        for n in 0..interior {
            let last = n + 1 == interior;
            let here = *tour.last().unwrap();
            let before = if tour.len() >= 2 {
                Some(tour[tour.len() - 2])
            } else {
                None
            };
            // Least turning: into the point, and for the last one on to the exit and its door.
            let mut best: Option<(f64, Vec<P2>)> = None;
            for _ in 0..40 {
                let Some(p) = space.interior_point(room, rng) else {
                    break;
                };
                let d = (p - here).norm();
                if d < 2.0 {
                    continue;
                }
                let Some(r) = space.route(here, p) else { continue };
                let mut turns = vec![before.map_or(0.0, |b| turn_angle(b, here, r[0]))];
                if let (true, Some(e)) = (last, &chosen) {
                    let from = if r.len() >= 2 { r[r.len() - 2] } else { here };
                    turns.push(turn_angle(from, p, e.here));
                    turns.push(turn_angle(p, e.here, space.doors[e.door].centre));
                }
                let cost = turns.iter().map(|t| t * t).sum::<f64>() + if d > 12.0 { 0.3 } else { 0.0 };
                if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                    best = Some((cost, r));
                }
                if chosen.is_none() && turns[0] < 100f64.to_radians() {
                    break;
                }
            }
            if let Some((_, r)) = best {
                push_route(&mut tour, r);
            }
        }
        let Some(chosen) = chosen else { continue };
        let here = *tour.last().unwrap();
        let Some(r) = space.route(here, chosen.here) else {
            // Unreachable door from here (should not happen in our plans): try again next loop.
            continue;
        };
        push_route(&mut tour, r);
        push_route(&mut tour, vec![space.doors[chosen.door].centre, chosen.there]);
        came = Some(chosen.door);
        room = chosen.to;
        visited[room] += 1;
    }
    tour
}

/// Turns sharper than this are widened before rounding.
const SHARP_TURN: f64 = 120.0 * std::f64::consts::PI / 180.0;

/// Replaces every corner turning more than [`SHARP_TURN`] (a U-turn, which no fillet can round) by
/// two corners either side of it, a bulb up to 0.9 m wide reaching a little beyond it, where the
/// free space allows; the legs to and between the new corners are clear like the tour's legs.
pub fn ease_sharp_turns(space: &Space, poly: &[P2]) -> Vec<P2> {
    let mut out = vec![poly[0]];
    for i in 1..poly.len() {
        let p = poly[i];
        if i + 1 == poly.len() || turn_angle(*out.last().unwrap(), p, poly[i + 1]) <= SHARP_TURN {
            out.push(p);
            continue;
        }
        let (a, b) = (*out.last().unwrap(), poly[i + 1]);
        let (d1, d2) = ((p - a).normalize(), (b - p).normalize());
        let u = (d1 - d2).normalize(); // points beyond the corner
        let m = V2::new(-u.y, u.x);
        let side = if (a - p).dot(&m) - (b - p).dot(&m) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        let mut eased = None;
        'search: for slack in [PLAN_SLACK_M, ARC_SLACK_M] {
            for (fwd, w) in [(0.4, 0.9), (0.3, 0.7), (0.2, 0.55), (0.0, 0.45), (0.0, 0.35)] {
                for sgn in [side, -side] {
                    let q1 = p + u * fwd + m * (w * sgn);
                    let q2 = p + u * fwd - m * (w * sgn);
                    if space.clear(a, q1, slack) && space.clear(q1, q2, slack) && space.clear(q2, b, slack) {
                        eased = Some((q1, q2));
                        break 'search;
                    }
                }
            }
        }
        match eased {
            Some((q1, q2)) => {
                out.push(q1);
                out.push(q2);
            }
            None => out.push(p),
        }
    }
    out
}

/// A densely sampled smooth path: points about 5 cm apart, with the curvature at each.
pub struct Dense {
    pub points: Vec<P2>,
    pub curvature: Vec<f64>,
    /// Arc length at each point.
    pub s: Vec<f64>,
}

/// Rounds every corner of the polyline with a circular arc: radius up to
/// [`MAX_TURN_RADIUS_M`], its tangent length at most half of either adjoining leg, halved until
/// the arc keeps [`ARC_SLACK_M`] beyond the inflated walls (down to a sharp corner, which is on
/// the clear polyline).
pub fn smooth(space: &Space, poly: &[P2]) -> Dense {
    const STEP: f64 = 0.05;
    let mut points = vec![poly[0]];
    let mut curvature = vec![0.0];
    let push_line = |points: &mut Vec<P2>, curvature: &mut Vec<f64>, to: P2| {
        let from = *points.last().unwrap();
        let n = ((to - from).norm() / STEP).ceil() as usize;
        for i in 1..=n {
            points.push(from + (to - from) * (i as f64 / n as f64));
            curvature.push(0.0);
        }
    };
    for i in 1..poly.len() {
        if i + 1 == poly.len() {
            push_line(&mut points, &mut curvature, poly[i]);
            break;
        }
        let (a, p, b) = (poly[i - 1], poly[i], poly[i + 1]);
        let (la, lb) = ((p - a).norm(), (b - p).norm());
        let (d1, d2) = ((p - a) / la, (b - p) / lb);
        let phi = cross(d1, d2).atan2(d1.dot(&d2));
        if phi.abs() < 1e-4 {
            push_line(&mut points, &mut curvature, p);
            continue;
        }
        let tan_half = (phi.abs() / 2.0).tan();
        let mut tl = (MAX_TURN_RADIUS_M * tan_half).min(0.5 * la).min(0.5 * lb);
        let mut arc = None;
        for _ in 0..8 {
            let r = tl / tan_half;
            let t1 = p - d1 * tl;
            let left = V2::new(-d1.y, d1.x) * phi.signum();
            let c = t1 + left * r;
            let a0 = (t1 - c).y.atan2((t1 - c).x);
            let n = ((r * phi.abs()) / STEP).ceil().max(2.0) as usize;
            let pts: Vec<P2> = (1..=n)
                .map(|k| {
                    let ang = a0 + phi * k as f64 / n as f64;
                    c + V2::new(ang.cos(), ang.sin()) * r
                })
                .collect();
            let mut prev = t1;
            let ok = pts.iter().all(|&q| {
                let good = space.clear(prev, q, ARC_SLACK_M);
                prev = q;
                good
            }) && space.clear(points.last().copied().unwrap(), t1, ARC_SLACK_M);
            if ok {
                arc = Some((t1, pts, 1.0 / r));
                break;
            }
            tl *= 0.5;
        }
        match arc {
            Some((t1, pts, k)) => {
                push_line(&mut points, &mut curvature, t1);
                for q in pts {
                    points.push(q);
                    curvature.push(k);
                }
            }
            None => {
                push_line(&mut points, &mut curvature, p);
                *curvature.last_mut().unwrap() = f64::INFINITY;
            }
        }
    }
    let mut s = vec![0.0];
    for w in points.windows(2) {
        s.push(s.last().unwrap() + (w[1] - w[0]).norm());
    }
    Dense { points, curvature, s }
}

/// Walking speeds at the dense points: 1.0–1.5 m/s varying smoothly along the path, limited in
/// turns by a lateral acceleration (not below 0.75 m/s), and changing at most 0.5 m/s² along it.
pub fn speeds(dense: &Dense, rng: &mut Rng) -> Vec<f64> {
    const A_LAT: f64 = 0.8;
    const A_LONG: f64 = 0.5;
    const V_TURN_MIN: f64 = 0.75;
    let (p1, p2) = (
        rng.range(0.0, std::f64::consts::TAU),
        rng.range(0.0, std::f64::consts::TAU),
    );
    let tau = std::f64::consts::TAU;
    let mut v: Vec<f64> = dense
        .s
        .iter()
        .zip(&dense.curvature)
        .map(|(&s, &k)| {
            let base = 1.25 + 0.18 * (tau * s / 17.0 + p1).sin() + 0.07 * (tau * s / 5.3 + p2).sin();
            let turn = if k > 0.0 {
                (A_LAT / k).sqrt().max(V_TURN_MIN)
            } else {
                f64::INFINITY
            };
            base.min(turn)
        })
        .collect();
    // Acceleration limit, both ways: v² changes by at most 2·a·ds. Starts from rest-free walking.
    for i in 1..v.len() {
        let ds = dense.s[i] - dense.s[i - 1];
        v[i] = v[i].min((v[i - 1] * v[i - 1] + 2.0 * A_LONG * ds).sqrt());
    }
    for i in (0..v.len() - 1).rev() {
        let ds = dense.s[i + 1] - dense.s[i];
        v[i] = v[i].min((v[i + 1] * v[i + 1] + 2.0 * A_LONG * ds).sqrt());
    }
    v
}

/// Positions and path headings at `frames` instants `dt` apart, walking the dense path at the
/// given speeds; `None` when the path is too short.
pub fn walk(dense: &Dense, v: &[f64], frames: usize, dt: f64) -> Option<Vec<(P2, f64)>> {
    const SUB: usize = 20;
    let total = *dense.s.last().unwrap();
    let mut out = Vec::with_capacity(frames);
    let mut s = 0.0;
    let mut idx = 0;
    let locate = |s: f64, idx: &mut usize| {
        while *idx + 2 < dense.s.len() && dense.s[*idx + 1] <= s {
            *idx += 1;
        }
        let (s0, s1) = (dense.s[*idx], dense.s[*idx + 1]);
        if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    for k in 0..frames {
        if k > 0 {
            for _ in 0..SUB {
                let f = locate(s, &mut idx);
                let speed = v[idx] + (v[idx + 1] - v[idx]) * f;
                s += speed * dt / SUB as f64;
            }
        }
        if s > total {
            return None;
        }
        let f = locate(s, &mut idx);
        let (a, b) = (dense.points[idx], dense.points[idx + 1]);
        let p = a + (b - a) * f;
        let d = b - a;
        out.push((p, d.y.atan2(d.x)));
    }
    Some(out)
}
