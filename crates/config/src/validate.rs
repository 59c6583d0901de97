//! The checks a loaded tracker config must pass ([`TrackerConfig::validate`]): every value in
//! its range, and the values that depend on each other consistent, each failure one line naming
//! the key.
//!
//! In: a parsed [`TrackerConfig`]. Out: `Ok`, or a [`ConfigError`].

use super::{ConfigError, TrackerConfig};

impl TrackerConfig {
    /// Range checks that serde's types cannot express, for a config built in code (one read
    /// from a file has passed them): the message names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.out_of_range().map_err(|message| ConfigError {
            file: "tracker config".to_string(),
            message,
        })
    }

    /// The first key out of its range, as the message of a [`ConfigError`].
    pub(crate) fn out_of_range(&self) -> Result<(), String> {
        fn positive(key: &str, v: f64) -> Result<(), String> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("key '{key}': must be a positive number, found {v}"))
            }
        }
        fn open_unit(key: &str, v: f64) -> Result<(), String> {
            if v > 0.0 && v < 1.0 {
                Ok(())
            } else {
                Err(format!("key '{key}': must lie strictly between 0 and 1, found {v}"))
            }
        }
        fn at_least(key: &str, v: u32, min: u32) -> Result<(), String> {
            if v >= min {
                Ok(())
            } else {
                Err(format!("key '{key}': must be at least {min}, found {v}"))
            }
        }
        // Upper bounds: every capacity and budget here sizes memory or time, so a value far past
        // any use (a typo, `1e9`) is refused before it asks for gigabytes or minutes per frame.
        fn at_most(key: &str, v: f64, max: f64, why: &str) -> Result<(), String> {
            if v <= max {
                Ok(())
            } else {
                Err(format!("key '{key}': must be at most {max} ({why}), found {v}"))
            }
        }
        let (e, i, m, v, s) = (
            &self.edges,
            &self.initialisation,
            &self.maintenance,
            &self.visibility,
            &self.solver,
        );
        at_least("edges.hue_strip_width_px", e.hue_strip_width_px, 1)?;
        at_least("edges.max_edges_per_sensor", e.max_edges_per_sensor, 3)?;
        at_most(
            "edges.hue_strip_width_px",
            f64::from(e.hue_strip_width_px),
            64.0,
            "a wider strip samples other surfaces than the edge's, at its cost per pixel",
        )?;
        at_most(
            "edges.max_edges_per_sensor",
            f64::from(e.max_edges_per_sensor),
            16384.0,
            "buffers and matching grow with it; a sensor image holds far fewer lines",
        )?;
        const MINUTE_MS: f64 = 60_000.0;
        for (key, ms) in [
            ("initialisation.time_budget_ms", i.time_budget_ms),
            (
                "initialisation.whole_model_time_budget_ms",
                i.whole_model_time_budget_ms,
            ),
            ("maintenance.time_budget_ms", m.time_budget_ms),
            ("maintenance.relocalise_time_budget_ms", m.relocalise_time_budget_ms),
        ] {
            at_most(key, ms, 10.0 * MINUTE_MS, "a search that long is a hang")?;
        }
        at_most(
            "initialisation.max_samples",
            f64::from(i.max_samples),
            1e7,
            "sample tables are sized by it",
        )?;
        at_most(
            "maintenance.max_samples",
            f64::from(m.max_samples),
            1e7,
            "sample tables are sized by it",
        )?;
        at_most(
            "visibility.cube_map_resolution",
            f64::from(v.cube_map_resolution),
            4096.0,
            "six faces of that many pixels squared per build worker",
        )?;
        positive("edges.min_edge_length_deg", e.min_edge_length_deg)?;
        for (key, x) in [
            ("edges.min_hue_saturation", e.min_hue_saturation),
            ("edges.min_hue_value", e.min_hue_value),
        ] {
            if !(0.0..1.0).contains(&x) {
                return Err(format!("key '{key}': must lie in [0, 1), found {x}"));
            }
        }
        positive("initialisation.search_diameter_m", i.search_diameter_m)?;
        at_least("initialisation.best_edges_per_segment", i.best_edges_per_segment, 1)?;
        at_least("initialisation.max_samples", i.max_samples, 1)?;
        positive("initialisation.time_budget_ms", i.time_budget_ms)?;
        at_least("initialisation.confirm_frames", i.confirm_frames, 1)?;
        at_least("initialisation.narrow_rig_searches", i.narrow_rig_searches, 1)?;
        at_least("initialisation.edges_considered", i.edges_considered, 3)?;
        if i.edges_considered > 64 {
            return Err(format!(
                "key 'initialisation.edges_considered': must be at most 64 (one bit per edge), found {}",
                i.edges_considered
            ));
        }
        at_least("initialisation.segments_considered", i.segments_considered, 3)?;
        at_least("initialisation.samples_per_cell", i.samples_per_cell, 1)?;
        positive("initialisation.dihedral_tolerance_deg", i.dihedral_tolerance_deg)?;
        positive("initialisation.max_dihedral_range_deg", i.max_dihedral_range_deg)?;
        positive(
            "initialisation.whole_model_time_budget_ms",
            i.whole_model_time_budget_ms,
        )?;
        if !(i.clear_winner_ratio > 0.0 && i.clear_winner_ratio <= 1.0) {
            return Err(format!(
                "key 'initialisation.clear_winner_ratio': must lie in (0, 1], found {}",
                i.clear_winner_ratio
            ));
        }
        if !(0.0..0.5).contains(&i.disputed_share_max) {
            return Err(format!(
                "key 'initialisation.disputed_share_max': must lie in [0, 0.5), found {}",
                i.disputed_share_max
            ));
        }
        if !(0.0..1.0).contains(&i.disputed_min_fraction) {
            return Err(format!(
                "key 'initialisation.disputed_min_fraction': must lie in [0, 1), found {}",
                i.disputed_min_fraction
            ));
        }
        if !(i.accept_explained_fraction > 0.0 && i.accept_explained_fraction < 1.0) {
            return Err(format!(
                "key 'initialisation.accept_explained_fraction': must lie strictly between 0 and 1, found {}",
                i.accept_explained_fraction
            ));
        }
        if !(i.accept_support_fraction >= 0.0 && i.accept_support_fraction < 1.0) {
            return Err(format!(
                "key 'initialisation.accept_support_fraction': must lie in [0, 1), found {}",
                i.accept_support_fraction
            ));
        }
        if !(i.blank_radius_deg >= 0.0 && i.blank_radius_deg <= 10.0) {
            return Err(format!(
                "key 'initialisation.blank_radius_deg': must lie in [0, 10] degrees, found {}",
                i.blank_radius_deg
            ));
        }
        at_least(
            "initialisation.wide_edges_considered",
            i.wide_edges_considered,
            i.edges_considered,
        )?;
        if i.wide_edges_considered > 64 {
            return Err(format!(
                "key 'initialisation.wide_edges_considered': must be at most 64 (one bit per edge), found {}",
                i.wide_edges_considered
            ));
        }
        at_least(
            "initialisation.wide_segments_considered",
            i.wide_segments_considered,
            i.segments_considered,
        )?;
        at_least("initialisation.wide_samples_per_cell", i.wide_samples_per_cell, 1)?;
        positive("maintenance.angular_gate_deg", m.angular_gate_deg)?;
        if !(m.hue_gate > 0.0 && m.hue_gate <= 0.5) {
            return Err(format!(
                "key 'maintenance.hue_gate': must lie in (0, 0.5] (hue wraps at 1), found {}",
                m.hue_gate
            ));
        }
        at_least("maintenance.accept_after_frames", m.accept_after_frames, 1)?;
        at_least("maintenance.sample_size", m.sample_size, 3)?;
        open_unit("maintenance.success_probability", m.success_probability)?;
        if !(0.0..100.0).contains(&m.outlier_percent) {
            return Err(format!(
                "key 'maintenance.outlier_percent': must lie in [0, 100), found {}",
                m.outlier_percent
            ));
        }
        at_least("maintenance.max_samples", m.max_samples, 1)?;
        positive("maintenance.time_budget_ms", m.time_budget_ms)?;
        positive("maintenance.inlier_angle_deg", m.inlier_angle_deg)?;
        at_least("maintenance.min_inliers", m.min_inliers, 4)?;
        at_least("maintenance.lost_after_frames", m.lost_after_frames, 1)?;
        positive("maintenance.max_jump_m", m.max_jump_m)?;
        positive("maintenance.max_jump_deg", m.max_jump_deg)?;
        if !(m.relocalise_diameter_m >= 0.0 && m.relocalise_diameter_m.is_finite()) {
            return Err(format!(
                "key 'maintenance.relocalise_diameter_m': must be 0 (off) or a positive number of metres, found {}",
                m.relocalise_diameter_m
            ));
        }
        positive("maintenance.relocalise_time_budget_ms", m.relocalise_time_budget_ms)?;
        if !(0.0..1.0).contains(&m.min_explained_ratio) {
            return Err(format!(
                "key 'maintenance.min_explained_ratio': must lie in [0, 1) (0 = off), found {}",
                m.min_explained_ratio
            ));
        }
        positive("visibility.node_spacing_m", v.node_spacing_m)?;
        at_least("visibility.min_visible_pixels", v.min_visible_pixels, 1)?;
        at_least("visibility.cube_map_resolution", v.cube_map_resolution, 8)?;
        if !(v.min_segment_length_m.is_finite() && v.min_segment_length_m >= 0.0) {
            return Err(format!(
                "key 'visibility.min_segment_length_m': must be a finite length ≥ 0 (0 = every segment), found {}",
                v.min_segment_length_m
            ));
        }
        if v.node_heights_m.is_empty() || v.node_heights_m.iter().any(|h| !h.is_finite()) {
            return Err("key 'visibility.node_heights_m': must be a non-empty list of finite heights".into());
        }
        at_least("solver.max_iterations", s.max_iterations, 1)?;
        at_most(
            "solver.max_iterations",
            f64::from(s.max_iterations),
            1000.0,
            "the solves converge in tens, and every frame may run one to its limit",
        )?;
        positive("solver.convergence_rad", s.convergence_rad)?;
        if ![12, 24, 60].contains(&s.initial_rotation_samples) {
            return Err(format!(
                "key 'solver.initial_rotation_samples': must be 12, 24 or 60 (Horn's rotation groups), found {}",
                s.initial_rotation_samples
            ));
        }
        at_least("solver.lms_subset_size", s.lms_subset_size, 3)?;
        at_most(
            "solver.lms_subset_size",
            f64::from(s.lms_subset_size),
            12.0,
            "the number of subsets drawn grows as (1 - outliers)^-size",
        )?;
        open_unit("solver.lms_success_probability", s.lms_success_probability)?;
        open_unit("solver.lms_outlier_fraction", s.lms_outlier_fraction)?;
        positive("solver.lms_outlier_threshold", s.lms_outlier_threshold)?;
        positive("solver.degenerate_subset_det", s.degenerate_subset_det)?;
        positive("noise.edge_normal_sigma_deg", self.noise.edge_normal_sigma_deg)?;
        positive("motion.upright_height_m", self.motion.upright_height_m)?;
        positive("motion.max_turn_rate_deg_s", self.motion.max_turn_rate_deg_s)?;
        positive("motion.max_speed_m_s", self.motion.max_speed_m_s)?;
        positive("motion.accel_noise_m_s2", self.motion.accel_noise_m_s2)?;
        positive(
            "motion.angular_accel_noise_deg_s2",
            self.motion.angular_accel_noise_deg_s2,
        )?;
        let tilt = self.motion.max_tilt_deg;
        if !(tilt > 0.0 && tilt <= 180.0) {
            return Err(format!("key 'motion.max_tilt_deg': must be in (0, 180], found {tilt}"));
        }
        let [lo, hi] = self.motion.height_above_floor_m;
        if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
            return Err(format!(
                "key 'motion.height_above_floor_m': must be [lowest, highest] with 0 <= lowest < highest, found [{lo}, {hi}]"
            ));
        }
        positive("budgets.frame_ms", self.budgets.frame_ms)?;
        positive("budgets.edges_ms", self.budgets.edges_ms)?;
        positive("budgets.frame_sync_tolerance_ms", self.budgets.frame_sync_tolerance_ms)?;
        positive("budgets.capture_ms", self.budgets.capture_ms)?;
        positive("budgets.track_ms", self.budgets.track_ms)?;
        positive("budgets.publish_ms", self.budgets.publish_ms)?;
        positive("budgets.frame_assembly_wait_ms", self.budgets.frame_assembly_wait_ms)?;
        positive("budgets.status_interval_ms", self.budgets.status_interval_ms)?;
        if self.budgets.realtime_priority > 99 {
            return Err(format!(
                "key 'budgets.realtime_priority': must be 0 (off) to 99, found {}",
                self.budgets.realtime_priority
            ));
        }
        Ok(())
    }
}
