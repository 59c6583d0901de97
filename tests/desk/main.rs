//! Integration tests of omnitrack-desk and the visibility build: plans, renders, scenarios, evaluation, pictures, the demo: one test binary for several files, so that they link once.

#[path = "../common/mod.rs"]
mod common;

mod calibration;
mod calibration_formats;
mod demo;
mod eval;
mod floorplan;
mod pictures;
mod random_buildings;
mod recording_replay;
mod render;
mod scenario;
mod visibility;
