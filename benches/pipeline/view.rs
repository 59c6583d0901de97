//! The live view beside a run of the bench (`--view`): `omnitrack-view`'s loop on a thread of
//! this process, subscribed to the run's services, writing an MCAP file and serving a Foxglove
//! WebSocket client (also here) subscribed to every channel, with the recording's images, the
//! re-projected model and the detected edges every half second: everything a user watching
//! the run would make the computer do, on the same two cores as the frame path.
//!
//! In: the run's service prefix and its recording. Out: the view's summary and the messages the
//! client received, once the run is over.

use omnitrack_view::images::ImageOptions;
use omnitrack_view::{Options, Summary};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;
use tungstenite::Message;

pub(crate) struct View {
    stop: Arc<AtomicBool>,
    view: JoinHandle<Summary>,
    client: JoinHandle<u64>,
    mcap: PathBuf,
}

/// Starts the view on `prefix`'s services and its client; returns once both are connected.
pub(crate) fn start(prefix: &str, rec: &Path) -> View {
    let mcap = std::env::temp_dir().join(format!("omnitrack-bench-view-{}.mcap", std::process::id()));
    let options = Options {
        pose_service: format!("{prefix}/pose"),
        status_service: format!("{prefix}/status"),
        listen: Some("127.0.0.1:0".parse().unwrap()),
        mcap: Some(mcap.clone()),
        model: Some(rec.join("model.obj")),
        images: Some(ImageOptions {
            recording: rec.to_path_buf(),
            every: Duration::from_millis(500),
            edges: true,
            quality: 80,
        }),
        count: None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel();
    let view = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || omnitrack_view::run(&options, &stop, &mut |a| tx.send(a.unwrap()).unwrap()).unwrap())
    };
    let addr = rx.recv().unwrap();
    let (ready_tx, ready) = mpsc::channel();
    let client = std::thread::spawn(move || {
        let stream = TcpStream::connect(addr).unwrap();
        let (mut ws, _) = tungstenite::client(format!("ws://{addr}"), stream).unwrap();
        let mut received = 0u64;
        while let Ok(m) = ws.read() {
            match m {
                Message::Text(t) => {
                    let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                    if v["op"] == "advertise" {
                        let subs: Vec<_> = v["channels"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|c| serde_json::json!({"id": c["id"], "channelId": c["id"]}))
                            .collect();
                        let s = serde_json::json!({"op": "subscribe", "subscriptions": subs});
                        ws.send(Message::text(s.to_string())).unwrap();
                        let _ = ready_tx.send(());
                    }
                }
                Message::Binary(_) => received += 1,
                _ => {}
            }
        }
        received
    });
    ready.recv().unwrap();
    View {
        stop,
        view,
        client,
        mcap,
    }
}

impl View {
    /// Stops the view (after the run); its summary and the client's message count.
    pub(crate) fn finish(self) -> (Summary, u64) {
        self.stop.store(true, Ordering::Relaxed);
        let summary = self.view.join().unwrap();
        let received = self.client.join().unwrap();
        let _ = std::fs::remove_file(&self.mcap);
        (summary, received)
    }
}
