//! Pose from line correspondences: Kumar & Hanson 1989 (R_then_T, R_and_T, Med_R_and_T and the
//! uncertainty of §5) and Koch & Teller 2007 (ξ of eq. 1 minimised by a simplex, the sample count
//! of eq. 2, random consensus sampling), for a generalised camera: every observation is an
//! [`EdgePlane`] through its own sensor's centre.
//!
//! In: [`Correspondence`]s (edge plane in the rig frame ↔ model segment in the world frame), an
//! optional pose guess, [`SolverOptions`]. Out: [`Solution`]: `T_world_rig`, its 6×6 covariance,
//! the inliers used, ξ and the iteration count.
//!
//! Beyond the papers: [`r_and_t_cauchy`], R_and_T by iteratively reweighted least squares with
//! Cauchy's loss, for the tracker's final fit against a coarse model.
//!
//! Layout: [`minimal`] (closed-form poses from minimal samples), [`refine`] (least squares from
//! a start, and the covariance), [`robust`] (estimators for correspondences with outliers).
//! Each imports only the ones before it: `minimal` none, `refine` none of the others, `robust`
//! both.
//!
//! Internally the unknown is `T_rig_world = (Q, s)`, so that an end point P of a segment seen by
//! a sensor centred at c gives Kumar–Hanson's residual `n · (Q P + s − c)`, linear in s — their
//! `N · (R p + T)` with the sensor offset added; a single camera at the rig origin is c = 0.
//!
//! A pose from the twelve edges of a 6 × 4 × 2.7 m room seen by one sensor at the rig's centre,
//! without a starting guess (`examples/solve_pose.rs` adds wrong matches):
//!
//! ```
//! use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
//! use omnitrack_core::geometry::Pose;
//! use omnitrack_solver::{med_r_and_t, Correspondence, EdgePlane, SolverOptions};
//!
//! let corner = |x: f64, y: f64, z: f64| Point3::new(6.0 * x, 4.0 * y, 2.7 * z);
//! let floor = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
//! let mut segments = Vec::new();
//! for i in 0..4 {
//!     let ((ax, ay), (bx, by)) = (floor[i], floor[(i + 1) % 4]);
//!     segments.push([corner(ax, ay, 0.0), corner(bx, by, 0.0)]);
//!     segments.push([corner(ax, ay, 1.0), corner(bx, by, 1.0)]);
//!     segments.push([corner(ax, ay, 0.0), corner(ax, ay, 1.0)]);
//! }
//! let truth = Pose::from_parts(
//!     Translation3::new(2.0, 1.5, 1.5),
//!     UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5),
//! );
//! // Each edge: the plane through the sensor's centre and the segment, in the rig frame.
//! let lines: Vec<Correspondence> = segments
//!     .iter()
//!     .map(|s| {
//!         let (a, b) = (truth.inverse_transform_point(&s[0]), truth.inverse_transform_point(&s[1]));
//!         let edge = EdgePlane::from_rays(Point3::origin(), &a.coords, &b.coords).unwrap();
//!         Correspondence { edge, segment: *s }
//!     })
//!     .collect();
//! let solution = med_r_and_t(&lines, None, &SolverOptions::default(), 1)?;
//! assert!((solution.pose.translation.vector - truth.translation.vector).norm() < 1e-6);
//! assert!(solution.pose.rotation.angle_to(&truth.rotation) < 1e-6);
//! assert_eq!(solution.inliers.len(), 12);
//! # Ok::<(), omnitrack_solver::SolveError>(())
//! ```

use nalgebra::Matrix6;
use omnitrack_core::geometry::Pose;
pub use omnitrack_core::geometry::{xi, Correspondence, EdgePlane};
use serde::{Deserialize, Serialize};

/// Which line error R_and_T minimises (Kumar–Hanson §2.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LineError {
    /// Eq. 10: squared distances of the model end points from the observed plane.
    E1,
    /// Eq. 11: E1 with each term divided by the end point's distance from the sensor centre
    /// (held fixed within an iteration): the sine of an angle, so near and far lines weigh alike.
    E2,
    /// Eq. 12: squared distances of the image end points' rays from the predicted plane.
    E3,
}

/// The solvers `omnitrack pose --method` and the tracker can use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Kumar–Hanson R_then_T: rotation from eq. 8, then translation from eq. 9.
    RThenT,
    /// Kumar–Hanson R_and_T: rotation and translation together (§3.1).
    RAndT,
    /// Kumar–Hanson Med_R_and_T: least median of squares, outlier rejection, R_and_T (§4).
    Lms,
    /// Koch–Teller: ξ (eq. 1) minimised by the Nelder–Mead simplex.
    Xi,
}

impl Method {
    /// Every method, in the order `omnitrack pose --help` lists them.
    pub const ALL: [Method; 4] = [Method::RAndT, Method::RThenT, Method::Lms, Method::Xi];

    /// The method's name in tracker.toml and on the command line (`r_and_t`, …).
    pub fn name(self) -> &'static str {
        match self {
            Method::RThenT => "r_then_t",
            Method::RAndT => "r_and_t",
            Method::Lms => "lms",
            Method::Xi => "xi",
        }
    }
}

/// A name that is none of [`Method::ALL`]'s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is not a method (r_and_t, r_then_t, lms or xi)")]
pub struct UnknownMethod(pub String);

impl std::str::FromStr for Method {
    type Err = UnknownMethod;

    /// A method from its [`Method::name`].
    fn from_str(s: &str) -> Result<Method, UnknownMethod> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| UnknownMethod(s.to_string()))
    }
}

/// Tunables of the solvers (their defaults are the papers', as in `firmware_config/tracker.toml`).
#[derive(Debug, Clone, PartialEq)]
pub struct SolverOptions {
    pub error: LineError,
    /// Kumar–Hanson §3.1 step 4: iteration cap …
    pub max_iterations: u32,
    /// … and the size of a step (rad, and rad-equivalent for translation) below which it stops.
    pub convergence_rad: f64,
    /// Horn's rotation samples used when there is no guess: 12, 24 or 60 (§3.2).
    pub initial_rotation_samples: u32,
    /// Med_R_and_T: probability that at least one random subset is outlier-free …
    pub lms_success_probability: f64,
    /// … assuming at most this fraction of outliers (Monte-Carlo subset count, §4).
    pub lms_outlier_fraction: f64,
    /// Med_R_and_T: a line is an outlier beyond this many σ̂ per end point (as an F-test against
    /// the fit's own σ̂, so wider when few lines fix σ̂).
    pub lms_outlier_threshold: f64,
    /// Med_R_and_T: subsets whose 3D line directions have |det| below this are degenerate.
    pub degenerate_subset_det: f64,
    /// σ (rad) of an observed edge plane's normal, for the covariance of §5 (but Med_R_and_T's,
    /// which is at the noise its own lines show).
    pub edge_sigma_rad: f64,
    /// The angle one pixel subtends at the centre of the sensors (rad: 1 / f for a pinhole; the
    /// largest of a rig's sensors), or 0 when unknown. Med_R_and_T's inlier decision takes σ̂
    /// no smaller than this: real line errors have heavier tails than a Gaussian of the bulk's
    /// σ̂, and a σ̂ of a fraction of a pixel would cut good lines a pixel or two off.
    pub pixel_rad: f64,
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self {
            error: LineError::E1,
            max_iterations: 50,
            convergence_rad: 1e-10,
            initial_rotation_samples: 24,
            lms_success_probability: 0.99999,
            lms_outlier_fraction: 0.5,
            lms_outlier_threshold: 2.5,
            degenerate_subset_det: 0.05,
            edge_sigma_rad: 0.5f64.to_radians(),
            pixel_rad: 0.0,
        }
    }
}

/// A solved pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// `T_world_rig`.
    pub pose: Pose,
    /// 6×6 covariance, row-major over (tx, ty, tz, rx, ry, rz): the rig position in the world and
    /// the rotation as a small-angle vector in the world frame (docs/interfaces.md, "Pose service").
    /// §5's, at `edge_sigma_rad`, or for Med_R_and_T at the noise of the lines it kept.
    pub covariance: Matrix6<f64>,
    /// Indices (into the input) of the correspondences the final fit used.
    pub inliers: Vec<usize>,
    /// Koch–Teller ξ (eq. 1, rad²) over the inliers.
    pub xi_rad2: f64,
    /// Iterations of the final refinement (simplex steps for `Method::Xi`).
    pub iterations: u32,
    /// Whether the final refinement met its convergence test before the iteration cap.
    pub converged: bool,
}

/// Why no pose could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("need at least {needed} correspondences, got {got}")]
    TooFew { needed: usize, got: usize },
    #[error("the correspondences do not constrain the pose (degenerate geometry)")]
    Degenerate,
    #[error("no subset gave a usable pose")]
    NoSolution,
}

pub mod minimal;
pub mod refine;
pub mod robust;

pub use refine::cauchy::r_and_t_cauchy;
pub use refine::covariance::{covariance, covariance_mixed};
pub use refine::kumar_hanson::{r_and_t, r_and_t_refine, r_and_t_refine_weighted, r_then_t, SharedStart};
pub use refine::points::r_and_t_mixed;
pub use refine::residuals::{line_residuals, point_residuals, LineResiduals, PointObservation};
pub use refine::simplex::{minimise_xi, minimise_xi_upright, xi_solve, SimplexOptions};
pub use refine::upright::refine_upright;
pub use robust::consensus::{
    ConsensusError, ConsensusOutcome, ConsensusSampler, SampleFit, SampleScore, SamplingBudget, StopReason,
};
pub use robust::lms::{med_r_and_t, med_r_and_t_landmarks};
pub use robust::sampling::sample_count;

/// One entry point for every method (`omnitrack pose --method`, the tracker). `Xi` needs a
/// starting pose for its simplex: the guess, or else R_and_T's from Horn's rotation samples.
/// `seed` drives Med_R_and_T's random subsets.
pub fn solve(
    method: Method,
    c: &[Correspondence],
    guess: Option<&Pose>,
    o: &SolverOptions,
    seed: u64,
) -> Result<Solution, SolveError> {
    match method {
        Method::RThenT => r_then_t(c, guess, o),
        Method::RAndT => r_and_t(c, guess, o),
        Method::Lms => med_r_and_t(c, guess, o, seed),
        Method::Xi => {
            let start = match guess {
                Some(g) => *g,
                None => r_and_t(c, None, o)?.pose,
            };
            xi_solve(c, &start, o, &SimplexOptions::default())
        }
    }
}

#[cfg(test)]
mod method_names {
    use super::{Method, UnknownMethod};

    /// The command line's names are tracker.toml's (serde's) names, and each parses back.
    #[test]
    fn names_round_trip_and_match_the_config_file() {
        for m in Method::ALL {
            assert_eq!(m.name().parse::<Method>(), Ok(m));
            assert_eq!(serde_json::to_string(&m).unwrap(), format!("\"{}\"", m.name()));
        }
        assert_eq!("ransac".parse::<Method>(), Err(UnknownMethod("ransac".into())));
    }
}
