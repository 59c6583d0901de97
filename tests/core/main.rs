//! Integration tests of omnitrack-core and omnitrack-config: lenses, rigs, models, tracker.toml: one test binary for several files, so that they link once.

#[path = "../common/mod.rs"]
mod common;

mod config;
mod lens;
mod model;
mod rig;
