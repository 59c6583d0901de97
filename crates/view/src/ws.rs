//! The live view's server: the Foxglove WebSocket protocol (`foxglove.websocket.v1`), which
//! Foxglove (desktop or browser, "Open connection" → Foxglove WebSocket) and its client
//! libraries speak.
//!
//! In: the channel table and messages by channel index ([`Server::send`]), from the view's loop.
//! Out: to every connected client, `serverInfo` and the `advertise` of every channel on connect,
//! then a binary message frame (opcode 1, subscription id u32 LE, log time u64 LE ns, the JSON
//! payload) for every message of a channel it subscribed to. A subscription first gets what the
//! channel keeps ([`Keep`]): the model at once, the trajectory so far, the latest pose.
//!
//! Each client has a thread of its own and a bounded queue: [`Server::send`] never blocks and
//! never waits for a client. A client that cannot keep up loses messages (counted), never slows
//! the others or the view's loop; one that sends nothing we understand gets a `status` line.

use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use serde_json::{json, Value};
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};

use crate::schemas::Channel;

/// The subprotocol Foxglove asks for.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Clients served at once; more are refused.
pub const MAX_CLIENTS: usize = 8;
/// Messages queued per client before the newest are dropped (≈ 2 s of poses at 30 Hz with
/// their transform, sample and ellipsoid).
pub const CLIENT_QUEUE: usize = 256;
/// Bytes a client's socket may hold unsent before messages to it are dropped.
const MAX_UNSENT_BYTES: usize = 8 << 20;

/// What a channel keeps for a client that subscribes later.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Keep {
    /// The latest message (a pose, the model).
    Last,
    /// Every message (the trajectory's pieces: together they are the trajectory).
    All,
}

/// A server that cannot start: one line.
#[derive(Debug, thiserror::Error)]
#[error("{addr}: cannot listen for the live view: {detail}")]
pub struct ServerError {
    pub addr: SocketAddr,
    pub detail: String,
}

#[derive(Debug)]
struct Outgoing {
    /// Order of sending: a subscriber that got a kept message skips it in its queue.
    serial: u64,
    channel: usize,
    log_time_ns: u64,
    data: Arc<[u8]>,
}

struct Shared {
    channels: Vec<Channel>,
    keep: Vec<Keep>,
    kept: Mutex<Vec<Vec<Arc<Outgoing>>>>,
    stop: AtomicBool,
    serial: AtomicU64,
    dropped: AtomicU64,
    sent: AtomicU64,
}

struct Client {
    queue: SyncSender<Arc<Outgoing>>,
    thread: JoinHandle<()>,
}

/// The Foxglove WebSocket server of the view.
pub struct Server {
    listener: TcpListener,
    addr: SocketAddr,
    shared: Arc<Shared>,
    clients: Vec<Client>,
    refused: u64,
}

impl Server {
    /// Listens on `addr` (port 0: any free port) and serves `channels`, each keeping for late
    /// subscribers what `keep` says (by index; [`Keep::Last`] where it says nothing).
    pub fn bind(addr: SocketAddr, channels: Vec<Channel>, keep: &[Keep]) -> Result<Server, ServerError> {
        let err = |e: std::io::Error| {
            let hint = match e.kind() {
                ErrorKind::AddrInUse => " (another program has the port: choose another with --port)",
                ErrorKind::AddrNotAvailable => " (no interface of this computer has that address)",
                ErrorKind::PermissionDenied => " (a port below 1024 needs privileges)",
                _ => "",
            };
            ServerError {
                addr,
                detail: format!("{e}{hint}"),
            }
        };
        let listener = TcpListener::bind(addr).map_err(err)?;
        listener.set_nonblocking(true).map_err(err)?;
        let addr = listener.local_addr().map_err(err)?;
        let keep = (0..channels.len())
            .map(|i| keep.get(i).copied().unwrap_or(Keep::Last))
            .collect();
        Ok(Server {
            listener,
            addr,
            shared: Arc::new(Shared {
                kept: Mutex::new(vec![Vec::new(); channels.len()]),
                channels,
                keep,
                stop: AtomicBool::new(false),
                serial: AtomicU64::new(0),
                dropped: AtomicU64::new(0),
                sent: AtomicU64::new(0),
            }),
            clients: Vec::new(),
            refused: 0,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Takes the connections that are waiting (never blocks): each gets a thread that does the
    /// WebSocket handshake and serves it.
    pub fn accept(&mut self) {
        self.clients.retain(|c| !c.thread.is_finished());
        while let Ok((stream, _)) = self.listener.accept() {
            if self.clients.len() >= MAX_CLIENTS {
                self.refused += 1;
                drop(stream);
                continue;
            }
            let (queue, rx) = sync_channel(CLIENT_QUEUE);
            let shared = Arc::clone(&self.shared);
            let thread = std::thread::Builder::new()
                .name("view-client".into())
                .spawn(move || serve_client(stream, rx, &shared));
            match thread {
                Ok(thread) => self.clients.push(Client { queue, thread }),
                Err(_) => self.refused += 1,
            }
        }
    }

    /// Sends a message of channel `channel` to the clients subscribed to it, and keeps it for
    /// later subscribers. Never blocks: a client whose queue is full loses it (counted).
    pub fn send(&mut self, channel: usize, log_time_ns: u64, data: &[u8]) {
        if channel >= self.shared.channels.len() {
            return;
        }
        let message = Arc::new(Outgoing {
            serial: self.shared.serial.fetch_add(1, Ordering::Relaxed) + 1,
            channel,
            log_time_ns,
            data: data.into(),
        });
        if let Ok(mut kept) = self.shared.kept.lock() {
            let k = &mut kept[channel];
            if self.shared.keep[channel] == Keep::Last {
                k.clear();
            }
            k.push(Arc::clone(&message));
        }
        self.clients.retain(|c| match c.queue.try_send(Arc::clone(&message)) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Disconnected(_)) => false,
        });
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.clients.iter().filter(|c| !c.thread.is_finished()).count()
    }

    /// Messages sent to clients, messages a slow client lost, connections refused (too many).
    pub fn counts(&self) -> (u64, u64, u64) {
        (
            self.shared.sent.load(Ordering::Relaxed),
            self.shared.dropped.load(Ordering::Relaxed),
            self.refused,
        )
    }

    /// Closes every connection and waits for the clients' threads.
    pub fn close(mut self) -> (u64, u64, u64) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for c in self.clients.drain(..) {
            drop(c.queue);
            let _ = c.thread.join();
        }
        self.counts()
    }
}

/// The handshake's answer: Foxglove's subprotocol when the client offers it (a browser refuses
/// a connection whose answer leaves it out).
#[allow(clippy::result_large_err)] // tungstenite's callback signature
fn choose_subprotocol(request: &Request, mut response: Response) -> Result<Response, ErrorResponse> {
    let offered = request
        .headers()
        .get_all("Sec-WebSocket-Protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if offered {
        response.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            SUBPROTOCOL.parse().expect("a valid header value"),
        );
    }
    Ok(response)
}

fn serve_client(stream: TcpStream, rx: Receiver<Arc<Outgoing>>, shared: &Shared) {
    // The handshake blocks this thread only, and not for long: a client that says nothing for
    // two seconds is dropped.
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_read_timeout(Some(Duration::from_secs(2)));
    let _ = stream.set_nodelay(true);
    let config = WebSocketConfig::default().max_write_buffer_size(MAX_UNSENT_BYTES);
    let Ok(mut ws) = tungstenite::accept_hdr_with_config(stream, choose_subprotocol, Some(config)) else {
        return;
    };
    if ws.get_mut().set_nonblocking(true).is_err() {
        return;
    }
    // (subscription id, channel index, serial of the last message it got from what was kept)
    let mut subscriptions: Vec<(u32, usize, u64)> = Vec::new();
    let hello = [server_info(), advertise(&shared.channels)];
    for h in hello {
        if ws.write(Message::text(h.to_string())).is_err() {
            return;
        }
    }
    loop {
        if shared.stop.load(Ordering::Relaxed) {
            let _ = ws.close(None);
            let _ = ws.flush();
            return;
        }
        // Outgoing first: wait briefly for a message, then take what else is queued.
        let mut next = match rx.recv_timeout(Duration::from_millis(10)) {
            Ok(m) => Some(m),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => {
                let _ = ws.close(None);
                let _ = ws.flush();
                return;
            }
        };
        while let Some(m) = next {
            let to = subscriptions
                .iter()
                .filter(|(_, c, since)| *c == m.channel && m.serial > *since);
            for &(id, _, _) in to {
                if !write_message(&mut ws, id, &m, shared) {
                    return;
                }
            }
            next = rx.try_recv().ok();
        }
        match ws.flush() {
            Ok(()) => {}
            Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::WouldBlock => {}
            Err(_) => return,
        }
        // Then what the client says (non-blocking: WouldBlock when it said nothing).
        loop {
            match ws.read() {
                Ok(Message::Text(text)) => {
                    for (id, channel) in handle_request(&text, &mut subscriptions, shared, &mut ws) {
                        let kept: Vec<Arc<Outgoing>> =
                            shared.kept.lock().map(|k| k[channel].clone()).unwrap_or_default();
                        for m in &kept {
                            if !write_message(&mut ws, id, m, shared) {
                                return;
                            }
                        }
                        if let (Some(last), Some(s)) = (kept.last(), subscriptions.iter_mut().find(|s| s.0 == id)) {
                            s.2 = last.serial;
                        }
                    }
                }
                Ok(Message::Close(_)) => {
                    let _ = ws.flush();
                    return;
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::WouldBlock => break,
                Err(_) => return,
            }
        }
    }
}

/// Queues one message frame; false when the connection is gone. A full socket buffer drops
/// the message (counted) and keeps the connection.
fn write_message(ws: &mut WebSocket<TcpStream>, subscription: u32, m: &Outgoing, shared: &Shared) -> bool {
    match ws.write(Message::binary(message_frame(subscription, m.log_time_ns, &m.data))) {
        Ok(()) => {
            shared.sent.fetch_add(1, Ordering::Relaxed);
            true
        }
        Err(tungstenite::Error::WriteBufferFull(_)) => {
            shared.dropped.fetch_add(1, Ordering::Relaxed);
            true
        }
        Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::WouldBlock => {
            // Queued in tungstenite's buffer; the next flush sends it.
            shared.sent.fetch_add(1, Ordering::Relaxed);
            true
        }
        Err(_) => false,
    }
}

/// A binary message frame of the protocol.
pub fn message_frame(subscription: u32, log_time_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(13 + payload.len());
    f.push(1);
    f.extend_from_slice(&subscription.to_le_bytes());
    f.extend_from_slice(&log_time_ns.to_le_bytes());
    f.extend_from_slice(payload);
    f
}

fn server_info() -> Value {
    json!({
        "op": "serverInfo",
        "name": concat!("omnitrack-view ", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "supportedEncodings": [],
        "metadata": {},
        "sessionId": format!("{}", std::process::id()),
    })
}

/// The `advertise` of the table: channel ids are the table's indices plus one.
fn advertise(channels: &[Channel]) -> Value {
    let list: Vec<Value> = channels
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "id": i + 1, "topic": c.topic, "encoding": "json", "schemaName": c.schema_name,
                "schema": c.schema, "schemaEncoding": "jsonschema",
            })
        })
        .collect();
    json!({"op": "advertise", "channels": list})
}

/// Applies a client's `subscribe` / `unsubscribe`; returns the new subscriptions (id, channel
/// index), which get what their channels keep. Anything else gets a `status` warning.
fn handle_request(
    text: &str,
    subscriptions: &mut Vec<(u32, usize, u64)>,
    shared: &Shared,
    ws: &mut WebSocket<TcpStream>,
) -> Vec<(u32, usize)> {
    let mut added = Vec::new();
    let mut warn = |message: String| {
        let status = json!({"op": "status", "level": 1, "message": message});
        let _ = ws.write(Message::text(status.to_string()));
    };
    let Ok(v) = serde_json::from_str::<Value>(text) else {
        warn("not JSON".into());
        return added;
    };
    match v["op"].as_str() {
        Some("subscribe") => {
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                let (Some(id), Some(channel)) = (s["id"].as_u64(), s["channelId"].as_u64()) else {
                    warn(format!("a subscription without id and channelId: {s}"));
                    continue;
                };
                let index = (channel as usize).wrapping_sub(1);
                match u32::try_from(id) {
                    Ok(id) if index < shared.channels.len() && !subscriptions.iter().any(|s| s.0 == id) => {
                        subscriptions.push((id, index, 0));
                        added.push((id, index));
                    }
                    _ => warn(format!("cannot subscribe {id} to channel {channel}")),
                }
            }
        }
        Some("unsubscribe") => {
            for id in v["subscriptionIds"].as_array().into_iter().flatten() {
                subscriptions.retain(|s| Some(u64::from(s.0)) != id.as_u64());
            }
        }
        Some(op) => warn(format!("'{op}' is not supported by this server")),
        None => warn("a request without 'op'".into()),
    }
    added
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schemas::channels;
    use std::time::Instant;
    use tungstenite::client::IntoClientRequest;

    type Client = WebSocket<TcpStream>;

    /// A client, once the server took its connection (the server's handshake is on its
    /// client's thread).
    fn connect(server: &mut Server) -> Client {
        let addr = server.addr();
        let request = format!("ws://{addr}").into_client_request().unwrap();
        let stream = TcpStream::connect(addr).unwrap();
        let deadline = Instant::now() + Duration::from_secs(5);
        let before = server.clients();
        while server.clients() == before && Instant::now() < deadline {
            server.accept();
            std::thread::sleep(Duration::from_millis(5));
        }
        stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let (mut ws, _) = tungstenite::client(request, stream).unwrap();
        ws.get_mut().set_read_timeout(Some(Duration::from_millis(100))).unwrap();
        for op in ["serverInfo", "advertise"] {
            assert_eq!(text(&mut ws)["op"], op);
        }
        ws
    }

    fn text(ws: &mut Client) -> Value {
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match ws.read() {
                Ok(Message::Text(t)) => return serde_json::from_str(t.as_str()).unwrap(),
                Ok(m) => panic!("expected text, got {m:?}"),
                Err(_) if Instant::now() < deadline => {}
                Err(e) => panic!("{e}"),
            }
        }
    }

    /// Message frames (subscription, time, payload) until `n` came or a second passed.
    fn frames(ws: &mut Client, server: &mut Server, n: usize) -> Vec<(u32, u64, String)> {
        let mut got = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(1);
        while got.len() < n && Instant::now() < deadline {
            server.accept();
            if let Ok(Message::Binary(b)) = ws.read() {
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                got.push((sub, t, String::from_utf8(b[13..].to_vec()).unwrap()));
            }
        }
        got
    }

    fn subscribe(ws: &mut Client, id: u32, channel_index: usize) {
        let s = json!({"op": "subscribe", "subscriptions": [{"id": id, "channelId": channel_index + 1}]});
        ws.send(Message::text(s.to_string())).unwrap();
    }

    fn server() -> Server {
        let mut keep = vec![Keep::Last; channels(0).len()];
        keep[1] = Keep::All;
        Server::bind("127.0.0.1:0".parse().unwrap(), channels(0), &keep).unwrap()
    }

    #[test]
    fn a_late_subscriber_gets_what_its_channel_keeps_once_then_what_follows() {
        let mut server = server();
        let mut ws = connect(&mut server);
        // Before anyone subscribes: channel 0 keeps its last, channel 1 all.
        server.send(0, 1, b"{\"a\":1}");
        server.send(0, 2, b"{\"a\":2}");
        server.send(1, 3, b"{\"b\":1}");
        server.send(1, 4, b"{\"b\":2}");
        subscribe(&mut ws, 7, 0);
        subscribe(&mut ws, 9, 1);
        let kept = frames(&mut ws, &mut server, 3);
        assert_eq!(
            kept,
            [
                (7, 2, "{\"a\":2}".to_string()),
                (9, 3, "{\"b\":1}".to_string()),
                (9, 4, "{\"b\":2}".to_string())
            ]
        );
        server.send(0, 5, b"{\"a\":3}");
        server.send(2, 6, b"{}");
        let next = frames(&mut ws, &mut server, 2);
        assert_eq!(
            next,
            [(7, 5, "{\"a\":3}".to_string())],
            "nothing of channel 2, nothing twice"
        );
        ws.send(Message::text(
            json!({"op": "unsubscribe", "subscriptionIds": [7]}).to_string(),
        ))
        .unwrap();
        std::thread::sleep(Duration::from_millis(100));
        server.send(0, 8, b"{\"a\":4}");
        assert!(frames(&mut ws, &mut server, 1).is_empty(), "unsubscribed");
        assert_eq!(server.close().1, 0, "nothing dropped");
    }

    #[test]
    fn requests_it_does_not_understand_get_a_warning_and_the_connection_stays() {
        let mut server = server();
        let mut ws = connect(&mut server);
        for (request, says) in [
            ("not json", "not JSON"),
            ("{\"op\":\"advertise\"}", "'advertise' is not supported"),
            (
                "{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":1,\"channelId\":999}]}",
                "cannot subscribe 1 to channel 999",
            ),
        ] {
            ws.send(Message::text(request)).unwrap();
            let status = text(&mut ws);
            assert_eq!(
                (status["op"].as_str(), status["level"].as_u64()),
                (Some("status"), Some(1))
            );
            assert!(status["message"].as_str().unwrap().contains(says), "{status}");
        }
        subscribe(&mut ws, 1, 0);
        std::thread::sleep(Duration::from_millis(100));
        server.send(0, 1, b"{}");
        assert_eq!(frames(&mut ws, &mut server, 1).len(), 1);
    }

    #[test]
    fn a_client_that_reads_nothing_never_holds_up_the_sender_or_the_others() {
        let mut server = server();
        // Subscribed, then never reads: its socket and queue fill.
        let mut stalled = connect(&mut server);
        subscribe(&mut stalled, 1, 0);
        let mut reader = connect(&mut server);
        subscribe(&mut reader, 1, 0);
        std::thread::sleep(Duration::from_millis(200));
        let payload = vec![b'x'; 64 << 10];
        let started = Instant::now();
        for t in 0..2_000 {
            server.send(0, t, &payload);
            if t % 50 == 0 {
                let _ = frames(&mut reader, &mut server, 1);
            }
        }
        assert!(started.elapsed() < Duration::from_secs(30), "{:?}", started.elapsed());
        let (_, dropped, _) = server.counts();
        assert!(
            dropped > 0,
            "128 MB to a client that reads nothing: some must be dropped"
        );
        let _ = frames(&mut reader, &mut server, 1);
        drop(stalled);
    }

    #[test]
    fn more_clients_than_it_serves_are_refused_and_a_port_in_use_is_named() {
        let mut server = server();
        let addr = server.addr();
        let clients: Vec<Client> = (0..MAX_CLIENTS).map(|_| connect(&mut server)).collect();
        let extra = TcpStream::connect(addr).unwrap();
        std::thread::sleep(Duration::from_millis(50));
        server.accept();
        assert_eq!(server.counts().2, 1);
        assert_eq!(server.clients(), MAX_CLIENTS);
        drop((clients, extra));
        let e = Server::bind(addr, channels(0), &[]).err().unwrap().to_string();
        assert!(
            e.starts_with(&addr.to_string()) && e.contains("choose another with --port"),
            "{e}"
        );
    }
}
