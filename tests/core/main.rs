//! Integration tests of omnitrack-core and omnitrack-config: lenses, rigs, models, tracker.toml: one test binary for several files, so that they link once.

mod config;
mod lens;
mod model;
mod rig;
