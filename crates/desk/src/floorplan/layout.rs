//! Geometry across features: a parsed [`FloorPlan`] in; out, per wall, its straight pieces, where
//! its faces end at each axis point (mitred at a corner, trimmed to the face of a wall it ends on,
//! or capped) and the openings on each piece; or a [`FloorPlanError`] naming the feature when a
//! wall cannot be joined or an opening lies on no wall.

use super::plan::{FloorPlan, Opening, Wall};
use super::{xy, FloorPlanError, MIN_M};
use nalgebra::{Point2, Vector2};

/// An opening's ends may stray this far from a thin wall's axis (hand-typed or snapped
/// coordinates); a thick wall allows half its thickness, so the ends may be drawn on a face.
const OPENING_TOLERANCE_M: f64 = 0.05;
/// A wall end this close to another wall's axis abuts it. Tight, because a looser test would
/// capture ends meant to stop short of a wall.
const JOIN_TOLERANCE_M: f64 = 1e-3;
/// Lengths below this are zero: far above rounding of plan-sized numbers.
const EPS_M: f64 = 1e-6;

/// One straight piece of a wall axis.
pub(super) struct Piece {
    pub start: Point2<f64>,
    /// Unit direction and its left normal (the wall's +n face is on this side).
    pub u: Vector2<f64>,
    pub n: Vector2<f64>,
    pub len: f64,
}

fn left_of(v: Vector2<f64>) -> Vector2<f64> {
    Vector2::new(-v.y, v.x)
}

pub(super) fn pieces(w: &Wall) -> Vec<Piece> {
    let m = w.axis.len();
    let count = if w.closed { m } else { m - 1 };
    (0..count)
        .map(|i| {
            let (a, b) = (w.axis[i], w.axis[(i + 1) % m]);
            let len = (b - a).norm();
            let u = (b - a) / len;
            Piece {
                start: a,
                u,
                n: left_of(u),
                len,
            }
        })
        .collect()
}

/// Where a wall's two faces end at one axis point: `left` on the +n side, `right` on the −n side
/// (the same point for a thin wall). `cap` marks a free end of a thick wall, closed by an end face.
#[derive(Clone, Copy)]
pub(super) struct Joint {
    pub left: Point2<f64>,
    pub right: Point2<f64>,
    pub cap: bool,
}

impl Joint {
    pub fn side(&self, k: f64) -> Point2<f64> {
        if k < 0.0 {
            self.right
        } else {
            self.left
        }
    }
}

/// A wall ready to emit: its pieces, one joint per axis point, and the openings on each piece
/// as `(opening index, s0, s1)` along the piece, sorted.
pub(super) struct Laid {
    pub pieces: Vec<Piece>,
    pub joints: Vec<Joint>,
    pub openings: Vec<Vec<(usize, f64, f64)>>,
}

/// The plan with its walls cut into pieces; `file` names the plan in error messages.
pub(super) struct Layout<'a> {
    pub plan: &'a FloorPlan,
    pub file: &'a str,
    pub pieces: Vec<Vec<Piece>>,
}

impl Layout<'_> {
    fn err(&self, feature: usize, kind: &str, message: impl Into<String>) -> FloorPlanError {
        FloorPlanError {
            file: self.file.to_string(),
            place: format!("features[{feature}] ({kind}): "),
            message: message.into(),
        }
    }

    fn wall_name(&self, w: usize) -> String {
        format!("features[{}] (wall)", self.plan.walls[w].feature)
    }

    fn joints(&self, w: usize) -> Result<Vec<Joint>, FloorPlanError> {
        let wall = &self.plan.walls[w];
        let ps = &self.pieces[w];
        let h = wall.thickness_m / 2.0;
        let m = wall.axis.len();
        let mut joints = Vec::with_capacity(m);
        for i in 0..m {
            let p = wall.axis[i];
            let end_piece = if wall.closed {
                None
            } else if i == 0 {
                Some(0)
            } else if i == m - 1 {
                Some(ps.len() - 1)
            } else {
                None
            };
            let joint = match end_piece {
                None => {
                    let (a, b) = (&ps[(i + ps.len() - 1) % ps.len()], &ps[i % ps.len()]);
                    let cos = a.n.dot(&b.n);
                    if cos < -1.0 + 1e-9 {
                        return Err(self.err(wall.feature, "wall", format!("turns back on itself at ({})", xy(&p))));
                    }
                    // Its projection on both pieces' normals is exactly 1, so ±h times it lies on
                    // both pieces' offset faces: the mitre line.
                    let mitre = (a.n + b.n) / (1.0 + cos);
                    Joint {
                        left: p + h * mitre,
                        right: p - h * mitre,
                        cap: false,
                    }
                }
                Some(k) => self.end_joint(w, k, p, h)?,
            };
            joints.push(joint);
        }
        Ok(joints)
    }

    /// The joint at a free end of wall `w`, whose end piece is `k`: trimmed to the surface of a
    /// wall whose axis it ends on (a T-junction, no cap), or capped.
    fn end_joint(&self, w: usize, k: usize, end: Point2<f64>, h: f64) -> Result<Joint, FloorPlanError> {
        let wall = &self.plan.walls[w];
        let piece = &self.pieces[w][k];
        let thick = h > 0.0;
        let mut corner_meeting = None;
        for (v, other) in self.plan.walls.iter().enumerate() {
            for (q, target) in self.pieces[v].iter().enumerate() {
                if v == w && q == k {
                    continue;
                }
                let rel = end - target.start;
                let (along, across) = (rel.dot(&target.u), rel.dot(&target.n));
                if across.abs() > JOIN_TOLERANCE_M || along < -JOIN_TOLERANCE_M || along > target.len + JOIN_TOLERANCE_M
                {
                    continue;
                }
                if along < JOIN_TOLERANCE_M || along > target.len - JOIN_TOLERANCE_M {
                    // At a vertex of the other axis: no single surface to stop at.
                    if thick || other.thickness_m > 0.0 {
                        corner_meeting.get_or_insert(v);
                    }
                    continue;
                }
                let sin = piece.u.dot(&target.n);
                if sin.abs() < (1.0f64).to_radians().sin() {
                    return Err(self.err(
                        wall.feature,
                        "wall",
                        format!(
                            "ends at ({}) on {} but runs along it (less than 1° apart)",
                            xy(&end),
                            self.wall_name(v)
                        ),
                    ));
                }
                // Stop at the other wall's face on the side this wall comes from.
                let inner = if end == piece.start {
                    piece.start + piece.len * piece.u
                } else {
                    piece.start
                };
                let side = if (inner - target.start).dot(&target.n) > 0.0 {
                    1.0
                } else {
                    -1.0
                };
                let surface = side * other.thickness_m / 2.0;
                let at = |offset: f64| {
                    let base = piece.start + offset * piece.n;
                    let s = (surface - (base - target.start).dot(&target.n)) / sin;
                    base + s * piece.u
                };
                return Ok(Joint {
                    left: at(h),
                    right: at(-h),
                    cap: false,
                });
            }
        }
        if let Some(v) = corner_meeting {
            return Err(self.err(
                wall.feature,
                "wall",
                format!(
                    "ends at ({}) on an end or corner of {}: continue one LineString through the \
                     corner so it is mitred, or end the wall on the middle of the other's axis",
                    xy(&end),
                    self.wall_name(v)
                ),
            ));
        }
        Ok(Joint {
            left: end + h * piece.n,
            right: end - h * piece.n,
            cap: thick,
        })
    }

    /// The wall piece an opening lies on, and its extent `(s0, s1)` along that piece.
    fn place_opening(&self, o: &Opening) -> Option<(usize, usize, f64, f64)> {
        let mut best: Option<(f64, usize, usize, f64, f64)> = None;
        for (w, wall) in self.plan.walls.iter().enumerate() {
            let tol = OPENING_TOLERANCE_M.max(wall.thickness_m / 2.0);
            for (k, piece) in self.pieces[w].iter().enumerate() {
                let [sa, sb] = o.ends.map(|e| (e - piece.start).dot(&piece.u));
                let [da, db] = o.ends.map(|e| (e - piece.start).dot(&piece.n).abs());
                let on = |s: f64, d: f64| d <= tol && s >= -tol && s <= piece.len + tol;
                if on(sa, da) && on(sb, db) && best.is_none_or(|b| da.max(db) < b.0) {
                    best = Some((da.max(db), w, k, sa.min(sb), sa.max(sb)));
                }
            }
        }
        best.map(|(_, w, k, s0, s1)| (w, k, s0, s1))
    }

    /// Every wall laid out, in the plan's order, after every cross-feature check.
    pub fn lay_out(&self) -> Result<Vec<Laid>, FloorPlanError> {
        let plan = self.plan;
        let mut laid = Vec::with_capacity(plan.walls.len());
        for (w, wall) in plan.walls.iter().enumerate() {
            let joints = self.joints(w)?;
            let ps = &self.pieces[w];
            for (k, piece) in ps.iter().enumerate() {
                let (j0, j1) = (&joints[k], &joints[(k + 1) % joints.len()]);
                for side in [j0.left - j1.left, j0.right - j1.right] {
                    if side.dot(&piece.u) > -MIN_M {
                        return Err(self.err(
                            wall.feature,
                            "wall",
                            format!(
                                "the piece from ({}) to ({}) is too short for the wall's thickness and \
                                 joins: one face has no length left",
                                xy(&piece.start),
                                xy(&(piece.start + piece.len * piece.u))
                            ),
                        ));
                    }
                }
            }
            laid.push(Laid {
                pieces: pieces(wall),
                joints,
                openings: vec![Vec::new(); ps.len()],
            });
        }

        for (i, o) in plan.openings.iter().enumerate() {
            let kind = o.kind.name();
            let Some((w, k, s0, s1)) = self.place_opening(o) else {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "not on any wall: its ends ({}) and ({}) are not both within max(5 cm, half \
                         the thickness) of one straight piece of a wall axis",
                        xy(&o.ends[0]),
                        xy(&o.ends[1])
                    ),
                ));
            };
            let wall = &plan.walls[w];
            if s1 - s0 < MIN_M {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "runs across {} instead of along it: its extent along the axis is under 1 mm",
                        self.wall_name(w)
                    ),
                ));
            }
            if o.head_height_m > wall.height_m + EPS_M {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "head_height_m {} is above the height {} of {}",
                        o.head_height_m,
                        wall.height_m,
                        self.wall_name(w)
                    ),
                ));
            }
            let piece = &self.pieces[w][k];
            let l = &laid[w];
            let (j0, j1) = (&l.joints[k], &l.joints[(k + 1) % l.joints.len()]);
            let start = (j0.left - piece.start)
                .dot(&piece.u)
                .max((j0.right - piece.start).dot(&piece.u));
            let end = (j1.left - piece.start)
                .dot(&piece.u)
                .min((j1.right - piece.start).dot(&piece.u));
            if s0 < start + MIN_M || s1 > end - MIN_M {
                return Err(self.err(
                    o.feature,
                    kind,
                    format!(
                        "reaches past the end of {}'s faces (a wall must extend beyond its openings)",
                        self.wall_name(w)
                    ),
                ));
            }
            laid[w].openings[k].push((i, s0, s1));
        }

        for (w, l) in laid.iter_mut().enumerate() {
            for list in &mut l.openings {
                list.sort_by(|a, b| a.1.total_cmp(&b.1));
                for pair in list.windows(2) {
                    let ((i, _, s1), (j, s0, _)) = (pair[0], pair[1]);
                    if s0 < s1 + MIN_M {
                        let (a, b) = (&plan.openings[i], &plan.openings[j]);
                        let (first, second) = if a.feature < b.feature { (a, b) } else { (b, a) };
                        return Err(self.err(
                            second.feature,
                            second.kind.name(),
                            format!(
                                "overlaps or touches features[{}] ({}) on {}",
                                first.feature,
                                first.kind.name(),
                                self.wall_name(w)
                            ),
                        ));
                    }
                }
            }
        }
        Ok(laid)
    }
}
