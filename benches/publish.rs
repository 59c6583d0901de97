//! Pose publish → subscriber receive latency over iceoryx2 shared memory (DESIGN.md target:
//! p99 < 50 µs). Publisher and subscriber run in two threads of this process, each with its own
//! iceoryx2 node and ports, on a unique service name. The publisher writes its send time (ns since
//! a process-wide `Instant`) into `timestamp_ns` just before loan/write/send; the subscriber takes
//! receive time − send time. N = 10,000 samples, one every ≥ 200 µs (the publisher sleeps between sends; each sample is received on its own),
//! first for a busy-polling subscriber (`PoseSubscriber::poll`), then for one that sleeps on the
//! service's event (`PoseSubscriber::wait`).
//!
//! Run: `cargo bench --bench publish` (add `-- N` to change the sample count).

use std::sync::{Arc, Barrier, OnceLock};
use std::time::{Duration, Instant};

use omnitrack::publish::{PosePublisher, PoseSample, PoseSubscriber};

static EPOCH: OnceLock<Instant> = OnceLock::new();

fn now_ns() -> u64 {
    EPOCH.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

#[derive(Clone, Copy)]
enum Mode {
    BusyPoll,
    Event,
}

struct Result {
    latencies_ns: Vec<u64>,
    missed: usize,
    publish_ns: Vec<u64>,
}

fn run(mode: Mode, n: usize) -> Result {
    let name = format!("omnitrack-bench/publish/{}/{}", std::process::id(), now_ns());
    let barrier = Arc::new(Barrier::new(2));
    let sub_name = name.clone();
    let sub_barrier = barrier.clone();
    let subscriber = std::thread::spawn(move || {
        let sub = PoseSubscriber::create(&sub_name).expect("subscriber");
        sub_barrier.wait();
        let mut latencies = Vec::with_capacity(n);
        let mut missed = 0;
        while latencies.len() + missed < n {
            let got = match mode {
                Mode::BusyPoll => sub.poll(Duration::from_secs(1)),
                Mode::Event => sub.wait(Duration::from_secs(1)),
            }
            .expect("receive");
            let t = now_ns();
            match got {
                Some(s) if s.sequence == u64::MAX => break,
                Some(s) => latencies.push(t.saturating_sub(s.timestamp_ns)),
                None => missed += 1,
            }
        }
        (latencies, missed)
    });
    let publisher = PosePublisher::create(&name).expect("publisher");
    barrier.wait();
    let mut sample = PoseSample::default();
    let mut publish_ns = Vec::with_capacity(n);
    let period = Duration::from_micros(200);
    let mut next = Instant::now() + period;
    for seq in 0..n as u64 {
        // Sleep (not spin) until the next send: the tracker does not spin either, and on two cores
        // a spinning publisher would starve the busy-polling subscriber.
        if let Some(d) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        next += period;
        sample.sequence = seq;
        sample.timestamp_ns = now_ns();
        publisher.publish(&sample).expect("publish");
        publish_ns.push(now_ns() - sample.timestamp_ns);
    }
    // Leave the subscriber time to drain, then stop it should it have lost samples.
    std::thread::sleep(Duration::from_millis(20));
    sample.sequence = u64::MAX;
    publisher.publish(&sample).expect("publish");
    let (latencies_ns, missed) = subscriber.join().expect("subscriber thread");
    Result {
        latencies_ns,
        missed,
        publish_ns,
    }
}

fn pct(sorted: &[u64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i] as f64 / 1000.0
}

fn report(label: &str, r: &mut Result, n: usize) {
    r.latencies_ns.sort_unstable();
    r.publish_ns.sort_unstable();
    let l = &r.latencies_ns;
    println!(
        "{label:<10} received {:>5}/{n} (timeouts {}) send→receive µs: p50 {:>7.2}  p99 {:>7.2}  max {:>8.2}   \
         publish() µs: p50 {:>5.2} p99 {:>5.2}",
        l.len(),
        r.missed,
        pct(l, 0.5),
        pct(l, 0.99),
        pct(l, 1.0),
        pct(&r.publish_ns, 0.5),
        pct(&r.publish_ns, 0.99)
    );
}

fn main() {
    let n: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(10_000);
    now_ns();
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "pose publish → receive latency, {n} samples every ≥200 µs, two threads, iceoryx2 ipc_threadsafe; \
         load average {}",
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
    println!("(samples not received were overwritten in the subscriber's 8-sample buffer while it was descheduled)");
    let mut busy = run(Mode::BusyPoll, n);
    report("busy-poll", &mut busy, n);
    let mut event = run(Mode::Event, n);
    report("event", &mut event, n);
    let target = 50.0;
    for (label, r) in [("busy-poll", &busy), ("event", &event)] {
        let p99 = pct(&r.latencies_ns, 0.99);
        println!(
            "{label}: p99 {p99:.2} µs {} target {target} µs",
            if p99 < target { "meets" } else { "MISSES" }
        );
    }
}
