//! Pose publish → subscriber receive latency over iceoryx2 shared memory (issue 8 / docs/design.md
//! target: p99 < 50 µs): p50/p99/max over 100,000 samples, subscriber in another process.
//!
//! By default the bench re-executes itself (`std::env::current_exe()`) with the hidden arguments
//! `--subscriber SERVICE N MODE`; that child creates a `PoseSubscriber` on a service name unique to
//! this run (pid + time), prints `READY`, receives samples until the end marker
//! (`sequence == u64::MAX`) and prints one `RESULT` line (received, lost, p50/p99/max in ns) on
//! stdout. The child exits if its stdin reaches EOF (the parent died or dropped the pipe) or if
//! no sample arrives for 5 s. With `--threads` the subscriber runs in a thread of this process
//! instead (the old setup).
//!
//! The publisher writes its send time into `timestamp_ns` just before loan/write/send; the
//! subscriber takes receive time − send time. Both are `SystemTime::now()` since UNIX_EPOCH in ns
//! (CLOCK_REALTIME, comparable across processes; NTP can slew it, by ≤ 500 ppm, i.e. < 0.05 µs
//! per 100 µs — negligible here, but a step would show up as an outlier or as 0, since negative
//! latencies are clamped to 0 and counted). The publisher sleeps (does not spin) until the next
//! send, one every 50 µs nominal (the sleep overshoots, so the real rate is lower; when late it does
//! not catch up in a burst). N = 100,000 samples for the busy-polling subscriber
//! (`PoseSubscriber::poll`), then 100,000 for the subscriber that sleeps on the service's event
//! (`PoseSubscriber::wait`); each takes roughly 5–15 s.
//!
//! Run: `cargo bench --bench publish` (`-- N` changes the sample count of both modes,
//! `-- --threads` uses a subscriber thread, `-- --period-us P` the publish period).

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use omnitrack::publish::{PosePublisher, PoseSample, PoseSubscriber};

/// CLOCK_REALTIME in ns since the UNIX epoch (comparable between processes).
fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// The subscriber gives up after this long without a sample.
const IDLE_LIMIT: Duration = Duration::from_secs(5);
const TARGET_US: f64 = 50.0;

#[derive(Clone, Copy)]
enum Mode {
    BusyPoll,
    Event,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::BusyPoll => "busy-poll",
            Mode::Event => "event",
        }
    }

    fn parse(s: &str) -> Option<Mode> {
        match s {
            "busy-poll" => Some(Mode::BusyPoll),
            "event" => Some(Mode::Event),
            _ => None,
        }
    }
}

/// What the subscriber reports (latencies in ns).
struct Summary {
    received: u64,
    lost: u64,
    clamped: u64,
    timed_out: bool,
    p50: u64,
    p99: u64,
    max: u64,
}

impl Summary {
    fn to_line(&self) -> String {
        format!(
            "RESULT {} {} {} {} {} {} {}",
            self.received, self.lost, self.clamped, self.timed_out as u8, self.p50, self.p99, self.max
        )
    }

    fn from_line(line: &str) -> Option<Summary> {
        let v: Vec<u64> = line
            .strip_prefix("RESULT ")?
            .split_whitespace()
            .map(|x| x.parse().ok())
            .collect::<Option<_>>()?;
        if v.len() != 7 {
            return None;
        }
        Some(Summary {
            received: v[0],
            lost: v[1],
            clamped: v[2],
            timed_out: v[3] != 0,
            p50: v[4],
            p99: v[5],
            max: v[6],
        })
    }
}

fn pct(sorted: &[u64], p: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// Receives until the end marker (or `IDLE_LIMIT` without a sample); `ready` is called once the
/// subscriber port exists.
fn subscribe(service: &str, n: usize, mode: Mode, ready: impl FnOnce()) -> Summary {
    let sub = PoseSubscriber::create(service).expect("subscriber");
    ready();
    let mut latencies = Vec::with_capacity(n);
    let mut clamped = 0;
    let mut timed_out = false;
    loop {
        let got = match mode {
            Mode::BusyPoll => sub.poll(IDLE_LIMIT),
            Mode::Event => sub.wait(IDLE_LIMIT),
        }
        .expect("receive");
        let t = now_ns();
        match got {
            Some(s) if s.sequence == u64::MAX => break,
            Some(s) => {
                if t < s.timestamp_ns {
                    clamped += 1;
                }
                latencies.push(t.saturating_sub(s.timestamp_ns));
            }
            None => {
                timed_out = true;
                break;
            }
        }
    }
    latencies.sort_unstable();
    Summary {
        received: latencies.len() as u64,
        lost: (n as u64).saturating_sub(latencies.len() as u64),
        clamped,
        timed_out,
        p50: pct(&latencies, 0.5),
        p99: pct(&latencies, 0.99),
        max: pct(&latencies, 1.0),
    }
}

/// Child process: `--subscriber SERVICE N MODE`.
fn child_main(args: &[String]) {
    let (service, n, mode) = match args {
        [s, n, m, ..] => (s.as_str(), n.parse().expect("N"), Mode::parse(m).expect("MODE")),
        _ => panic!("usage: --subscriber SERVICE N MODE"),
    };
    // Exit when the parent goes away (its end of our stdin closes).
    std::thread::spawn(|| {
        let mut buf = [0u8; 64];
        let mut stdin = std::io::stdin();
        loop {
            match stdin.read(&mut buf) {
                Ok(0) | Err(_) => std::process::exit(2),
                Ok(_) => {}
            }
        }
    });
    let summary = subscribe(service, n, mode, || {
        println!("READY");
        std::io::stdout().flush().ok();
    });
    println!("{}", summary.to_line());
    std::io::stdout().flush().ok();
}

/// Publishes `n` samples one every `period` (sleeping), then the end marker; returns the
/// per-`publish()` durations in ns, sorted.
fn publish_all(service: &str, n: usize, period: Duration) -> Vec<u64> {
    let publisher = PosePublisher::create(service).expect("publisher");
    let mut sample = PoseSample::default();
    let mut publish_ns = Vec::with_capacity(n);
    let mut next = Instant::now() + period;
    for seq in 0..n as u64 {
        // Sleep (not spin): the tracker does not spin either, and on two cores a spinning
        // publisher would starve the busy-polling subscriber.
        let now = Instant::now();
        match next.checked_duration_since(now) {
            Some(d) => {
                std::thread::sleep(d);
                next += period;
            }
            // Late (sleep overshoot): send now, no catch-up burst.
            None => next = now + period,
        }
        sample.sequence = seq;
        sample.timestamp_ns = now_ns();
        publisher.publish(&sample).expect("publish");
        publish_ns.push(now_ns().saturating_sub(sample.timestamp_ns));
    }
    // Leave the subscriber time to drain, then stop it.
    std::thread::sleep(Duration::from_millis(20));
    sample.sequence = u64::MAX;
    publisher.publish(&sample).expect("publish");
    publish_ns.sort_unstable();
    publish_ns
}

fn service_name(mode: Mode) -> String {
    format!(
        "omnitrack-bench/publish/{}/{}/{}",
        std::process::id(),
        now_ns(),
        mode.name()
    )
}

fn run_process(mode: Mode, n: usize, period: Duration) -> (Summary, Vec<u64>) {
    let service = service_name(mode);
    let exe = std::env::current_exe().expect("current_exe");
    let mut child = Command::new(exe)
        .args(["--subscriber", &service, &n.to_string(), mode.name()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn subscriber process");
    // Keep the child's stdin open while it works: closing it (or dying) makes the child exit.
    let stdin = child.stdin.take();
    let mut lines = BufReader::new(child.stdout.take().expect("child stdout")).lines();
    let mut next_line = |want: &str| loop {
        match lines.next() {
            Some(Ok(l)) if l.starts_with(want) => return l,
            Some(Ok(_)) => {}
            _ => panic!("subscriber process ended before {want}"),
        }
    };
    next_line("READY");
    let publish_ns = publish_all(&service, n, period);
    let summary = Summary::from_line(&next_line("RESULT ")).expect("RESULT line");
    drop(stdin);
    child.wait().expect("wait for subscriber");
    (summary, publish_ns)
}

fn run_thread(mode: Mode, n: usize, period: Duration) -> (Summary, Vec<u64>) {
    let service = service_name(mode);
    let (tx, rx) = mpsc::channel();
    let sub_service = service.clone();
    let handle = std::thread::spawn(move || subscribe(&sub_service, n, mode, move || tx.send(()).unwrap()));
    rx.recv().expect("subscriber thread ready");
    let publish_ns = publish_all(&service, n, period);
    (handle.join().expect("subscriber thread"), publish_ns)
}

fn us(ns: u64) -> f64 {
    ns as f64 / 1000.0
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(i) = args.iter().position(|a| a == "--subscriber") {
        child_main(&args[i + 1..]);
        return;
    }
    let threads = args.iter().any(|a| a == "--threads");
    let period_us: u64 = args
        .iter()
        .position(|a| a == "--period-us")
        .and_then(|i| args.get(i + 1)?.parse().ok())
        .unwrap_or(50);
    let n: usize = args
        .iter()
        .enumerate()
        .filter(|(i, _)| *i == 0 || args[i - 1] != "--period-us")
        .find_map(|(_, a)| a.parse().ok())
        .unwrap_or(100_000);
    let period = Duration::from_micros(period_us);
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let setup = if threads {
        "subscriber in a thread of this process"
    } else {
        "subscriber in another process"
    };
    println!(
        "pose publish → receive latency, {n} samples per mode, one every ≥{period_us} µs, {setup}, \
         iceoryx2 ipc; load average {}\n",
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
    println!("| subscriber | samples | received | lost | p50 µs | p99 µs | max µs | p99 < {TARGET_US} µs | publish() p50/p99 µs |");
    println!("|---|---:|---:|---:|---:|---:|---:|---|---:|");
    for mode in [Mode::BusyPoll, Mode::Event] {
        let (s, publish_ns) = if threads {
            run_thread(mode, n, period)
        } else {
            run_process(mode, n, period)
        };
        let p99 = us(s.p99);
        println!(
            "| {} | {n} | {} | {} | {:.2} | {:.2} | {:.2} | {} | {:.2}/{:.2} |",
            mode.name(),
            s.received,
            s.lost,
            us(s.p50),
            p99,
            us(s.max),
            if s.received > 0 && p99 < TARGET_US {
                "yes"
            } else {
                "**no**"
            },
            us(pct(&publish_ns, 0.5)),
            us(pct(&publish_ns, 0.99)),
        );
        if s.timed_out || s.clamped > 0 {
            println!(
                "|   ({}: {}{} negative latencies clamped to 0) | | | | | | | | |",
                mode.name(),
                if s.timed_out { "subscriber timed out; " } else { "" },
                s.clamped
            );
        }
    }
    println!("\n(lost = overwritten in the subscriber's 8-sample buffer while it was descheduled)");
}
