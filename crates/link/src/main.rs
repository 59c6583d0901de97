//! `omnitrack-link`: poses to other hosts over Zenoh (see the library doc).
//!
//! ```text
//! omnitrack-link send   [--service omnitrack/pose] [--key omnitrack/pose] [--listen EP]... [--connect EP]... [--count N]
//! omnitrack-link listen [--key omnitrack/pose] [--listen EP]... [--connect EP]... [--count N] [--idle-s S] [--latency] [--republish SERVICE]
//! omnitrack-link completions SHELL
//! omnitrack-link manpage [--dir DIR]
//! ```
//!
//! `send` runs beside the tracker; `listen` on the far host prints one line per pose, as
//! `omnitrack listen` does, and with `--latency` a closing line with the poses' age on arrival
//! where it can be read (a live source's stamps, the sender on this machine: the same machine
//! or network namespaces of one machine), and otherwise says that the clocks are not comparable
//! and why (see the library doc). Errors are one line on standard error and exit code 1; a
//! broken standard output ends quietly.

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
        /// Print the poses' age on arrival (p50, p99, max) when done, where the clocks are
        /// comparable (a live source's stamps, the sender on this machine); otherwise say why not.
        #[arg(long)]
        latency: bool,
        /// Publish each pose on this local iceoryx2 service too (e.g. omnitrack/pose), for
        /// programs on this host that subscribe as they would on the rig.
        #[arg(long, value_name = "SERVICE")]
        republish: Option<String>,
    },
    /// Prints a shell completion script for omnitrack-link (bash, zsh, fish, elvish or powershell).
    Completions {
        /// The shell.
        shell: omnitrack_manual::Shell,
    },
    /// Prints omnitrack-link's manual page (roff), or writes it and a page per command into a
    /// directory.
    Manpage(omnitrack_manual::ManpageArgs),
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
            if latency {
                eprintln!("{}", latency_line(&s));
            }
        }
        Command::Completions { shell } => omnitrack_manual::run_completions(&manual(), shell)?,
        Command::Manpage(args) => omnitrack_manual::run_manpage(&manual(), &args)?,
    }
    Ok(())
}

fn manual() -> omnitrack_manual::Manual {
    omnitrack_manual::Manual::new(<Cli as clap::CommandFactory>::command())
}

/// `latency: p50 … µs, p99 … µs, max … µs (N poses)`, and the poses whose age cannot be read
/// with the reason; or `latency: not comparable: …` when none can.
fn latency_line(s: &omnitrack_link::ListenSummary) -> String {
    let reasons: Vec<String> = s
        .not_comparable
        .iter()
        .map(|(why, n)| format!("{n} poses: {why}"))
        .collect();
    let quantiles = (
        s.latency_quantile_us(0.5),
        s.latency_quantile_us(0.99),
        s.latency_quantile_us(1.0),
    );
    match quantiles {
        (Some(p50), Some(p99), Some(max)) => {
            let mut line = format!(
                "latency: p50 {p50:.0} µs, p99 {p99:.0} µs, max {max:.0} µs ({} poses)",
                s.latencies_us.len()
            );
            if !reasons.is_empty() {
                line += &format!("; not comparable: {}", reasons.join("; "));
            }
            line
        }
        _ if reasons.is_empty() => "latency: no pose received".to_string(),
        _ => format!("latency: not comparable: {}", reasons.join("; ")),
    }
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
