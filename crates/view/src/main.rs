//! `omnitrack-view`: the tracker seen live in Foxglove, and written to an MCAP file (see the
//! library doc).
//!
//! ```text
//! omnitrack-view serve [--services PREFIX] [--bind ADDR] [--port N | --no-server] [--mcap FILE]
//!     [--model MODEL.obj] [--recording DIR [--images-every-s S] [--no-edges] [--jpeg-quality Q]]
//!     [--count N] [--ready]
//! omnitrack-view completions SHELL
//! omnitrack-view manpage [--dir DIR]
//! ```
//!
//! `serve` says where to connect on standard error at start and prints a summary line at the
//! end. Errors are one line on standard error and exit code 1; usage errors are one line too
//! and exit 2.

use clap::{Parser, Subcommand};
use omnitrack_view::images::ImageOptions;
use omnitrack_view::{run, stop_on_signals, Options, ViewError, DEFAULT_PORT};
use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// `serve --ready`'s line on standard output.
const READY: &str = "ready";

#[derive(Parser)]
#[command(
    name = "omnitrack-view",
    version,
    about = "The tracker's poses, status, model and images live in Foxglove, and in an MCAP file"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

fn seconds(s: &str) -> Result<Duration, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=3600.0).contains(&v) => Ok(Duration::from_secs_f64(v)),
        _ => Err(format!("'{s}' is not a number of seconds from 0 to 3600")),
    }
}

fn quality(s: &str) -> Result<u8, String> {
    match s.parse::<u8>() {
        Ok(q) if (1..=100).contains(&q) => Ok(q),
        _ => Err(format!("'{s}' is not a JPEG quality (1 to 100)")),
    }
}

fn prefix(s: &str) -> Result<String, String> {
    if s.is_empty() || s.contains(char::is_whitespace) || s.ends_with('/') {
        Err(format!(
            "'{s}' is not a service prefix (non-empty, no spaces, no trailing '/')"
        ))
    } else {
        Ok(s.to_string())
    }
}

#[derive(Subcommand)]
enum Command {
    /// Views the tracker's services until stopped: a Foxglove WebSocket server (Foxglove: Open
    /// connection → Foxglove WebSocket → ws://HOST:PORT) and, with --mcap, an MCAP file.
    Serve {
        /// The tracker's services: PREFIX/pose and PREFIX/status (`omnitrack run --services`).
        #[arg(long, value_name = "PREFIX", default_value = "omnitrack", value_parser = prefix)]
        services: String,
        /// The address to listen on (0.0.0.0: every interface, for a viewer on another host).
        #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
        bind: IpAddr,
        /// The port to listen on (0: any free port, printed at start).
        #[arg(long, default_value_t = DEFAULT_PORT)]
        port: u16,
        /// No WebSocket server: write the MCAP file only.
        #[arg(long, requires = "mcap")]
        no_server: bool,
        /// Writes every channel to this MCAP file (replaced if it exists).
        #[arg(long, value_name = "FILE.mcap")]
        mcap: Option<PathBuf>,
        /// The building model, drawn under the trajectory and re-projected into the images.
        #[arg(long, value_name = "MODEL.obj")]
        model: Option<PathBuf>,
        /// The recording the tracker replays (its source `replay:DIR`): its images go out with
        /// the re-projected model and the detected edges.
        #[arg(long, value_name = "DIR")]
        recording: Option<PathBuf>,
        /// At most one set of images per this many seconds of the recording.
        #[arg(long = "images-every-s", value_name = "S", default_value = "0.5", value_parser = seconds)]
        images_every: Duration,
        /// Leaves the detected edges out of the images' annotations.
        #[arg(long)]
        no_edges: bool,
        /// JPEG quality of the images.
        #[arg(long, default_value = "80", value_parser = quality)]
        jpeg_quality: u8,
        /// Stops after this many pose samples.
        #[arg(long)]
        count: Option<u64>,
        /// For a parent process that starts the view and then publishes (`omnitrack run
        /// --mcap`): prints `ready` on standard output once subscribed (and the file created),
        /// so that no sample comes before the view listens, and stops when standard input
        /// closes (the parent stops it, or ended however abruptly), and only then: SIGINT and
        /// SIGTERM are ignored, as they may be meant for the parent (systemd's stop reaches every
        /// process of the service), which still has samples to publish.
        #[arg(long)]
        ready: bool,
    },
    /// Prints a shell completion script for omnitrack-view (bash, zsh, fish, elvish or powershell).
    Completions {
        /// The shell.
        shell: omnitrack_manual::Shell,
    },
    /// Prints omnitrack-view's manual page (roff), or writes it and a page per command into a
    /// directory.
    Manpage(omnitrack_manual::ManpageArgs),
}

#[derive(Debug, thiserror::Error)]
enum MainError {
    #[error("{0}")]
    View(#[from] ViewError),
    #[error("cannot write: {0}")]
    Output(#[from] std::io::Error),
}

fn run_cli(cli: Cli) -> Result<(), MainError> {
    match cli.command {
        Command::Serve {
            services,
            bind,
            port,
            no_server,
            mcap,
            model,
            recording,
            images_every,
            no_edges,
            jpeg_quality,
            count,
            ready,
        } => {
            let options = Options {
                pose_service: format!("{services}/pose"),
                status_service: format!("{services}/status"),
                listen: (!no_server).then_some(SocketAddr::new(bind, port)),
                mcap,
                model,
                images: recording.map(|recording| ImageOptions {
                    recording,
                    every: images_every,
                    edges: !no_edges,
                    quality: jpeg_quality,
                }),
                count,
            };
            let stop = if ready {
                let stop = Arc::new(AtomicBool::new(false));
                ignore_stop_signals();
                stop_at_end_of_input(&stop);
                stop
            } else {
                stop_on_signals()
            };
            let s = run(&options, &stop, &mut |addr| {
                let server = addr.map_or("no server".to_string(), |a| {
                    format!("ws://{a} (Foxglove: Open connection → Foxglove WebSocket)")
                });
                let file = options
                    .mcap
                    .as_ref()
                    .map_or(String::new(), |p| format!(", MCAP file {}", p.display()));
                eprintln!("omnitrack-view: {} → {server}{file}", options.pose_service);
                if ready {
                    // A parent that is gone cannot be told; the view goes on either way.
                    let mut stdout = std::io::stdout().lock();
                    let _ = writeln!(stdout, "{READY}").and_then(|_| stdout.flush());
                }
            })?;
            eprintln!(
                "omnitrack-view: {} poses ({} tracking, {} missed), {} statuses, {} image sets; \
                 {} messages to the MCAP file{}; {} to viewers, {} lost by slow viewers, {} viewers refused",
                s.poses,
                s.tracking,
                s.poses_missed,
                s.statuses,
                s.image_sets,
                s.mcap_messages,
                s.mcap_error.map_or(String::new(), |e| format!(" (stopped early: {e})")),
                s.ws_sent,
                s.ws_dropped,
                s.ws_refused
            );
        }
        Command::Completions { shell } => omnitrack_manual::run_completions(&manual(), shell)?,
        Command::Manpage(args) => omnitrack_manual::run_manpage(&manual(), &args)?,
    }
    Ok(())
}

/// SIGINT and SIGTERM do nothing but interrupt a wait (which the loop takes as no sample): a
/// view started by a parent ends when the parent says so, after its last sample. A handler
/// that sets a flag nobody reads, rather than `SIG_IGN`, needs no `unsafe`.
fn ignore_stop_signals() {
    let ignored = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        let _ = signal_hook::flag::register(signal, Arc::clone(&ignored));
    }
}

/// Sets `stop` when standard input reaches its end or fails: a parent that holds the other end
/// of the pipe and dies (even by SIGKILL) closes it, and the view finishes its file instead of
/// waiting for samples that will not come.
fn stop_at_end_of_input(stop: &Arc<AtomicBool>) {
    let stop = Arc::clone(stop);
    std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        let mut input = std::io::stdin().lock();
        while matches!(input.read(&mut buf), Ok(n) if n > 0) {}
        stop.store(true, Ordering::Relaxed);
    });
}

fn manual() -> omnitrack_manual::Manual {
    omnitrack_manual::Manual::new(<Cli as clap::CommandFactory>::command())
}

fn main() {
    match run_cli(omnitrack_runtime::cli::parse_or_exit::<Cli>(
        "omnitrack-view",
        "omnitrack-view serve",
    )) {
        Ok(()) => {}
        Err(MainError::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        Err(e) => {
            eprintln!("omnitrack-view: {e}");
            std::process::exit(1);
        }
    }
}
