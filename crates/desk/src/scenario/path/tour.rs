//! The random tour: a [`Space`] and a stream of draws in, a polyline out that visits rooms along
//! the room graph (through approach points before and after each door) with legs clear of the
//! walls by [`PLAN_SLACK_M`] beyond the body; then U-turns widened so that they can be rounded.

use super::geometry::{length, turn_angle};
use super::space::{Exit, Space};
use super::{Rng, ARC_SLACK_M, P2, PLAN_SLACK_M, V2};

/// Pushes a route to `to`, keeping the tour's polyline free of zero-length legs.
fn push_route(tour: &mut Vec<P2>, route: Vec<P2>) {
    for p in route {
        if (p - *tour.last().unwrap()).norm() > 1e-6 {
            tour.push(p);
        }
    }
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

/// Replaces every corner turning more than `SHARP_TURN` (a U-turn, which no fillet can round) by
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
