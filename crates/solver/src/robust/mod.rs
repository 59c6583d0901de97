//! Robust estimation: poses from correspondences of which some are wrong.
//!
//! - [`lms`]: Kumar–Hanson §4's Med_R_and_T, least median of squares over 3-line subsets
//!   (`omnitrack pose --method lms`, whole-frame solves);
//! - [`consensus`]: Koch–Teller §4.2.3's random consensus sampling, fixed-capacity and anytime,
//!   the tracker's per-frame estimator;
//! - [`sampling`]: how many samples either needs (Koch–Teller eq. 2).
//!
//! Both estimators draw minimal samples, solve them ([`crate::minimal`] or a refinement from the
//! guess), score them by an order statistic or a truncated sum over all correspondences, and
//! refit the winner's inliers ([`crate::refine`]).
//!
//! They keep two signatures rather than one trait because their contracts differ where it
//! matters: the consensus sampler is sized once and allocates nothing per frame, takes the
//! caller's refinement as a closure and stops at a sample count or a deadline (the frame path);
//! Med_R_and_T needs no guess, considers every pose a 3-line subset allows and allocates its
//! scratch per call (one-off solves). A common trait would either give the frame path a
//! per-call allocation or take the no-guess search away from `omnitrack pose`.

pub mod consensus;
pub mod lms;
pub mod sampling;
