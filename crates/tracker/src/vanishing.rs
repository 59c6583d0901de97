//! Rotation hypotheses from vanishing directions: a third way for the initialisation to find
//! poses, beside the triplet sampling of Figure 4 and the translation vote (beyond the papers).
//!
//! In: the model's segments (once, at start-up) and one frame's edges. Out: a few rotations
//! `R_world_rig` that put the frame's dominant line directions onto the model's, for the
//! translation vote (module `vote`) to find positions under.
//!
//! Why: buildings are drawn from few directions (the vertical and one to a few horizontal
//! ones), so their edges meet in few vanishing points. A line of direction d (world) seen by the
//! rig lies in an edge plane whose normal n satisfies n · Rᵀd = 0: every edge of one direction
//! has its normal at right angles to the same rig-frame vector. Real photographs add textures
//! (floorboards, blinds, tiles) whose edges outshine the walls' and defeat triplets of the
//! strongest edges, but those textures run along the building's own directions: they reinforce
//! the vanishing points instead of hiding them. Measured on the real panoramas of the ZInD
//! benchmark, the triplet sampling's candidates held the truth for 1 of 32 panoramas; see
//! docs/decisions.md ("initialisation on real photographs") for what this adds.
//!
//! How:
//! 1. The vertical: each pair of the longest edges proposes the vector at right angles to both
//!    normals; proposals too tilted to be the vertical are vanishing directions of other lines,
//!    and the best few of them propose the vertical at right angles to two of them (where the
//!    longest edges are all horizontal). Of the proposals within `max_tilt` of the rig's up
//!    axis, the one that explains the most edge length as a Manhattan frame wins — the edges
//!    along it (normal within [`AGREE_RAD`] of a right angle) plus, levelled by it, the edges
//!    along the strongest horizontal direction and the one at right angles to it — refined as
//!    the least eigenvector of the agreeing normals' scatter.
//! 2. The horizontals: every other edge, if its line is horizontal, runs along n × up; the
//!    azimuths of those directions about the vertical (modulo π), weighted by edge length,
//!    peak at the frame's horizontal vanishing directions.
//! 3. The model's horizontal directions: azimuths of its non-vertical segments, weighted by
//!    length, peaked the same way (at start-up).
//! 4. Each of the frame's best peaks against each of the model's, both ways round: a yaw; the
//!    rotation levels the vertical and turns by that yaw. A Manhattan building gives four
//!    rotations a quarter turn apart, which the vote and the scoring tell apart.
//!
//! Fixed memory: the histograms and the pair list are sized at start-up.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use omnitrack_core::model::Model;
use omnitrack_edges::Edge;

/// An edge agrees with a direction when its normal is within this of a right angle to it (rad).
const AGREE_RAD: f64 = 1.5 * std::f64::consts::PI / 180.0;
/// Edges at least this close to the vertical direction count as vertical, not horizontal (rad).
const VERTICAL_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Directions too tilted for the vertical kept to propose it at right angles to two of them.
const HORIZONTAL_PROPOSALS: usize = 8;
/// A horizontal direction gathers the edges within this many azimuth bins of it (± 2°).
const MANHATTAN_BINS: usize = 2;
/// The longest edges whose pairs propose the vertical.
const PROPOSERS: usize = 32;
/// Azimuth histogram: one bin per degree over [0, π).
const BINS: usize = 180;
/// Peaks of a histogram are at least this many bins apart and at least this share of the
/// highest.
const PEAK_SEPARATION_BINS: usize = 10;
const PEAK_SHARE: f64 = 0.25;
/// A peak's azimuth is the mean of the directions within this of its bin (rad).
const REFINE_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Peaks used: of the frame, of the model.
const FRAME_PEAKS: usize = 2;
const MODEL_PEAKS: usize = 4;
/// Most rotations returned.
pub(super) const MAX_ROTATIONS: usize = 8;
/// Two rotations closer than this are one (rad).
const SAME_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;

/// The model's horizontal directions and the per-frame buffers.
pub(super) struct VanishingDirections {
    /// Azimuths (rad, [0, π)) of the model's dominant horizontal directions, strongest first.
    model_azimuths: Vec<f64>,
    hist: Vec<f64>,
    longest: Vec<(f64, u32)>,
}

impl VanishingDirections {
    pub fn new(model: &Model, max_edges: usize) -> VanishingDirections {
        let mut hist = vec![0.0; BINS];
        for s in &model.segments {
            let d = s.b - s.a;
            let len = d.norm();
            if len < 1e-9 || d.z.abs() > len * VERTICAL_RAD.sin() {
                continue;
            }
            // Slanted segments (a stair's string) project shortened; their azimuth still
            // names a direction the building is drawn in.
            hist[azimuth_bin(d.y.atan2(d.x))] += d.xy().norm();
        }
        let mut peaks = [0usize; MODEL_PEAKS];
        let n = find_peaks(&hist, &mut peaks);
        let directions = || {
            model.segments.iter().filter_map(|s| {
                let d = s.b - s.a;
                let len = d.norm();
                (len >= 1e-9 && d.z.abs() <= len * VERTICAL_RAD.sin()).then(|| (d.y.atan2(d.x), d.xy().norm()))
            })
        };
        VanishingDirections {
            model_azimuths: peaks[..n]
                .iter()
                .map(|&b| refine(bin_azimuth(b), directions()))
                .collect(),
            hist,
            longest: omnitrack_core::memory::resident(Vec::with_capacity(max_edges)),
        }
    }

    /// Rotations `R_world_rig` that put the frame's vertical on the world's and its horizontal
    /// vanishing directions on the model's, at most `max_tilt` (rad) from upright; written into
    /// `out`, returns how many.
    pub fn rotations(
        &mut self,
        edges: &[Edge],
        max_tilt: f64,
        out: &mut [UnitQuaternion<f64>; MAX_ROTATIONS],
    ) -> usize {
        if self.model_azimuths.is_empty() || edges.len() < 4 {
            return 0;
        }
        let Some(up) = self.vertical(edges, max_tilt) else {
            return 0;
        };
        // Level: the rotation taking the rig's vertical onto the world's z.
        let level = UnitQuaternion::rotation_between(&up, &Vector3::z())
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
        self.hist.iter_mut().for_each(|h| *h = 0.0);
        let sin_vertical = VERTICAL_RAD.sin();
        for e in edges {
            let n = level * e.plane.normal.into_inner();
            // A vertical line's plane holds the world's z: its normal is horizontal.
            if n.z.abs() < sin_vertical {
                continue;
            }
            // If the line is horizontal, it runs along n × z.
            let d = n.cross(&Vector3::z());
            if d.norm() < 1e-9 {
                continue;
            }
            self.hist[azimuth_bin(d.y.atan2(d.x))] += e.length_rad;
        }
        let mut peaks = [0usize; FRAME_PEAKS];
        let found = find_peaks(&self.hist, &mut peaks);
        let mut count = 0;
        for &p in &peaks[..found] {
            let a = refine(
                bin_azimuth(p),
                edges.iter().filter_map(|e| {
                    let n = level * e.plane.normal.into_inner();
                    let d = n.cross(&Vector3::z());
                    (n.z.abs() >= sin_vertical && d.norm() > 1e-9).then(|| (d.y.atan2(d.x), e.length_rad))
                }),
            );
            for &b in &self.model_azimuths {
                for half in [0.0, std::f64::consts::PI] {
                    let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), b - a + half);
                    let r = yaw * level;
                    if count < out.len() && out[..count].iter().all(|o| o.angle_to(&r) > SAME_RAD) {
                        out[count] = r;
                        count += 1;
                    }
                }
            }
        }
        count
    }

    /// The rig-frame vertical: the direction at right angles to the most edge length, within
    /// `max_tilt` of the rig's z.
    fn vertical(&mut self, edges: &[Edge], max_tilt: f64) -> Option<Vector3<f64>> {
        self.longest.clear();
        for (i, e) in edges.iter().enumerate() {
            if self.longest.len() < self.longest.capacity() {
                self.longest.push((e.length_rad, i as u32));
            }
        }
        let k = PROPOSERS.min(self.longest.len());
        if k < 2 {
            return None;
        }
        self.longest.select_nth_unstable_by(k - 1, |a, b| b.0.total_cmp(&a.0));
        let sin_agree = AGREE_RAD.sin();
        let min_up = max_tilt.min(std::f64::consts::FRAC_PI_2).cos();
        let mut hist = std::mem::take(&mut self.hist);
        let mut support = |v: &Vector3<f64>| manhattan_support(edges, v, sin_agree, &mut hist);
        let along = |v: &Vector3<f64>| -> f64 {
            edges
                .iter()
                .filter(|e| e.plane.normal.dot(v).abs() < sin_agree)
                .map(|e| e.length_rad)
                .sum()
        };
        let mut best: Option<(f64, Vector3<f64>)> = None;
        // Directions too tilted to be the vertical are the frame's other vanishing directions:
        // the best few are kept, and the vertical is also proposed at right angles to two of
        // them. Where the longest edges are all horizontal (a garage door's panels, a corridor's
        // floor and ceiling lines) no pair of them proposes the vertical directly.
        let mut others = [(0.0f64, Vector3::zeros()); HORIZONTAL_PROPOSALS];
        for i in 0..k {
            for j in i + 1..k {
                let (a, b) = (&edges[self.longest[i].1 as usize], &edges[self.longest[j].1 as usize]);
                let Some(mut v) = a.plane.normal.cross(&b.plane.normal).try_normalize(1e-6) else {
                    continue;
                };
                if v.z < 0.0 {
                    v = -v;
                }
                if v.z < min_up {
                    let s = along(&v);
                    if let Some(slot) = others
                        .iter_mut()
                        .find(|o| o.0 > 0.0 && o.1.dot(&v).abs() > SAME_RAD.cos())
                    {
                        if s > slot.0 {
                            *slot = (s, v);
                        }
                    } else if let Some(slot) = others.iter_mut().min_by(|x, y| x.0.total_cmp(&y.0)) {
                        if s > slot.0 {
                            *slot = (s, v);
                        }
                    }
                    continue;
                }
                let s = support(&v);
                if best.is_none_or(|(bs, _)| s > bs) {
                    best = Some((s, v));
                }
            }
        }
        for i in 0..others.len() {
            for j in i + 1..others.len() {
                if others[i].0 <= 0.0 || others[j].0 <= 0.0 {
                    continue;
                }
                let Some(mut v) = others[i].1.cross(&others[j].1).try_normalize(1e-6) else {
                    continue;
                };
                if v.z < 0.0 {
                    v = -v;
                }
                if v.z < min_up {
                    continue;
                }
                let s = support(&v);
                if best.is_none_or(|(bs, _)| s > bs) {
                    best = Some((s, v));
                }
            }
        }
        self.hist = hist;
        let (_, v) = best?;
        // Refine: the direction at right angles to the agreeing normals in the least squares.
        let mut scatter = Matrix3::zeros();
        for e in edges {
            let n = e.plane.normal.into_inner();
            if n.dot(&v).abs() < sin_agree {
                scatter += n * n.transpose() * e.length_rad;
            }
        }
        let eig = scatter.symmetric_eigen();
        let (k_min, _) = eig.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
        let mut refined = eig.eigenvectors.column(k_min).into_owned();
        if refined.dot(&v) < 0.0 {
            refined = -refined;
        }
        (refined.z >= min_up).then_some(refined).or(Some(v))
    }
}

/// How much edge length a building whose vertical is `v` would explain: the edges along `v`,
/// plus, of the others taken as horizontal lines, those along the strongest horizontal
/// direction and the one at right angles to it (within [`MANHATTAN_BINS`] bins). The edges
/// along the vertical alone are not enough: in a room of few, short vertical edges (a garage:
/// one door, long horizontal panels) a direction 56° off lay on more edge length than the true
/// vertical, which has its evidence in the horizontal lines it levels into two directions.
/// `hist` is scratch of [`BINS`] bins.
fn manhattan_support(edges: &[Edge], v: &Vector3<f64>, sin_agree: f64, hist: &mut [f64]) -> f64 {
    hist.iter_mut().for_each(|h| *h = 0.0);
    let a = v
        .cross(&Vector3::x())
        .try_normalize(1e-6)
        .unwrap_or_else(|| v.cross(&Vector3::y()).normalize());
    let b = v.cross(&a);
    let mut vertical = 0.0;
    for e in edges {
        let n = e.plane.normal.into_inner();
        if n.dot(v).abs() < sin_agree {
            vertical += e.length_rad;
            continue;
        }
        let d = n.cross(v);
        if d.norm() < 1e-9 {
            continue;
        }
        hist[azimuth_bin(d.dot(&b).atan2(d.dot(&a)))] += e.length_rad;
    }
    let window = |centre: usize| -> f64 {
        (0..2 * MANHATTAN_BINS + 1)
            .map(|k| hist[(centre + BINS + k - MANHATTAN_BINS) % BINS])
            .sum()
    };
    let best = (0..BINS / 2)
        .map(|c| window(c) + window(c + BINS / 2))
        .fold(0.0, f64::max);
    vertical + best
}

fn azimuth_bin(azimuth: f64) -> usize {
    let a = azimuth.rem_euclid(std::f64::consts::PI);
    ((a / std::f64::consts::PI * BINS as f64) as usize).min(BINS - 1)
}

/// The azimuth of a bin's centre.
fn bin_azimuth(bin: usize) -> f64 {
    (bin as f64 + 0.5) * std::f64::consts::PI / BINS as f64
}

/// The weighted mean (modulo π) of the (azimuth, weight) pairs within [`REFINE_RAD`] of
/// `peak`: the bins are a degree wide, the directions of a building's lines agree far better.
fn refine(peak: f64, directions: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut s, mut c) = (0.0, 0.0);
    for (a, w) in directions {
        // Doubled angles make a and a + π one direction.
        let d = (2.0 * (a - peak)).sin().atan2((2.0 * (a - peak)).cos()) / 2.0;
        if d.abs() <= REFINE_RAD {
            s += w * (2.0 * a).sin();
            c += w * (2.0 * a).cos();
        }
    }
    if s == 0.0 && c == 0.0 {
        peak
    } else {
        (0.5 * s.atan2(c)).rem_euclid(std::f64::consts::PI)
    }
}

/// The highest bins of a circular histogram (smoothed over three bins), at least
/// [`PEAK_SEPARATION_BINS`] apart and [`PEAK_SHARE`] of the highest; returns how many.
fn find_peaks(hist: &[f64], out: &mut [usize]) -> usize {
    let smooth = |k: usize| hist[(k + BINS - 1) % BINS] + 2.0 * hist[k] + hist[(k + 1) % BINS];
    let mut found = 0;
    let mut top = 0.0;
    while found < out.len() {
        let mut best: Option<(f64, usize)> = None;
        for k in 0..BINS {
            let far = out[..found].iter().all(|&p| {
                let d = k.abs_diff(p);
                d.min(BINS - d) >= PEAK_SEPARATION_BINS
            });
            let v = smooth(k);
            if far && v > 0.0 && best.is_none_or(|(b, _)| v > b) {
                best = Some((v, k));
            }
        }
        let Some((v, k)) = best else { break };
        if found == 0 {
            top = v;
        } else if v < PEAK_SHARE * top {
            break;
        }
        out[found] = k;
        found += 1;
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Translation3, Unit};
    use omnitrack_core::geometry::{EdgePlane, Pose};
    use omnitrack_core::model::{ModelStats, Segment};

    /// A box room 6 × 4 × 2.5 m turned by 20° about the vertical: its twelve edges.
    fn room() -> Model {
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 20f64.to_radians());
        let c = |x: f64, y: f64, z: f64| Point3::from(turn * Vector3::new(x, y, z));
        let corners = [(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)];
        let mut segments = Vec::new();
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            for z in [0.0, 2.5] {
                segments.push(Segment {
                    a: c(a.0, a.1, z),
                    b: c(b.0, b.1, z),
                    faces: vec![],
                });
            }
            segments.push(Segment {
                a: c(a.0, a.1, 0.0),
                b: c(a.0, a.1, 2.5),
                faces: vec![],
            });
        }
        Model {
            vertices: vec![],
            faces: vec![],
            segments,
            labels: vec![String::new()],
            stats: ModelStats::default(),
        }
    }

    fn edges_seen(model: &Model, pose: &Pose) -> Vec<Edge> {
        let inv = pose.inverse();
        model
            .segments
            .iter()
            .map(|s| {
                let (a, b) = ((inv * s.a).coords.normalize(), (inv * s.b).coords.normalize());
                let plane = EdgePlane {
                    normal: Unit::new_normalize(a.cross(&b)),
                    centre: Point3::origin(),
                    ends: [Unit::new_normalize(a), Unit::new_normalize(b)],
                };
                crate::test_edges::edge_on(0, plane, 10)
            })
            .collect()
    }

    #[test]
    fn a_tilted_rig_in_a_turned_room_gets_its_rotation_among_four_quarter_turns() {
        let model = room();
        let truth = Pose::from_parts(
            Translation3::new(2.0, 2.5, 1.5),
            UnitQuaternion::from_euler_angles(0.08, -0.05, 1.1),
        );
        let edges = edges_seen(&model, &truth);
        let mut vd = VanishingDirections::new(&model, edges.len());
        let mut out = [UnitQuaternion::identity(); MAX_ROTATIONS];
        let n = vd.rotations(&edges, 30f64.to_radians(), &mut out);
        assert!((2..=MAX_ROTATIONS).contains(&n), "{n} rotations");
        let best = out[..n]
            .iter()
            .map(|r| r.angle_to(&truth.rotation).to_degrees())
            .fold(f64::INFINITY, f64::min);
        assert!(best < 0.5, "nearest rotation {best}° off");
        // Every hypothesis is level: the rig's vertical goes to the world's.
        for r in &out[..n] {
            let up = r * (truth.rotation.inverse() * Vector3::z());
            assert!(up.z > (0.5f64).to_radians().cos(), "{up:?}");
        }
    }

    /// A frame without one vertical edge (a garage: long horizontal panels, short or no
    /// corners): no pair of its edges proposes the vertical, which comes from two of its
    /// horizontal vanishing directions instead.
    #[test]
    fn a_frame_of_horizontal_lines_alone_still_gets_its_vertical() {
        let model = room();
        let truth = Pose::from_parts(
            Translation3::new(2.0, 2.5, 1.5),
            UnitQuaternion::from_euler_angles(0.06, 0.04, 0.7),
        );
        let up_rig = truth.rotation.inverse() * Vector3::z();
        let edges: Vec<Edge> = edges_seen(&model, &truth)
            .into_iter()
            .filter(|e| e.plane.normal.dot(&up_rig).abs() > 0.2)
            .collect();
        assert!(edges.len() >= 6, "{} horizontal edges", edges.len());
        let mut vd = VanishingDirections::new(&model, edges.len());
        let mut out = [UnitQuaternion::identity(); MAX_ROTATIONS];
        let n = vd.rotations(&edges, 60f64.to_radians(), &mut out);
        let best = out[..n]
            .iter()
            .map(|r| r.angle_to(&truth.rotation).to_degrees())
            .fold(f64::INFINITY, f64::min);
        assert!(best < 0.5, "nearest of {n} rotations {best}° off");
    }

    #[test]
    fn too_few_edges_or_no_horizontal_model_direction_give_nothing() {
        let model = room();
        let mut vd = VanishingDirections::new(&model, 8);
        let mut out = [UnitQuaternion::identity(); MAX_ROTATIONS];
        assert_eq!(vd.rotations(&[], 0.5, &mut out), 0);
        let posts = Model {
            segments: model
                .segments
                .iter()
                .filter(|s| (s.b - s.a).z.abs() > 1.0)
                .cloned()
                .collect(),
            ..model
        };
        let mut vd = VanishingDirections::new(&posts, 8);
        let edges = edges_seen(&posts, &Pose::identity());
        assert_eq!(vd.rotations(&edges, 0.5, &mut out), 0);
    }
}
