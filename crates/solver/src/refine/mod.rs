//! Refinement: from a start pose to the least squares (or a robust loss) of all the given
//! observations, and the uncertainty of the result.
//!
//! - [`residuals`]: the line and point errors, their Jacobians and eq. 21's normal equations —
//!   the kernel everything below builds on;
//! - [`kumar_hanson`]: R_then_T and R_and_T (§2–§3), starting from a guess or from Horn's
//!   rotation samples ([`horn`], §3.2);
//! - [`points`]: R_and_T over points and lines together (eqs. 14–15);
//! - [`upright`]: R_and_T with the vertical known (Koch–Teller §5.4: x, y and yaw);
//! - [`simplex`]: Koch–Teller's ξ (eq. 1) minimised by Nelder–Mead;
//! - [`cauchy`]: R_and_T under Cauchy's loss, for a coarse model (beyond the papers);
//! - [`covariance`]: the pose's covariance (Kumar–Hanson §5).
//!
//! Imports run down this list's reverse: `residuals` imports none of the others, `covariance`
//! only `residuals`, the solvers both.

pub mod cauchy;
pub mod covariance;
pub mod horn;
pub mod kumar_hanson;
pub mod points;
pub mod residuals;
pub mod simplex;
pub mod upright;
