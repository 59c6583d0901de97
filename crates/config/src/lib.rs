//! The tracker's tunables (`firmware_config/tracker.toml`).
//!
//! In: TOML whose every key is optional; an absent key takes the papers' value. Out: a validated
//! [`TrackerConfig`]. Unknown keys and out-of-range values are errors naming the file and key, so
//! a typo never silently runs the tracker on a default.
//!
//! The defaults here and the shipped `tracker.toml` are the same numbers (a test checks it); the
//! comments in the TOML file cite the paper section each value comes from.
//!
//! ```
//! use omnitrack_config::TrackerConfig;
//!
//! // Every key is optional: the rest keep the papers' values.
//! let cfg = TrackerConfig::from_toml_str("[maintenance]\ninlier_angle_deg = 2.0\n", "inline.toml")?;
//! assert_eq!(cfg.maintenance.inlier_angle_deg, 2.0);
//! assert_eq!(cfg.initialisation, TrackerConfig::default().initialisation);
//! // A typo is an error naming the file and the key, never a silent default.
//! let typo = TrackerConfig::from_toml_str("[maintenance]\ninlier_angel_deg = 2.0\n", "inline.toml");
//! let message = typo.unwrap_err().to_string();
//! assert!(message.starts_with("inline.toml: ") && message.contains("inlier_angel_deg"), "{message}");
//! # Ok::<(), omnitrack_config::ConfigError>(())
//! ```

mod validate;

use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EdgeConfig {
    pub hue_strip_width_px: u32,
    pub max_edges_per_sensor: u32,
    pub min_edge_length_deg: f64,
    pub min_hue_saturation: f64,
    pub min_hue_value: f64,
}

/// Which searches' grids rank their positions by the final merit's blank share too, by a
/// per-frame map of the directions near an edge (issue 47, item 1: recall;
/// `initialisation.grid_blank`, written `"off"`, `"volumes"` or `"everywhere"`; `false` and
/// `true` are read as `"off"` and `"everywhere"`).
///
/// `Volumes` by default: in a bounded volume (a hint, a relocalisation, the volume round a lost
/// pose) it turned wrong commits on FZK-Haus from 3 m (3 → 1) and ZInD from 3 m (1 → 0) into
/// right poses or none; over the whole model it finds, with the truth, twins from every room,
/// and one (a pantry's, ZInD) outscores the truth on the one frame there is
/// (docs/decisions.md, 2026-11-30).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GridBlank {
    /// No search: the grid ranks by explained × support.
    Off,
    /// Searches of a bounded volume; the whole model's search without it.
    Volumes,
    /// Every search, the whole model's too.
    Everywhere,
}

impl<'de> Deserialize<'de> for GridBlank {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Named;
        impl serde::de::Visitor<'_> for Named {
            type Value = GridBlank;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("\"off\", \"volumes\" or \"everywhere\" (or false / true)")
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<GridBlank, E> {
                Ok(if v { GridBlank::Everywhere } else { GridBlank::Off })
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<GridBlank, E> {
                match v {
                    "off" => Ok(GridBlank::Off),
                    "volumes" => Ok(GridBlank::Volumes),
                    "everywhere" => Ok(GridBlank::Everywhere),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(v), &self)),
                }
            }
        }
        d.deserialize_any(Named)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialisationConfig {
    pub search_diameter_m: f64,
    pub best_edges_per_segment: u32,
    pub max_samples: u32,
    /// The search's work budget in reference milliseconds (`omnitrack_tracker::init::work`): the
    /// work decides where it stops, never the load of the machine; the wall clock stops it only
    /// at four times the budget, and says so. The search runs off the frame path and its result
    /// is taken up this long after its frame on the frames' clock (`omnitrack_tracker::background`).
    pub time_budget_ms: f64,
    pub simplex_refinement: bool,
    pub confirm_frames: u32,
    /// A rig imaging less than half the sphere commits only where this many decided searches in
    /// a row chose the same place (one narrow view cannot tell a symmetric place from its twin).
    pub narrow_rig_searches: u32,
    pub edges_considered: u32,
    pub segments_considered: u32,
    pub samples_per_cell: u32,
    pub dihedral_tolerance_deg: f64,
    pub max_dihedral_range_deg: f64,
    /// The whole-model search's work budget (reference milliseconds, as `time_budget_ms`: the
    /// reference machine's two cores side by side).
    pub whole_model_time_budget_ms: f64,
    /// A search whose budget runs out before it has looked at every cell of its volume decides
    /// nothing; the next goes on from the nearest cell it left, the best candidates so far
    /// carried along as rivals, and the search that ends the sweep decides (issue 47, item 1).
    /// Off by default: measured, it refuses wrong commits on FZK-Haus but adds one on ZInD and
    /// delays the first pose (docs/decisions.md, 2026-11-30). A hint that grows with the rig's
    /// walk (`omnitrack_tracker`'s module `tracker::hint_age`) is a new volume for each search:
    /// while the rig walks, such a sweep does not end.
    pub sweep_volume: bool,
    /// Which searches' grids rank their positions by the share of blank points too
    /// (`blank_radius_deg`), as the final merit does ([`GridBlank`]).
    pub grid_blank: GridBlank,
    pub clear_winner_ratio: f64,
    /// A rival scoring more than `clear_winner_ratio` × the best is beaten all the same when
    /// the best does at least as well by each part of the merit (explained, support, blank)
    /// and, of the frame's edges that exactly one of the two explains (the *disputed* edges),
    /// the rival explains at most this share (by angle): a twin differs from the truth only
    /// where the building does, and there the image sides with the truth. 0 turns the test off.
    pub disputed_share_max: f64,
    /// … and when the disputed edges are at least this share (by angle) of the frame's edges:
    /// a dispute over a line or two decides nothing.
    pub disputed_min_fraction: f64,
    pub accept_explained_fraction: f64,
    /// A candidate must also explain this share of the frame's edges (by angle).
    pub accept_support_fraction: f64,
    /// A search that looked at every cell of its volume may also accept a candidate by the
    /// share explained over the lines the matcher can resolve: segments whose planes through the
    /// rig's centre lie within the inlier angle of each other and whose arcs overlap by half the
    /// shorter count as one line. A detailed model draws a window as nested frames and a floor
    /// junction as slab, finish and skirting lines, where the image shows one.
    pub accept_resolved_lines: bool,
    /// A sampled point of a predicted segment with no edge of any direction this near (deg) is
    /// *blank*: the model draws a line across a plain surface of the image there. 0 turns the
    /// blank share off.
    pub blank_radius_deg: f64,
    pub wide_edges_considered: u32,
    pub wide_segments_considered: u32,
    pub wide_samples_per_cell: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MaintenanceConfig {
    pub angular_gate_deg: f64,
    pub hue_gate: f64,
    pub accept_after_frames: u32,
    pub sample_size: u32,
    pub success_probability: f64,
    pub outlier_percent: f64,
    pub max_samples: u32,
    pub time_budget_ms: f64,
    pub constant_velocity_prior: bool,
    /// The frame's final fit over its observed correspondences weighs them by Cauchy's loss
    /// (`solver::refine::cauchy`) instead of least squares (R_and_T only, not upright).
    pub robust_final_fit: bool,
    /// How the consensus scores a sample's pose (`truncated`: MSAC, `median`: least median of
    /// squares).
    pub consensus_score: omnitrack_solver::SampleScore,
    pub inlier_angle_deg: f64,
    pub min_inliers: u32,
    pub lost_after_frames: u32,
    pub max_jump_m: f64,
    pub max_jump_deg: f64,
    pub relocalise_diameter_m: f64,
    /// The work budget of that search (reference milliseconds, as `initialisation.time_budget_ms`),
    /// and how long after its frame it is taken up. A few frame budgets, not the first start's
    /// `initialisation.time_budget_ms`: the frames that come meanwhile are caught up on a few
    /// at a time, and a walking rig needs its pose again soon.
    pub relocalise_time_budget_ms: f64,
    /// A solved pose must explain (an edge within the inlier angle) at least this fraction of
    /// what recent good frames explained of VIS(T) (their running mean); 0 turns the check off.
    pub min_explained_ratio: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VisibilityConfig {
    pub node_spacing_m: f64,
    pub min_visible_pixels: u32,
    pub cube_map_resolution: u32,
    pub node_heights_m: Vec<f64>,
    /// Model segments shorter than this (m) enter no visibility set, so the tracker never
    /// matches or scores them: the handles, sash profiles and tessellated curves of a detailed
    /// model (docs/models.md, "Models from IFC").
    pub min_segment_length_m: f64,
}

pub use omnitrack_solver::{LineError, Method as SolverMethod};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverConfig {
    pub method: SolverMethod,
    pub error: LineError,
    pub max_iterations: u32,
    pub convergence_rad: f64,
    pub initial_rotation_samples: u32,
    pub lms_subset_size: u32,
    pub lms_success_probability: f64,
    pub lms_outlier_fraction: f64,
    pub lms_outlier_threshold: f64,
    pub degenerate_subset_det: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseConfig {
    pub edge_normal_sigma_deg: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionConfig {
    pub upright: bool,
    pub upright_height_m: f64,
    /// Fastest plausible turn of the rig (deg/s): a relocalised or re-initialised pose that
    /// turned further since the last good frame (beyond `maintenance.max_jump_deg`) is refused.
    pub max_turn_rate_deg_s: f64,
    /// Fastest plausible speed of the rig (m/s): while no frame is tracked, the published pose
    /// (the last good one) has its position σ grown by this × the time since.
    pub max_speed_m_s: f64,
    /// Largest tilt of the rig's z axis from the world's up (deg) a search considers; 180 keeps
    /// every orientation.
    pub max_tilt_deg: f64,
    /// The rig centre's height above the floor beneath it (m, lowest and highest): searches
    /// refuse poses outside it, below every floor or outside the building. Ignored for a model
    /// without floors and when `upright`.
    pub height_above_floor_m: [f64; 2],
    /// Maintenance predicts, fuses and publishes through the motion filter
    /// (`omnitrack_tracker::motion_filter`): a frame whose few lines fix the pose only in some
    /// directions is fused where it is informative instead of refused whole.
    pub filter: bool,
    /// The filter's linear acceleration noise: σ of the change of velocity over one second,
    /// per axis (m/s² per √s).
    pub accel_noise_m_s2: f64,
    /// The same for turning (deg/s² per √s).
    pub angular_accel_noise_deg_s2: f64,
    /// Maintenance predicts the rig's turn since the last frame from the image
    /// (`omnitrack_tracker::frame_rotation`: the frames' edges, model lines or not) where it
    /// disagrees with the motion model's by more than the inlier angle; for rigs imaging at
    /// least half the sphere (in a narrow view a turn and a step move the lines alike: on one
    /// 50° pinhole it added wrong frames). Off by default: on the shipped rig the accuracy is
    /// the same within the seeds' spread and maintenance's CPU p99 a sixth, but its p50 is
    /// 0.1–0.2 ms higher (docs/decisions.md, 2026-11-30).
    pub frame_rotation: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BudgetConfig {
    pub frame_ms: f64,
    pub edges_ms: f64,
    pub frame_sync_tolerance_ms: f64,
    /// One grab: a whole-rig `next_frame` or one sensor's read (runtime::pipeline).
    pub capture_ms: f64,
    /// Tracker (matching + solve) per frame.
    pub track_ms: f64,
    /// Loan, write and send of one pose sample.
    pub publish_ms: f64,
    /// Longest wait for the other sensors' images of one instant once the first has arrived.
    pub frame_assembly_wait_ms: f64,
    /// Time between two status samples.
    pub status_interval_ms: f64,
    /// `SCHED_FIFO` priority of the pipeline's frame-path threads (capture, assembly, process,
    /// edge workers), 1–99, where the OS allows it; 0 = the normal policy.
    pub realtime_priority: u8,
}

/// Every tunable of the tracker, grouped by the stage that reads it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerConfig {
    pub edges: EdgeConfig,
    pub initialisation: InitialisationConfig,
    pub maintenance: MaintenanceConfig,
    pub visibility: VisibilityConfig,
    pub solver: SolverConfig,
    pub noise: NoiseConfig,
    pub motion: MotionConfig,
    pub budgets: BudgetConfig,
}

impl Default for EdgeConfig {
    fn default() -> Self {
        Self {
            hue_strip_width_px: 5, // Koch–Teller §4.2.1
            max_edges_per_sensor: 256,
            min_edge_length_deg: 2.0,
            min_hue_saturation: 0.15,
            min_hue_value: 0.10,
        }
    }
}

impl Default for InitialisationConfig {
    fn default() -> Self {
        Self {
            search_diameter_m: 3.0,    // Koch–Teller §5.3
            best_edges_per_segment: 3, // Koch–Teller §4.1.2, k = 3
            max_samples: 5000,
            time_budget_ms: 950.0,
            simplex_refinement: true, // Koch–Teller §4.1.3
            confirm_frames: 3,
            narrow_rig_searches: 3,
            edges_considered: 40,
            segments_considered: 40,
            samples_per_cell: 100,
            dihedral_tolerance_deg: 1.0,
            max_dihedral_range_deg: 10.0,
            whole_model_time_budget_ms: 5000.0,
            sweep_volume: false,
            grid_blank: GridBlank::Volumes,
            clear_winner_ratio: 0.8,
            disputed_share_max: 0.33,
            disputed_min_fraction: 0.03,
            accept_explained_fraction: 0.4,
            accept_support_fraction: 0.15,
            accept_resolved_lines: true,
            blank_radius_deg: 2.0,
            wide_edges_considered: 64,
            wide_segments_considered: 60,
            wide_samples_per_cell: 300,
        }
    }
}

impl Default for MaintenanceConfig {
    fn default() -> Self {
        Self {
            angular_gate_deg: 10.0,    // Koch–Teller §4.2.1
            hue_gate: 0.03,            // Koch–Teller §4.2.1
            accept_after_frames: 4,    // Koch–Teller §4.2.4, k = 4
            sample_size: 10,           // Koch–Teller §4.2.4, λ
            success_probability: 0.95, // Koch–Teller eq. 2
            outlier_percent: 30.0,     // Koch–Teller Table 1, b
            max_samples: 1000,
            time_budget_ms: 30.0,
            constant_velocity_prior: true,
            robust_final_fit: true,
            consensus_score: omnitrack_solver::SampleScore::Median,
            inlier_angle_deg: 1.5,
            min_inliers: 8,
            lost_after_frames: 3,
            max_jump_m: 0.5,
            max_jump_deg: 15.0,
            relocalise_diameter_m: 1.0,
            relocalise_time_budget_ms: 150.0,
            min_explained_ratio: 0.6,
        }
    }
}

/// The default [`VisibilityConfig::min_segment_length_m`] (m): measured on KIT's FZK-Haus
/// converted from IFC (docs/models.md, "Models from IFC").
pub const MIN_SEGMENT_LENGTH_M: f64 = 0.1;

impl Default for VisibilityConfig {
    fn default() -> Self {
        Self {
            node_spacing_m: 1.0,   // Koch–Teller §4.1.1
            min_visible_pixels: 2, // Koch–Teller §4.3
            cube_map_resolution: 256,
            node_heights_m: vec![1.0, 1.5, 2.0],
            min_segment_length_m: MIN_SEGMENT_LENGTH_M,
        }
    }
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            method: SolverMethod::RAndT, // Kumar–Hanson §6: R_and_T beats R_then_T
            error: LineError::E2,        // Kumar–Hanson eq. 11 (best in the tracker benchmark)
            max_iterations: 50,          // Kumar–Hanson §3.1 step 4
            convergence_rad: 1e-10,
            initial_rotation_samples: 24, // Kumar–Hanson §3.2 (Horn: 12, 24 or 60)
            lms_subset_size: 3,           // Kumar–Hanson §4
            // Kumar–Hanson §4 promises 49.9 % outliers: sized for half (87 subsets of 3).
            lms_success_probability: 0.99999,
            lms_outlier_fraction: 0.5,
            lms_outlier_threshold: 2.5,  // Rousseeuw & Leroy: |r| > 2.5 σ̂
            degenerate_subset_det: 0.05, // Kumar–Hanson §4
        }
    }
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            edge_normal_sigma_deg: 0.5,
        } // Koch–Teller §5.1
    }
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            upright: false,
            upright_height_m: 1.2,
            max_turn_rate_deg_s: 360.0, // ours: heads turn at up to ~300–400°/s
            max_speed_m_s: 2.0,
            max_tilt_deg: 60.0,               // ours: a worn rig leans less than a look at the floor
            height_above_floor_m: [1.0, 2.0], // ours: worn 1.2–1.9 m, hand-held or on a cart 1.0–1.6 m
            filter: true,
            accel_noise_m_s2: 2.0,             // ours: a walk starting or stopping within a second
            angular_accel_noise_deg_s2: 180.0, // ours: a head turning to 180°/s within a second
            frame_rotation: false,             // ours: docs/decisions.md, 2026-11-30
        } // Koch–Teller §5.4
    }
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self {
            frame_ms: 33.0,
            edges_ms: 10.0,
            frame_sync_tolerance_ms: 5.0,
            capture_ms: 40.0,
            track_ms: 20.0,
            publish_ms: 0.5,
            frame_assembly_wait_ms: 10.0,
            status_interval_ms: 250.0,
            realtime_priority: 10,
        }
    }
}

/// A tracker config that cannot be used: one line naming the file and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {message}")]
pub struct ConfigError {
    pub file: String,
    pub message: String,
}

impl TrackerConfig {
    /// The solver tunables of this config.
    pub fn solver_options(&self) -> omnitrack_solver::SolverOptions {
        let s = &self.solver;
        omnitrack_solver::SolverOptions {
            error: s.error,
            max_iterations: s.max_iterations,
            convergence_rad: s.convergence_rad,
            initial_rotation_samples: s.initial_rotation_samples,
            lms_success_probability: s.lms_success_probability,
            lms_outlier_fraction: s.lms_outlier_fraction,
            lms_outlier_threshold: s.lms_outlier_threshold,
            degenerate_subset_det: s.degenerate_subset_det,
            edge_sigma_rad: self.noise.edge_normal_sigma_deg.to_radians(),
            // A tracker.toml knows no camera: whoever holds the rig sets its pixel.
            pixel_rad: 0.0,
        }
    }

    pub fn load(path: &Path) -> Result<TrackerConfig, ConfigError> {
        let file = path.display().to_string();
        let text =
            omnitrack_core::text_file::read_text(path, omnitrack_core::text_file::SMALL_FILE_LIMIT).map_err(|e| {
                ConfigError {
                    file: file.clone(),
                    message: format!("cannot read tracker config: {e}"),
                }
            })?;
        TrackerConfig::from_toml_str(&text, &file)
    }

    pub fn from_toml_str(text: &str, file: &str) -> Result<TrackerConfig, ConfigError> {
        let config: TrackerConfig = toml::from_str(text).map_err(|e| ConfigError {
            file: file.to_string(),
            message: omnitrack_core::rig::one_line(&e.to_string()),
        })?;
        config.out_of_range().map_err(|message| ConfigError {
            file: file.to_string(),
            message,
        })?;
        Ok(config)
    }
}
