//! The tracker: Koch–Teller §4.1 (initialisation, Figures 4 and 5) and §4.2 (maintenance,
//! Figures 7 and 8) on the edges, the prior visibility table and the pose solvers.
//!
//! In: per frame, the frame's [`Edge`](omnitrack_edges::Edge)s (all sensors) and its capture time. Out: a
//! [`FrameResult`]: the tracker state (initialising → tracking → lost → tracking), the pose
//! `T_world_rig` with its covariance when tracking, and what the frame cost.
//!
//! States:
//! - **Initialising / Lost**: [`init::Initialiser`] searches a volume (the `--init` hint, the
//!   whole model without one, or after a loss a volume around the last good pose that grows with
//!   every failed attempt). Its best distinct candidates are then scored on the next frames
//!   (`confirm_frames`) before one is committed — the paper's admitted weakness is ambiguity from
//!   repeated structure (doorways along a corridor): a single frame may prefer the wrong one. On
//!   each of those frames a candidate must pass the search's acceptance test again, or it is
//!   dropped; with none left, the next frame searches afresh.
//! - **Tracking**: `maintenance` per Figure 7.
//!
//! The searches (initialisation, re-initialisation, relocalisation) run off the frame path and
//! are taken up a budget later on the frames' clock, the frames in between kept and caught up
//! on (module `background`); the earlier frames' poses come out through [`Tracker::late`].
//!
//! A frame is "bad" when the solve fails, leaves fewer than `min_inliers` accepted inliers, or
//! jumps more than `max_jump_m` / `max_jump_deg` from the motion prior; `lost_after_frames`
//! consecutive bad frames lose lock.
//!
//! Memory: everything is sized in [`Tracker::new`], and written through there
//! (`omnitrack_core::memory::resident`): [`Tracker::process`] allocates nothing, and writes no
//! memory not held from the start, while tracking or searching, relocalisations included
//! (counted by a test, page faults too).
//!
//! Where things are: [`Tracker`] (module `tracker`: the state machine and the frame loop, with
//! the search scheduling and the commit decision in `tracker::search` and Figure 7 in
//! `tracker::maintenance`); what a frame's answer holds (module `report`); the searches
//! themselves (module [`init`]); the correspondence table of Figure 8 ([`correspondence`]); the
//! visibility table ([`visibility`]); the search worker ([`background`]); the motion filter
//! ([`motion_filter`]) and the turn between frames from the image ([`frame_rotation`]).
//!
//! The tracker on a recording's frames, from a 3 m hint (what `omnitrack run` does, without the
//! threads and the publishers; `tests/tracker.rs` runs it on rendered recordings):
//!
//! ```no_run
//! use nalgebra::Point3;
//! use omnitrack_config::TrackerConfig;
//! use omnitrack_core::{FrameSet, Model, Rig};
//! use omnitrack_edges::EdgeDetector;
//! use omnitrack_tracker::visibility::VisibilityTable;
//! use omnitrack_tracker::{SearchVolume, Tracker};
//! use std::path::Path;
//!
//! # fn frames() -> Vec<FrameSet> { Vec::new() }
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let rig = Rig::load(Path::new("firmware_config/ladybug2.toml"))?;
//! let model = Model::load(Path::new("office.obj"))?;
//! let table = VisibilityTable::load(Path::new("office.vis"), &model)?;
//! let cfg = TrackerConfig::load(Path::new("firmware_config/tracker.toml"))?;
//! let hint = SearchVolume { centre: Point3::new(3.0, 13.0, 1.2), diameter_m: Some(3.0) };
//! let mut tracker = Tracker::new(&rig, &model, &table, &cfg, Some(hint), 1);
//! let mut detector = EdgeDetector::new(&rig, &cfg.edges);
//! for frame in frames() {
//!     let timestamp_ns = frame.sensors()[0].timestamp_ns;
//!     let result = tracker.process(detector.detect(&frame), timestamp_ns);
//!     if let Some(pose) = result.pose {
//!         println!("{timestamp_ns} {:?} {:?}", result.state, pose.translation.vector);
//!     }
//! }
//! # Ok(())
//! # }
//! ```

pub mod background;
pub mod correspondence;
pub mod edge_index;
mod floor;
pub mod frame_rotation;
pub mod init;
pub mod matching;
pub mod motion_filter;
mod report;
#[cfg(test)]
mod test_edges;
mod tracker;
mod vanishing;
pub mod visibility;
mod vote;

pub use background::{search_link, SearchJob, SearchLink, SearchWorker};
pub use correspondence::{CorrespondenceState, CorrespondenceTable, HeldEdge, Track};
pub use init::{Candidate, InitOptions, InitReport, Initialiser, SearchProgress, SearchSnapshot, SearchVolume};
pub use report::{FrameResult, SearchKind, StateCounts, TrackerEvent, TrackerState, TrackerStats, Weighed};
pub use tracker::{Tracker, CATCH_UP_FRAMES};
