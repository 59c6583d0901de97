//! The plan prepared for planning: a [`FloorPlan`] in; out, a [`Space`] that knows its wall
//! panels, its passable doors with approach points either side, its rooms and the graph of rooms
//! joined by doors, and answers what planning asks: is a leg clear, a random free point in a
//! room, a route around what blocks a straight leg (A* on a grid).

use super::geometry::{in_rooms, point_in_polygon, polygon_boundary_dist, seg_point_dist, seg_seg_dist};
use super::{panels_and_doors, Door, Panel, Rng, BODY_CLEARANCE_M, P2, PLAN_SLACK_M, V2};
use crate::floorplan::FloorPlan;
use std::collections::BinaryHeap;

/// Room points tested either side of a door, along its normal, to find the rooms it joins.
const DOOR_PROBE_M: f64 = 0.6;
/// Approach points before and after a door, along its normal.
const DOOR_APPROACH_M: f64 = 0.8;
/// Tour waypoints inside rooms keep this much from every inflated wall.
const INTERIOR_MARGIN_M: f64 = 0.6;
/// Grid cell of the planner used when a straight leg is blocked inside a room.
const GRID_M: f64 = 0.2;

/// A door seen from one room: which door, the room behind it, and the approach points on this
/// side and the other.
#[derive(Debug, Clone, Copy)]
pub(super) struct Exit {
    pub door: usize,
    pub to: usize,
    pub here: P2,
    pub there: P2,
}

/// The plan prepared for planning: panels, doors, rooms and the room graph.
pub struct Space {
    panels: Vec<Panel>,
    pub(super) doors: Vec<Door>,
    pub(super) outlines: Vec<Vec<P2>>,
    pub(super) exits: Vec<Vec<Exit>>,
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
    pub(super) fn clear(&self, a: P2, b: P2, slack: f64) -> bool {
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
    pub(super) fn interior_point(&self, room: usize, rng: &mut Rng) -> Option<P2> {
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
    pub(super) fn route(&self, a: P2, b: P2) -> Option<Vec<P2>> {
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
