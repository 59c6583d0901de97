//! `omnitrack-link`: poses to other hosts over Zenoh (see the library doc).
//!
//! ```text
//! omnitrack-link send   [--service omnitrack/pose] [--key omnitrack/pose] [--listen EP]... [--connect EP]... [--count N]
//! omnitrack-link listen [--key omnitrack/pose] [--listen EP]... [--connect EP]... [--count N] [--idle-s S] [--latency] [--republish SERVICE]
//! ```
//!
//! `send` runs beside the tracker; `listen` on the far host prints one line per pose, as
//! `omnitrack listen` does, and with `--latency` a closing line with the poses' age on arrival
//! (on this host's monotonic clock: meaningful where the sender's capture clock is the same,
//! i.e. the same machine or network namespaces of one machine). Errors are one line on standard
//! error and exit code 1; a broken standard output ends quietly.

use clap::{Parser, Subcommand};
use omnitrack_link::{listen, send, stop_on_signals, Endpoints, LinkError, ListenOptions, POSE_KEY};
use std::time::Duration;

#[derive(Parser)]
#[command(
    name = "omnitrack-link",
    version,
    about = "omnitrack poses to other hosts over Zenoh"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args)]
struct Network {
    /// A Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).
    #[arg(long = "listen")]
    listen: Vec<String>,
    /// A Zenoh endpoint to connect to, e.g. tcp/192.168.1.20:7447 (repeatable).
    #[arg(long = "connect")]
    connect: Vec<String>,
    /// The Zenoh key expression of the poses.
    #[arg(long, default_value = POSE_KEY)]
    key: String,
}

#[derive(Subcommand)]
enum Command {
    /// Forwards the local pose service to Zenoh.
    Send {
        /// The local iceoryx2 pose service.
        #[arg(long, default_value = "omnitrack/pose")]
        service: String,
        #[command(flatten)]
        network: Network,
        /// Stop after forwarding this many poses.
        #[arg(long)]
        count: Option<u64>,
    },
    /// Prints the poses arriving over Zenoh, one line each.
    Listen {
        #[command(flatten)]
        network: Network,
        /// Stop after this many poses.
        #[arg(long)]
        count: Option<u64>,
        /// Stop when no pose came for this many seconds.
        #[arg(long = "idle-s")]
        idle_s: Option<f64>,
        /// Print the poses' age on arrival (p50, p99, max) when done.
        #[arg(long)]
        latency: bool,
        /// Publish each pose on this local iceoryx2 service too (e.g. omnitrack/pose), for
        /// programs on this host that subscribe as they would on the rig.
        #[arg(long, value_name = "SERVICE")]
        republish: Option<String>,
    },
}

fn endpoints(n: &Network) -> Endpoints {
    Endpoints {
        listen: n.listen.clone(),
        connect: n.connect.clone(),
    }
}

fn run(cli: Cli) -> Result<(), LinkError> {
    let stop = stop_on_signals();
    match cli.command {
        Command::Send {
            service,
            network,
            count,
        } => {
            let s = send(&service, &network.key, &endpoints(&network), count, &stop)?;
            eprintln!("forwarded {} poses from {service} to {}", s.forwarded, network.key);
        }
        Command::Listen {
            network,
            count,
            idle_s,
            latency,
            republish,
        } => {
            let idle = match idle_s {
                Some(s) if !(s.is_finite() && s > 0.0) => {
                    return Err(LinkError::Zenoh(format!(
                        "--idle-s must be a positive number of seconds, found {s}"
                    )))
                }
                s => s.map(Duration::from_secs_f64),
            };
            let mut out = std::io::stdout().lock();
            let options = ListenOptions {
                count,
                idle,
                latency,
                republish,
            };
            let s = listen(&network.key, &endpoints(&network), &options, &stop, &mut out)?;
            eprintln!("received {} poses, {} missing", s.received, s.missing);
            if let (Some(p50), Some(p99), Some(max)) = (
                s.latency_quantile_us(0.5),
                s.latency_quantile_us(0.99),
                s.latency_quantile_us(1.0),
            ) {
                eprintln!("latency: p50 {p50:.0} µs, p99 {p99:.0} µs, max {max:.0} µs");
            }
        }
    }
    Ok(())
}

fn main() {
    match run(Cli::parse()) {
        Ok(()) => {}
        Err(LinkError::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        Err(e) => {
            eprintln!("omnitrack-link: {e}");
            std::process::exit(1);
        }
    }
}
