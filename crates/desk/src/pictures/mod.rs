//! Pictures of a tracking run, as PNG files: what people look at before they read a table.
//!
//! In: the building [`Model`](omnitrack_core::Model), trajectories and their evaluation
//! ([`crate::eval`]), the [`Rig`](omnitrack_core::Rig) and one frame's sensor images, traces of correspondence states. Out: PNG files:
//! - [`plan_view`]: ground truth beside the estimated path over the floor plan, the estimate
//!   coloured by its position error (Koch–Teller Figures 1, 10, 11);
//! - [`omni_view`]: the sensor images of one frame tiled, the model re-projected in green
//!   through each sensor's lens (Figure 12);
//! - [`error_over_time`]: position and rotation error against time;
//! - [`correspondence_states`]: the state of chosen correspondences over time (Figure 14).
//!
//! Drawing is plotters into an RGB buffer that the `image` crate encodes; text uses DejaVu Sans
//! embedded from the `dejavu` crate, so no system font is ever looked up. Every function returns
//! a [`PictureError`] naming the output file instead of panicking.
//!
//! One submodule per picture: `plan` ([`plan_view`]), `omni` ([`omni_view`] and the projection
//! behind it), `over_time` ([`error_over_time`], [`correspondence_states`]); `canvas` holds the
//! drawing machinery they share (fonts, supersampling, PNG writing, the colour map).

mod canvas;
mod omni;
mod over_time;
mod plan;

pub use canvas::error_colour;
pub use omni::{frame_images, omni_layout, omni_view, OmniLayout, OmniOptions, MODEL_GREEN};
pub use omnitrack_tracker::CorrespondenceState;
pub use over_time::{correspondence_states, error_over_time, ErrorTrace, StateTrace};
pub use plan::{plan_view, PlanOptions};

use std::path::Path;

/// A picture that could not be made: `path: what went wrong`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct PictureError {
    pub path: String,
    pub message: String,
}

fn picture_error(path: &Path, message: impl Into<String>) -> PictureError {
    PictureError {
        path: path.display().to_string(),
        message: message.into(),
    }
}
