//! omnitrack: 6-DOF egomotion of an omnidirectional camera rig inside a known building model.
//!
//! Koch & Teller 2007 (edge-to-segment matching, INIT-SEGMENT-EDGE, maintenance, prior
//! visibility) on the line pose solvers of Kumar & Hanson 1989. This crate is the front door:
//! the `omnitrack` binary, and every layer crate of the workspace under the module name it is
//! known by (`omnitrack::solver` is `omnitrack-solver`, …). The layers, bottom up (each imports
//! only those before it):
//!
//! | module | crate | what |
//! | --- | --- | --- |
//! | `geometry`, `rig`, `model`, `trajectory`, `lines`, `frame` | `omnitrack-core` | the shared vocabulary |
//! | `solver` | `omnitrack-solver` | Kumar–Hanson and Koch–Teller pose solvers |
//! | `config` | `omnitrack-config` | tracker.toml |
//! | `capture`, `publish` | `omnitrack-io` | frames in, poses out |
//! | `edges` | `omnitrack-edges` | edge and hue extraction |
//! | `visibility`, `tracker` | `omnitrack-tracker` | prior visibility, initialisation, maintenance |
//! | `runtime` | `omnitrack-runtime` | the device pipeline |
//! | `desk` (feature `desk`) | `omnitrack-desk` | offline work: plans, renders, evaluation, demo |

pub use omnitrack_config as config;
pub use omnitrack_core::{frame, geometry, lines, model, rig, text_file, trajectory};
pub use omnitrack_edges as edges;
pub use omnitrack_io::{capture, publish};
pub use omnitrack_runtime as runtime;
pub use omnitrack_solver as solver;
pub use omnitrack_tracker as tracker;
pub use omnitrack_tracker::visibility;

#[cfg(feature = "desk")]
pub use omnitrack_desk as desk;

pub use geometry::Pose;
pub use model::{Face, Model, Segment};
pub use rig::{Rig, Sensor};
