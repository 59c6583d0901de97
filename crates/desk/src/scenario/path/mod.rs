//! Walkable paths through a floor plan's free space, and the check that a path never passes
//! through a wall.
//!
//! Free space is the union of the plan's room polygons minus every wall panel (a wall axis piece
//! with its passable door openings cut out) inflated by half the wall's thickness plus
//! [`BODY_CLEARANCE_M`]. A tour visits rooms along the graph of rooms joined by doors, then is
//! rounded at every corner with an arc whose radius the clearance allows, and sampled by arc
//! length at a walking speed.
//!
//! The parts, one submodule each: `geometry` (distances and polygons in the plane), `space` (the
//! plan prepared for planning: panels, doors, the room graph, routes around obstacles), `tour`
//! (the random polyline through the rooms) and `walk` (rounding it and walking it at a speed).
//! Here: the panels and doors themselves, and the checks a finished path must pass.

mod geometry;
mod space;
mod tour;
mod walk;

pub use crate::render::appearance::Rng;
pub use geometry::polygon_area;
pub use space::Space;
pub use tour::{ease_sharp_turns, tour};
pub use walk::{smooth, speeds, walk, Dense};

use crate::floorplan::{FloorPlan, OpeningKind};
use geometry::{in_rooms, seg_point_dist, seg_seg_dist};
use nalgebra::{Point2, Vector2};
use omnitrack_core::trajectory::Stamped;

type P2 = Point2<f64>;
type V2 = Vector2<f64>;

/// Half the width of the body carrying the rig: how far from a wall's face the rig centre stays.
pub const BODY_CLEARANCE_M: f64 = 0.25;
/// Extra clearance the straight legs of a tour keep beyond [`BODY_CLEARANCE_M`] (door crossings
/// excepted), so that rounding corners has room to cut them.
const PLAN_SLACK_M: f64 = 0.25;
/// Extra clearance a rounded corner keeps beyond [`BODY_CLEARANCE_M`].
const ARC_SLACK_M: f64 = 0.05;

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

/// Where a trajectory leaves the plan's free space ([`check_path`]); one line naming the first
/// offending frame, or the step into it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("frame {frame}: position is not finite")]
    NotFinite { frame: usize },
    #[error("frame {frame}: ({:.3}, {:.3}) is in no room", .position.x, .position.y)]
    InNoRoom { frame: usize, position: P2 },
    /// The step from `frame - 1` to `frame`.
    #[error("step {}→{frame}: its midpoint is in no room", .frame - 1)]
    StepInNoRoom { frame: usize },
    /// The step from `frame - 1` (at `from`) to `frame` (at `to`) comes `distance` from the axis
    /// of a wall panel that needs `needed` (half its thickness plus [`BODY_CLEARANCE_M`]).
    #[error(
        "step {}→{frame}: ({:.3}, {:.3})→({:.3}, {:.3}) passes {distance:.3} m from the axis of wall \
         features[{wall_feature}] (needs {needed:.3} m)",
        .frame - 1, .from.x, .from.y, .to.x, .to.y
    )]
    ThroughWall {
        frame: usize,
        from: P2,
        to: P2,
        distance: f64,
        needed: f64,
        wall_feature: usize,
    },
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

/// Checks that a trajectory stays in the plan's free space: every position inside a room, and
/// every step (2D segment between consecutive positions) at least the inflated radius away from
/// every wall panel. `Err` names the first offending frame.
pub fn check_path(plan: &FloorPlan, trajectory: &[Stamped]) -> Result<(), PathError> {
    let (panels, _) = panels_and_doors(plan);
    let outlines: Vec<Vec<P2>> = plan.rooms.iter().map(|r| r.outline.clone()).collect();
    let xy = |s: &Stamped| P2::new(s.pose.translation.x, s.pose.translation.y);
    for (i, s) in trajectory.iter().enumerate() {
        let p = xy(s);
        if !p.x.is_finite() || !p.y.is_finite() {
            return Err(PathError::NotFinite { frame: i });
        }
        if !in_rooms(&outlines, p) {
            return Err(PathError::InNoRoom { frame: i, position: p });
        }
        if i == 0 {
            continue;
        }
        let q = xy(&trajectory[i - 1]);
        if !in_rooms(&outlines, nalgebra::center(&p, &q)) {
            return Err(PathError::StepInNoRoom { frame: i });
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
                return Err(PathError::ThroughWall {
                    frame: i,
                    from: q,
                    to: p,
                    distance: d,
                    needed: r,
                    wall_feature: w.wall_feature,
                });
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
