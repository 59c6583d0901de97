//! Stage timings: fixed-size log-linear histograms (no allocation after construction), the
//! pipeline's stages with their budgets, the CPU time per frame and per thread (thread CPU
//! clocks, [`CpuSummary`]), and per-sensor counters shared between threads.

use omnitrack_config::BudgetConfig;
use omnitrack_io::publish::Stage;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Sub-buckets per power of two: 2^5 = 32, so a bucket is at most 1/32 ≈ 3 % wide.
const SUB_BITS: u32 = 5;
const SUB: usize = 1 << SUB_BITS;
/// Largest exponent kept apart: 2^41 ns ≈ 37 min; longer durations share the last bucket.
const MAX_EXP: u32 = 40;
/// Buckets of a [`Histogram`]: 32 exact ones (0–31 ns), then 32 per power of two up to 2^41 ns.
pub const BUCKETS: usize = SUB + (MAX_EXP - SUB_BITS + 1) as usize * SUB;

/// Durations (nanoseconds) in `BUCKETS` log-linear buckets: quantiles within ~3 %, the maximum
/// and the mean exact. Allocates once, in [`Histogram::new`].
#[derive(Clone)]
pub struct Histogram {
    counts: Box<[u64; BUCKETS]>,
    total: u64,
    sum_ns: u128,
    max_ns: u64,
}

impl std::fmt::Debug for Histogram {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Histogram")
            .field("count", &self.total)
            .field("p50", &self.quantile(0.5))
            .field("p99", &self.quantile(0.99))
            .field("max", &self.max())
            .finish()
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram::new()
    }
}

fn bucket(ns: u64) -> usize {
    if ns < SUB as u64 {
        return ns as usize;
    }
    let e = 63 - ns.leading_zeros();
    if e > MAX_EXP {
        return BUCKETS - 1;
    }
    let m = ((ns >> (e - SUB_BITS)) as usize) & (SUB - 1);
    SUB + (e - SUB_BITS) as usize * SUB + m
}

/// Largest value that falls into bucket `i`.
fn bucket_upper(i: usize) -> u64 {
    if i < SUB {
        return i as u64;
    }
    let e = ((i - SUB) / SUB) as u32 + SUB_BITS;
    let m = ((i - SUB) % SUB) as u64;
    ((SUB as u64 + m + 1) << (e - SUB_BITS)) - 1
}

impl Histogram {
    pub fn new() -> Histogram {
        Histogram {
            counts: Box::new([0; BUCKETS]),
            total: 0,
            sum_ns: 0,
            max_ns: 0,
        }
    }

    pub fn record(&mut self, d: Duration) {
        let ns = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        self.counts[bucket(ns)] += 1;
        self.total += 1;
        self.sum_ns += u128::from(ns);
        self.max_ns = self.max_ns.max(ns);
    }

    pub fn count(&self) -> u64 {
        self.total
    }

    pub fn max(&self) -> Duration {
        Duration::from_nanos(self.max_ns)
    }

    pub fn mean(&self) -> Duration {
        if self.total == 0 {
            return Duration::ZERO;
        }
        Duration::from_nanos((self.sum_ns / u128::from(self.total)) as u64)
    }

    /// The `q` quantile (0 ≤ q ≤ 1): the upper edge of the bucket holding it, never above the
    /// maximum; zero when empty.
    pub fn quantile(&self, q: f64) -> Duration {
        if self.total == 0 {
            return Duration::ZERO;
        }
        let target = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= target {
                return Duration::from_nanos(bucket_upper(i).min(self.max_ns));
            }
        }
        self.max()
    }
}

/// A stage's budget in tracker.toml `[budgets]`, if it has one: `capture_ms`, `edges_ms`,
/// `track_ms`, `publish_ms` and, for the whole frame (hand-over into the pool → pose sent),
/// `frame_ms`. Matching and solving are parts of `track` with no budget of their own.
pub fn stage_budget(stage: Stage, b: &BudgetConfig) -> Option<Duration> {
    let ms = match stage {
        Stage::Capture => b.capture_ms,
        Stage::Edges => b.edges_ms,
        Stage::Track => b.track_ms,
        Stage::Publish => b.publish_ms,
        Stage::Frame => b.frame_ms,
        Stage::Match | Stage::Solve => return None,
    };
    Some(Duration::from_secs_f64(ms / 1e3))
}

/// One stage's timings against its budget.
#[derive(Debug, Clone, Default)]
pub struct StageClock {
    pub histogram: Histogram,
    pub budget: Option<Duration>,
    /// Measurements above the budget.
    pub overruns: u64,
}

impl StageClock {
    pub fn new(budget: Option<Duration>) -> StageClock {
        StageClock {
            histogram: Histogram::new(),
            budget,
            overruns: 0,
        }
    }

    /// Records `d`; true when it overran the budget.
    pub fn record(&mut self, d: Duration) -> bool {
        self.histogram.record(d);
        let over = self.budget.is_some_and(|b| d > b);
        self.overruns += u64::from(over);
        over
    }

    pub fn summary(&self) -> StageSummary {
        StageSummary {
            budget: self.budget,
            overruns: self.overruns,
            ..summary_of(&self.histogram)
        }
    }
}

/// One stage over a whole run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageSummary {
    pub count: u64,
    pub p50: Duration,
    pub p99: Duration,
    pub max: Duration,
    pub mean: Duration,
    pub budget: Option<Duration>,
    pub overruns: u64,
}

/// The kinds of pipeline thread whose CPU time a run adds up ([`CpuSummary`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ThreadRole {
    /// Capture threads and the assembly thread: reading and decoding the source.
    Capture = 0,
    /// The process thread: its share of the edges, the tracker, publishing; start-up included.
    Process,
    /// The edge detector's worker threads, on frames.
    EdgeWorkers,
    /// The tracker's search thread.
    Search,
    /// The caller's thread while it runs the sink.
    Sink,
}

impl ThreadRole {
    pub(crate) const COUNT: usize = 5;
}

/// CPU time (thread CPU clocks: time a thread ran, not time it waited for a core, so other work
/// on the machine disturbs it far less than the wall-clock stage times).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CpuSummary {
    /// Per processed frame: the edge stage, every thread's share
    /// ([`EdgeDetector::last_cpu`](omnitrack_edges::EdgeDetector::last_cpu)).
    pub edges: StageSummary,
    /// Per processed frame: the tracker on the process thread (a search's own thread apart).
    pub track: StageSummary,
    /// Per processed frame: edges + tracker + publishing the pose, the frame path's cost.
    pub frame: StageSummary,
    /// Per read of the source by a capture thread (a whole-rig source: per frame, decoding
    /// included).
    pub capture: StageSummary,
    /// Over the whole run, per kind of thread (start-up included where the thread does it).
    pub capture_total: Duration,
    pub process_total: Duration,
    pub edge_workers_total: Duration,
    /// The search thread's and its helper threads' (a search's lanes run on both).
    pub search_total: Duration,
    pub sink_total: Duration,
}

impl CpuSummary {
    /// Every pipeline thread's CPU time over the run.
    pub fn total(&self) -> Duration {
        self.capture_total + self.process_total + self.edge_workers_total + self.search_total + self.sink_total
    }
}

/// The summary of a histogram with no budget.
pub(crate) fn summary_of(h: &Histogram) -> StageSummary {
    StageSummary {
        count: h.count(),
        p50: h.quantile(0.5),
        p99: h.quantile(0.99),
        max: h.max(),
        mean: h.mean(),
        budget: None,
        overruns: 0,
    }
}

/// What happened to one sensor's images, counted by the thread that decided it. Every image a
/// source produced lands in exactly one of these.
#[derive(Debug, Default)]
pub(crate) struct SensorCounters {
    pub delivered: AtomicU64,
    pub overwritten: AtomicU64,
    pub faults: AtomicU64,
    pub sync_missed: AtomicU64,
    pub left: AtomicU64,
}

impl SensorCounters {
    pub fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }

    pub fn snapshot(&self) -> SensorSummary {
        SensorSummary {
            delivered: self.delivered.load(Ordering::Relaxed),
            overwritten: self.overwritten.load(Ordering::Relaxed),
            faults: self.faults.load(Ordering::Relaxed),
            sync_missed: self.sync_missed.load(Ordering::Relaxed),
            left: self.left.load(Ordering::Relaxed),
        }
    }
}

/// One sensor over a run (or so far).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SensorSummary {
    /// Valid images that reached the tracker.
    pub delivered: u64,
    /// Valid images lost because a newer frame replaced theirs while the tracker was busy
    /// (latest frame wins), or because a second image of the same instant replaced them.
    pub overwritten: u64,
    /// Images the source marked invalid (dropped, missing, corrupt, wrong size or format, the
    /// camera lost).
    pub faults: u64,
    /// Images that missed their instant's assembly window (per-sensor capture only): too late,
    /// too early, or never came while the other sensors' images did.
    pub sync_missed: u64,
    /// Valid images of frames read but never processed because the run ended first (a stop, or
    /// `max_frames` reached while capture had read ahead): neither dropped nor delivered.
    pub left: u64,
}

impl SensorSummary {
    /// Every image of this sensor that did not reach the tracker: what the status sample's
    /// `frames_dropped` carries.
    pub fn lost(&self) -> u64 {
        self.overwritten + self.faults + self.sync_missed + self.left
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_are_contiguous_and_tight() {
        let mut prev_upper = None;
        for i in 0..BUCKETS - 1 {
            let up = bucket_upper(i);
            assert_eq!(bucket(up), i, "upper edge of {i}");
            if let Some(p) = prev_upper {
                assert_eq!(bucket(p + 1), i, "first value of {i}");
            }
            prev_upper = Some(up);
        }
        for ns in [0u64, 1, 31, 32, 33, 63, 64, 1000, 123_456, 33_000_000] {
            let up = bucket_upper(bucket(ns));
            assert!(up >= ns && (up - ns) as f64 <= ns as f64 / 31.0 + 1.0, "{ns} → {up}");
        }
    }

    #[test]
    fn quantiles_come_within_the_bucket_width() {
        let mut h = Histogram::new();
        for us in 1..=1000u64 {
            h.record(Duration::from_micros(us));
        }
        let p50 = h.quantile(0.5).as_secs_f64() * 1e6;
        let p99 = h.quantile(0.99).as_secs_f64() * 1e6;
        assert!((500.0..=500.0 * 1.04).contains(&p50), "{p50}");
        assert!((990.0..=1000.0).contains(&p99), "{p99}");
        assert_eq!(h.max(), Duration::from_micros(1000));
        assert_eq!(h.count(), 1000);
        assert_eq!(Histogram::new().quantile(0.5), Duration::ZERO);
    }

    #[test]
    fn overruns_are_counted_against_the_budget() {
        let mut c = StageClock::new(Some(Duration::from_millis(10)));
        assert!(!c.record(Duration::from_millis(9)));
        assert!(!c.record(Duration::from_millis(10)));
        assert!(c.record(Duration::from_millis(11)));
        assert_eq!(c.summary().overruns, 1);
        assert_eq!(c.summary().count, 3);
    }
}
