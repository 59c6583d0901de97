//! Integration tests of the `omnitrack` command line, run as a user runs it: one test binary for several files, so that they link once.

#[path = "../common/mod.rs"]
mod common;

mod cli_control;
mod cli_manual;
mod cli_mcap;
mod cli_pose;
mod cli_record;
mod cli_report;
mod cli_run;
mod cli_stop;
mod cli_visibility;
