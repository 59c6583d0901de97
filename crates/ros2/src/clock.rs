//! From the capture clock to ROS time.
//!
//! The tracker stamps a pose with its frame's capture time (`PoseSample::timestamp_ns`). A live
//! source (V4L2, USB3 Vision) stamps on this host's `CLOCK_MONOTONIC`; ROS time is the system
//! clock (`CLOCK_REALTIME`, what `rclcpp::Clock` and tf2 read when no simulated time is used).
//! The two differ by an offset that NTP or PTP slews (and a `settimeofday` steps), so it is
//! measured, not assumed, and measured again every [`REMEASURE`]:
//!
//! 1. read `CLOCK_MONOTONIC` (m₀), `CLOCK_REALTIME` (r), `CLOCK_MONOTONIC` (m₁);
//! 2. offset = r − (m₀ + m₁)/2, uncertain by ± (m₁ − m₀)/2 (r was read somewhere between m₀ and
//!    m₁);
//! 3. keep the narrowest of [`READS`] such brackets (a preemption between two reads widens one
//!    bracket, rarely all of them).
//!
//! A pose's ROS stamp is then `timestamp_ns + offset`: its capture instant on the system clock,
//! not the instant it was published (the tracker's latency is not added to the data's age). The
//! offset and its uncertainty are printed at start and sent in every diagnostic message.
//!
//! A replay stamps its recording's time, which is neither clock: with [`CaptureClock::Receipt`]
//! a pose is stamped with the system clock when it arrives here (as a driver without hardware
//! stamps would). In [`CaptureClock::Monotonic`] mode a stamp that cannot be this host's
//! monotonic time of a live capture (more than [`MAX_AGE`] old, or ahead of now) is an error
//! naming the option, never a pose stamped minutes or years away.

use std::time::Duration;

/// Brackets read per measurement; the narrowest is kept.
pub const READS: usize = 32;

/// How often the offset is measured again while running.
pub const REMEASURE: Duration = Duration::from_secs(1);

/// Oldest a live pose's capture stamp may be on arrival (a long whole-model search publishes its
/// pose for the frame it started from, seconds earlier); older is not a live capture's stamp.
pub const MAX_AGE: Duration = Duration::from_secs(60);

/// Furthest ahead of this host's monotonic clock a stamp may be (none should be).
pub const MAX_AHEAD: Duration = Duration::from_millis(100);

/// Which clock the tracker's pose stamps are on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CaptureClock {
    /// This host's CLOCK_MONOTONIC (live V4L2 and USB3 Vision sources): ROS stamp = capture
    /// stamp + the measured system − monotonic offset.
    Monotonic,
    /// Not a clock of this host (a replay's recording time): ROS stamp = the system clock when
    /// the pose arrives.
    Receipt,
}

// `time_t` and `c_long` are i64 here, i32 on 32-bit targets.
#[allow(clippy::unnecessary_cast)]
fn read(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write; both clocks always exist on Linux.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as i64 * 1_000_000_000 + ts.tv_nsec as i64
}

/// This host's `CLOCK_MONOTONIC`, nanoseconds.
pub fn monotonic_ns() -> i64 {
    read(libc::CLOCK_MONOTONIC)
}

/// This host's system clock (`CLOCK_REALTIME`, ROS time), nanoseconds since the epoch.
pub fn system_ns() -> i64 {
    read(libc::CLOCK_REALTIME)
}

/// system − monotonic, as measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockOffset {
    /// Add to a monotonic time to get the system time of the same instant, ns.
    pub offset_ns: i64,
    /// Half the narrowest bracket: the offset is right within ± this, ns.
    pub uncertainty_ns: i64,
}

impl ClockOffset {
    /// Measures the offset ([`READS`] brackets, the narrowest kept; see the module doc).
    pub fn measure() -> ClockOffset {
        (0..READS)
            .map(|_| {
                let m0 = monotonic_ns();
                let r = system_ns();
                let m1 = monotonic_ns();
                ClockOffset {
                    offset_ns: r - (m0 + (m1 - m0) / 2),
                    uncertainty_ns: (m1 - m0 + 1) / 2,
                }
            })
            .min_by_key(|o| o.uncertainty_ns)
            .expect("READS > 0")
    }
}

impl std::fmt::Display for ClockOffset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "system − monotonic = {}.{:09} s ± {} ns",
            self.offset_ns.div_euclid(1_000_000_000),
            self.offset_ns.rem_euclid(1_000_000_000),
            self.uncertainty_ns
        )
    }
}

/// A stamp that is not what `--capture-clock` says it is.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StampError {
    #[error(
        "pose {sequence}: its stamp is {age_s:.1} s before this host's monotonic clock, not a live \
         capture's (a replay stamps its recording's time): run with --capture-clock receipt"
    )]
    TooOld { sequence: u64, age_s: f64 },
    #[error(
        "pose {sequence}: its stamp is {ahead_s:.3} s ahead of this host's monotonic clock, not a \
         live capture's: run with --capture-clock receipt"
    )]
    Ahead { sequence: u64, ahead_s: f64 },
    #[error("pose {sequence}: its stamp is beyond what ROS time can hold (year 2038)")]
    OutOfRange { sequence: u64 },
}

/// The ROS time (system clock, ns since the epoch) of a pose captured at `stamp_ns` on
/// `clock`, received at monotonic `now_mono_ns` / system `now_system_ns`, with the current
/// `offset`.
pub fn ros_stamp_ns(
    clock: CaptureClock,
    sequence: u64,
    stamp_ns: u64,
    now_mono_ns: i64,
    now_system_ns: i64,
    offset: &ClockOffset,
) -> Result<i64, StampError> {
    match clock {
        CaptureClock::Receipt => Ok(now_system_ns),
        CaptureClock::Monotonic => {
            let age = now_mono_ns as i128 - stamp_ns as i128;
            if age > MAX_AGE.as_nanos() as i128 {
                return Err(StampError::TooOld {
                    sequence,
                    age_s: age as f64 / 1e9,
                });
            }
            if -age > MAX_AHEAD.as_nanos() as i128 {
                return Err(StampError::Ahead {
                    sequence,
                    ahead_s: -age as f64 / 1e9,
                });
            }
            // Within a minute of a monotonic reading: fits an i64.
            Ok(stamp_ns as i64 + offset.offset_ns)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_offset_is_the_system_clock_minus_the_monotonic_within_its_bracket() {
        let o = ClockOffset::measure();
        // Independently: a monotonic read, then the system clock (std's, not libc's call here).
        let m = monotonic_ns();
        let s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as i64;
        // The two reads here are a few µs apart, and the offset moves by at most NTP's
        // 500 ppm slew in between.
        assert!((s - m - o.offset_ns).abs() < 2_000_000, "{o}, s − m = {}", s - m);
        assert!(o.uncertainty_ns >= 0 && o.uncertainty_ns < 1_000_000, "{o}");
        assert!(o.to_string().starts_with("system − monotonic = "), "{o}");
    }

    #[test]
    fn a_live_stamp_moves_by_the_offset_and_a_replays_is_refused_by_name() {
        let offset = ClockOffset {
            offset_ns: 1_700_000_000_000_000_000,
            uncertainty_ns: 40,
        };
        let now = 5_000_000_000_000i64;
        let stamp = (now - 20_000_000) as u64;
        let ros = ros_stamp_ns(CaptureClock::Monotonic, 1, stamp, now, 0, &offset);
        assert_eq!(ros, Ok(stamp as i64 + 1_700_000_000_000_000_000));
        // Receipt: the system clock at arrival, whatever the stamp.
        assert_eq!(ros_stamp_ns(CaptureClock::Receipt, 1, 7, now, 42, &offset), Ok(42));
        // A replay's stamps, 1,340 s back (what `omnitrack-link listen` once printed as a latency).
        let old = (now - 1_340_000_000_000) as u64;
        let e = ros_stamp_ns(CaptureClock::Monotonic, 9, old, now, 0, &offset).unwrap_err();
        assert_eq!(
            e.to_string(),
            "pose 9: its stamp is 1340.0 s before this host's monotonic clock, not a live capture's \
             (a replay stamps its recording's time): run with --capture-clock receipt"
        );
        let ahead = (now + 2_000_000_000) as u64;
        let e = ros_stamp_ns(CaptureClock::Monotonic, 3, ahead, now, 0, &offset).unwrap_err();
        assert!(matches!(e, StampError::Ahead { sequence: 3, .. }), "{e}");
        let e = ros_stamp_ns(CaptureClock::Monotonic, 4, u64::MAX, now, 0, &offset).unwrap_err();
        assert!(matches!(e, StampError::Ahead { sequence: 4, .. }), "{e}");
    }
}
