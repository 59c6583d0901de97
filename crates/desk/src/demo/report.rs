//! The demo's table as the command prints it: accuracy, speed, the first search, the stages'
//! times and the pictures' paths.
//!
//! In: a [`DemoReport`]. Out: text.

use super::*;

impl fmt::Display for DemoReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let excerpt = if self.frames_requested < self.paper_frames {
            format!(
                ", a {:.0} s excerpt of the paper's {}-frame sequence",
                self.frames_requested as f64 / self.frame_rate_hz,
                self.paper_frames
            )
        } else {
            String::new()
        };
        writeln!(
            f,
            "omnitrack demo: the synthetic `{}` building, {} frames at {} Hz{excerpt} (seed {})",
            self.scenario, self.frames_requested, self.frame_rate_hz, self.seed
        )?;
        writeln!(f, "cache:     {} ({})", self.cache_dir.display(), self.cache_origin)?;
        writeln!(
            f,
            "recording: {} ({})",
            self.recording_dir.display(),
            if self.rendered_now { "rendered now" } else { "reused" }
        )?;
        writeln!(f, "table:     {}", self.table_origin)?;
        let c = self.hint.centre;
        writeln!(
            f,
            "start:     searched a {} m volume centred at ({:.2}, {:.2}, {:.2}), {:.1} m from the true start",
            self.hint.diameter_m.unwrap_or(f64::NAN),
            c.x,
            c.y,
            c.z,
            (c - self.first_truth).norm()
        )?;
        writeln!(f)?;
        let ms = |d: Option<Duration>| d.map_or("n/a".into(), |d| format!("{:.0}", d.as_secs_f64() * 1e3));
        let pair = |p: Option<(f64, f64)>, scale: f64, digits: usize| {
            p.map_or("n/a".into(), |(a, b)| {
                format!("{:.digits$} / {:.digits$}", a * scale, b * scale)
            })
        };
        let first = self
            .first_pose_frame
            .map_or(String::new(), |k| format!(" (first pose on frame {k})"));
        let rows = [
            ("frames", self.frames.to_string()),
            (
                "frames tracked",
                format!(
                    "{:.1} % on time ({} of {}), {:.1} % with the late poses",
                    100.0 * self.tracked as f64 / self.frames.max(1) as f64,
                    self.tracked,
                    self.frames,
                    100.0 * (self.tracked + self.late) as f64 / self.frames.max(1) as f64,
                ),
            ),
            ("ATE position RMSE / max (cm)", pair(self.ate_position_m, 100.0, 2)),
            ("ATE rotation RMSE / max (deg)", pair(self.ate_rotation_deg, 1.0, 3)),
            ("initialisation (ms)", format!("{}{first}", ms(self.init_time))),
            ("frames/s (edges + tracking)", format!("{:.1}", self.frames_per_s)),
            (
                "latency p50 / p99 (ms)",
                format!("{:.1} / {:.1}", self.latency_p50_ms, self.latency_p99_ms),
            ),
            (
                "re-initialisations",
                format!(
                    "{} ({} losses, {} relocalisations)",
                    self.reinitialisations, self.losses, self.relocalisations
                ),
            ),
        ];
        for (name, value) in rows {
            writeln!(f, "  {name:<31} {value}")?;
        }
        writeln!(
            f,
            "  (ATE with no alignment: both trajectories are in the model frame; speed excludes PNG decoding)"
        )?;
        writeln!(f)?;
        writeln!(f, "pictures:")?;
        for p in &self.pictures {
            writeln!(f, "  {:<22} {}", p.name, p.path.display())?;
        }
        for s in &self.skipped {
            writeln!(f, "  not drawn: {s}")?;
        }
        let t = &self.times;
        let s = |d: Duration| d.as_secs_f64();
        write!(
            f,
            "time: recording {:.1} s ({}), visibility table {:.1} s, tracking {:.1} s (with PNG decoding), \
             pictures {:.1} s; total {:.1} s",
            s(t.recording),
            if self.rendered_now { "rendered" } else { "cached" },
            s(t.table),
            s(t.tracking),
            s(t.pictures),
            s(t.total)
        )
    }
}
