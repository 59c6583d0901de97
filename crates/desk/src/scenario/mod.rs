//! The paper's test scenarios (Koch & Teller 2007, §5 and Table 2) as synthetic buildings and
//! physically plausible trajectories through them.
//!
//! | scenario | building | motion | frame rate | paper: frames, length, area |
//! | --- | --- | --- | --- | --- |
//! | `lab` | one 25 m × 18 m room with bays and partitions | rolling 3-DOF, 1.2 m high | 5 Hz | 1,500, 120 m, 450 m² |
//! | `corridor` | two adjoining office buildings, 144 offices off a 320 m corridor | rolling 3-DOF | 5 Hz | 7,800, 936 m, 7,000 m² |
//! | `handheld` | the lab | hand-held 6-DOF, 1.5 m, step bob and wobble | 15 Hz | 1,900, 33 m, 450 m² |
//!
//! In: a scenario name, a frame count and a seed. Out: the plan's GeoJSON (generated in code),
//! its extruded OBJ, and a [`Trajectory`] of `T_world_rig` at the scenario's frame rate that walks
//! a random tour of the building (rooms joined by doors, rounded corners, 1.0–1.5 m/s, slower in
//! turns, rate-limited yaw) and never comes within [`path::BODY_CLEARANCE_M`] of a wall's face
//! ([`check_path`]). Everything is deterministic in the seed.

pub mod path;
pub mod plans;
pub mod random;

pub use path::{check_path, doorways_passed, PathError, BODY_CLEARANCE_M};

use crate::floorplan::{self, FloorPlan, FloorPlanError};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use omnitrack_core::geometry::Pose;
use omnitrack_core::trajectory::{Stamped, Trajectory};
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

/// A scenario of Koch–Teller Table 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ScenarioName {
    Lab,
    Corridor,
    Handheld,
}

impl ScenarioName {
    pub const ALL: [ScenarioName; 3] = [ScenarioName::Lab, ScenarioName::Corridor, ScenarioName::Handheld];

    pub fn as_str(self) -> &'static str {
        match self {
            ScenarioName::Lab => "lab",
            ScenarioName::Corridor => "corridor",
            ScenarioName::Handheld => "handheld",
        }
    }
}

impl fmt::Display for ScenarioName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An unknown scenario name; displays the valid ones.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown scenario {0:?}: expected one of lab, corridor, handheld")]
pub struct UnknownScenario(pub String);

impl FromStr for ScenarioName {
    type Err = UnknownScenario;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ScenarioName::ALL
            .into_iter()
            .find(|n| n.as_str() == s)
            .ok_or_else(|| UnknownScenario(s.to_string()))
    }
}

/// How the rig moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// On a cart: x, y and yaw only, the rig centre at a fixed height; roll = pitch = 0.
    Rolling3Dof { height_m: f64 },
    /// Carried: about 1.5 m high with a ±4 cm bob at ~1.8 Hz step frequency, a few degrees of
    /// pitch and roll wobble and sideways yaw glances, all smooth sums of sinusoids.
    HandHeld6Dof,
}

/// A scenario: its plan, frame rate and kind of motion, and the paper's figures for comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    pub name: ScenarioName,
    /// The floor plan, GeoJSON for [`floorplan::extrude`].
    pub geojson: String,
    pub frame_rate_hz: f64,
    pub motion: Motion,
    /// Table 2: number of frames of the paper's sequence.
    pub paper_frames: usize,
    /// Table 2: excursion length, metres.
    pub paper_length_m: f64,
    /// Table 2: total surface area, m² (what the room polygons should add up to).
    pub paper_area_m2: f64,
}

/// Maximum yaw rate of the rig following the path tangent (the hand-held glances add ≤ 15°/s).
const MAX_YAW_RATE: f64 = 60.0 * std::f64::consts::PI / 180.0;

impl Scenario {
    pub fn get(name: ScenarioName) -> Scenario {
        match name {
            ScenarioName::Lab => Scenario {
                name,
                geojson: plans::lab(),
                frame_rate_hz: 5.0,
                motion: Motion::Rolling3Dof { height_m: 1.2 },
                paper_frames: 1500,
                paper_length_m: 120.0,
                paper_area_m2: 450.0,
            },
            ScenarioName::Corridor => Scenario {
                name,
                geojson: plans::corridor(),
                frame_rate_hz: 5.0,
                motion: Motion::Rolling3Dof { height_m: 1.2 },
                paper_frames: 7800,
                paper_length_m: 936.0,
                paper_area_m2: 7000.0,
            },
            ScenarioName::Handheld => Scenario {
                name,
                geojson: plans::lab(),
                frame_rate_hz: 15.0,
                motion: Motion::HandHeld6Dof,
                paper_frames: 1900,
                paper_length_m: 33.0,
                paper_area_m2: 450.0,
            },
        }
    }

    /// The file name used for the plan in messages and the OBJ header: `lab.geojson`.
    pub fn plan_file_name(&self) -> String {
        format!("{}.geojson", self.name)
    }

    /// The parsed floor plan.
    pub fn plan(&self) -> Result<FloorPlan, FloorPlanError> {
        floorplan::parse(&self.geojson, &self.plan_file_name())
    }

    /// The extruded model, Wavefront OBJ text.
    pub fn model_obj(&self) -> Result<String, FloorPlanError> {
        floorplan::extrude(&self.geojson, &self.plan_file_name())
    }

    /// Sum of the room polygons' areas, m².
    pub fn floor_area_m2(&self) -> Result<f64, FloorPlanError> {
        Ok(self.plan()?.rooms.iter().map(|r| path::polygon_area(&r.outline)).sum())
    }

    /// Time between frames, nanoseconds (rounded): timestamps are `k × frame_period_ns()`.
    pub fn frame_period_ns(&self) -> u64 {
        (1e9 / self.frame_rate_hz).round() as u64
    }

    /// A trajectory of exactly `frames` poses `T_world_rig` at the scenario's frame rate, starting
    /// at timestamp 0: a random tour of the building chosen by `seed` (same seed, same
    /// trajectory). Any length works; the tour is as long as needed.
    pub fn trajectory(&self, frames: usize, seed: u64) -> Trajectory {
        let plan = self.plan().expect("the built-in scenario plans parse");
        walk_through(&plan, self.frame_rate_hz, self.motion, frames, seed)
    }
}

/// A trajectory of exactly `frames` poses `T_world_rig` at `frame_rate_hz` through `plan`,
/// starting at timestamp 0: a random tour of its rooms chosen by `seed`, moving as `motion` says
/// (the scenarios' walks, and those of [`random`] buildings).
pub fn walk_through(plan: &FloorPlan, frame_rate_hz: f64, motion: Motion, frames: usize, seed: u64) -> Trajectory {
    if frames == 0 {
        return Trajectory::new();
    }
    let space = path::Space::new(plan);
    let period_ns = (1e9 / frame_rate_hz).round() as u64;
    let dt = period_ns as f64 * 1e-9;
    let mut need = frames as f64 * dt * 1.6 + 10.0;
    let samples = loop {
        // Each attempt restarts the generator from the seed: the result depends on the seed only
        // (and on `frames`, through how long a tour is drawn).
        let mut rng = path::Rng::from_state(tour_stream(seed));
        let tour = path::tour(&space, need, &mut rng);
        let tour = path::ease_sharp_turns(&space, &tour);
        let dense = path::smooth(&space, &tour);
        let v = path::speeds(&dense, &mut rng);
        if let Some(s) = path::walk(&dense, &v, frames, dt) {
            break s;
        }
        need *= 2.0;
    };
    let mut rng = path::Rng::from_state(tour_stream(seed ^ 0x5eed_0f6d_0f00));
    let phases: Vec<f64> = (0..8).map(|_| rng.range(0.0, TAU)).collect();
    let mut yaw = samples[0].1;
    samples
        .iter()
        .enumerate()
        .map(|(k, &(p, heading))| {
            if k > 0 {
                let err = wrap_angle(heading - yaw);
                yaw += err.clamp(-MAX_YAW_RATE * dt, MAX_YAW_RATE * dt);
            }
            let t = k as f64 * dt;
            let (z, roll, pitch, yaw_offset) = match motion {
                Motion::Rolling3Dof { height_m } => (height_m, 0.0, 0.0, 0.0),
                Motion::HandHeld6Dof => {
                    let s = |f: f64, i: usize| (TAU * f * t + phases[i]).sin();
                    let deg = std::f64::consts::PI / 180.0;
                    let z = 1.5 + 0.04 * s(1.8, 0);
                    let pitch = 2.5 * deg * s(0.23, 1) + 1.0 * deg * s(1.8, 2);
                    let roll = 2.0 * deg * s(0.9, 3) + 1.0 * deg * s(0.17, 4);
                    let glance = 10.0 * deg * s(0.11, 5) + 4.0 * deg * s(0.29, 6);
                    (z, roll, pitch, glance)
                }
            };
            let pose: Pose = Isometry3::from_parts(
                Translation3::new(p.x, p.y, z),
                UnitQuaternion::from_euler_angles(roll, pitch, wrap_angle(yaw + yaw_offset)),
            );
            Stamped {
                timestamp_ns: k as u64 * period_ns,
                pose,
            }
        })
        .collect()
}

fn wrap_angle(a: f64) -> f64 {
    let mut a = a % TAU;
    if a > std::f64::consts::PI {
        a -= TAU;
    } else if a < -std::f64::consts::PI {
        a += TAU;
    }
    a
}

/// The generator state that reproduces the tours of earlier versions for a seed (the stream
/// pre-adds the SplitMix increment, hence the subtraction).
fn tour_stream(seed: u64) -> u64 {
    (seed ^ 0x6a09_e667_f3bc_c909).wrapping_sub(0x9e37_79b9_7f4a_7c15)
}
