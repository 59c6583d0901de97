//! What a position really sees, by brute-force ray casting, and how much of it a visibility
//! table's VIS(T) holds: the ground truth of Koch–Teller §4.3's tables on models of any origin.
//!
//! In: a model, its [`Occluders`], eye positions, a visibility table. Out: per segment whether any of
//! it is visible from the eye and the angle its visible runs subtend ([`visible_segments`]); the
//! recall of VIS(T) over those segments ([`recall`]).
//!
//! A segment is visible from a position if any sample point along it (samples at most 0.5° apart
//! as seen from the position, at most 2,000 per segment) within range is unoccluded: a ray from
//! the position stops short of it by 1 mm without hitting a face. Its visible extent is the angle
//! subtended by runs of consecutive unoccluded samples. Recall counts those whose extent exceeds
//! 2° (smaller ones no edge detector finds) and, separately, all visible segments.

use nalgebra::{Point3, Vector3};
use omnitrack_core::model::Model;
use omnitrack_tracker::visibility::build::Occluders;
use omnitrack_tracker::visibility::VisibilityTable;

/// Per model segment: (visible at all, visible extent in radians).
pub fn visible_segments(scene: &Occluders, model: &Model, eye: &Point3<f64>, range_m: f64) -> Vec<(bool, f64)> {
    let step_rad = 0.5f64.to_radians();
    model
        .segments
        .iter()
        .map(|s| {
            let ab = s.b - s.a;
            let len = ab.norm();
            // Nearest distance for a quick range reject.
            let t = ((eye - s.a).dot(&ab) / (len * len)).clamp(0.0, 1.0);
            let near = (s.a + ab * t - eye).norm();
            if near > range_m {
                return (false, 0.0);
            }
            let n = ((len / (near.max(0.05) * step_rad)).ceil() as usize).clamp(1, 2000);
            let mut any = false;
            let mut extent = 0.0;
            let mut prev: Option<Vector3<f64>> = None;
            for k in 0..=n {
                let p = s.a + ab * (k as f64 / n as f64);
                let d = p - eye;
                let dist = d.norm();
                let visible = dist <= range_m && dist > 1e-6 && scene.clear_line(eye, &(eye + d * (1.0 - 1e-3 / dist)));
                if visible {
                    any = true;
                    if let Some(q) = prev {
                        extent += q.angle(&d);
                    }
                    prev = Some(d);
                } else {
                    prev = None;
                }
            }
            (any, extent)
        })
        .collect()
}

/// Recall of VIS(T) against brute force over some positions.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Recall {
    /// Visible segments (summed over positions) whose extent exceeds 2°, and how many of them
    /// VIS(T) held.
    pub visible_big: usize,
    pub held_big: usize,
    /// All visible segments, and how many VIS(T) held.
    pub visible_all: usize,
    pub held_all: usize,
    /// Ids in VIS(T) (summed), and how many of them are visible at all (precision).
    pub in_sets: usize,
    pub in_sets_visible: usize,
    /// Positions with no valid node to serve them.
    pub unserved: usize,
}

impl Recall {
    /// Recall over segments wider than 2°, percent.
    pub fn big_percent(&self) -> f64 {
        100.0 * self.held_big as f64 / self.visible_big.max(1) as f64
    }
    /// Recall over every visible segment, percent.
    pub fn all_percent(&self) -> f64 {
        100.0 * self.held_all as f64 / self.visible_all.max(1) as f64
    }
    /// Precision of VIS(T), percent.
    pub fn precision_percent(&self) -> f64 {
        100.0 * self.in_sets_visible as f64 / self.in_sets.max(1) as f64
    }
}

/// The recall of `table`'s VIS(T) at `eyes` (the table's own range); positions no node serves
/// count every segment they see as missed.
pub fn recall(table: &VisibilityTable, scene: &Occluders, model: &Model, eyes: &[Point3<f64>]) -> Recall {
    let big = 2f64.to_radians();
    let range = table.header.max_range_m;
    let mut r = Recall::default();
    for eye in eyes {
        let truth = visible_segments(scene, model, eye, range);
        let set = table.query(eye);
        if set.is_none() {
            r.unserved += 1;
        }
        let held = |s: usize| {
            set.as_ref()
                .is_some_and(|v| v.segments.binary_search(&(s as u32)).is_ok())
        };
        for (s, &(v, extent)) in truth.iter().enumerate() {
            if !v {
                continue;
            }
            let h = held(s);
            r.visible_all += 1;
            r.held_all += h as usize;
            if extent > big {
                r.visible_big += 1;
                r.held_big += h as usize;
            }
        }
        if let Some(v) = &set {
            r.in_sets += v.segments.len();
            r.in_sets_visible += v.segments.iter().filter(|&&s| truth[s as usize].0).count();
        }
    }
    r
}
