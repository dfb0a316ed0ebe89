//! A server of Foxglove's WebSocket protocol (`foxglove.websocket.v1`): what Foxglove, Lichtblick
//! and `@foxglove/ws-protocol`'s client connect to.
//!
//! What it does of the protocol: `serverInfo` (capabilities `time`, and `playbackControl` with
//! the data's time range when the source can seek), `advertise` of every channel at connection,
//! `subscribe` and `unsubscribe`, message data (binary op 1), the server's time (binary op 2),
//! playback state (binary op 5) and the client's playback control requests (binary op 3). The
//! opcodes and layouts are those of Foxglove's SDK (`foxglove::protocol::v1`, MIT).
//!
//! Each client has its own thread and its own bounded outbox: a client that falls behind loses
//! its oldest messages, counted per client, and never holds whoever publishes (publishing only
//! queues). Our own code rather than the `foxglove` crate's server, because that server drops a
//! slow client's messages without counting them.

use anyhow::{Context, Result};
use std::collections::VecDeque;
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tungstenite::Message;
use tungstenite::handshake::server::{ErrorResponse, Request, Response};

/// The protocol's WebSocket subprotocol.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// One channel the server advertises.
#[derive(Debug, Clone)]
pub struct ChannelSpec {
    /// Its topic (`/nav/location`).
    pub topic: &'static str,
    /// Its schema's name (`foxglove.LocationFix`).
    pub schema_name: &'static str,
    /// The schema's text (a JSON schema).
    pub schema: &'static str,
}

/// A playback control request from a client (pause, play, seek).
#[derive(Debug, Clone, PartialEq)]
pub struct Control {
    /// Play (`false`: pause).
    pub play: bool,
    /// The speed asked for, a factor of real time.
    pub speed: f32,
    /// Seek to this time, ns, when asked.
    pub seek_ns: Option<u64>,
    /// The request's id, echoed in the playback state that answers it.
    pub request_id: String,
}

/// Playback status (the protocol's `PlaybackStatus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Playback {
    /// Playing.
    Playing = 0,
    /// Paused.
    Paused = 1,
    /// Not yet playing.
    Buffering = 2,
    /// At the end of the data.
    Ended = 3,
}

/// How one client fared.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct ClientStats {
    /// Its address.
    pub peer: String,
    /// Subscriptions it made.
    pub subscriptions: u64,
    /// Messages sent to it (data, time, state).
    pub sent: u64,
    /// Messages it lost because it fell behind (its outbox was full): the oldest go first.
    pub dropped: u64,
    /// Bytes sent to it.
    pub bytes: u64,
    /// Playback requests it made.
    pub controls: u64,
}

/// What the server did.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct ServerStats {
    /// The address it listened on.
    pub addr: String,
    /// Messages published (each counted once, however many clients took it).
    pub published: u64,
    /// Every client that connected, in order.
    pub clients: Vec<ClientStats>,
}

struct Client {
    peer: SocketAddr,
    outbox: Mutex<VecDeque<Message>>,
    /// Subscription id per channel (index), when subscribed.
    subs: Mutex<Vec<Option<u32>>>,
    subscriptions: AtomicU64,
    sent: AtomicU64,
    dropped: AtomicU64,
    bytes: AtomicU64,
    controls: AtomicU64,
    gone: AtomicBool,
}

impl Client {
    fn push(&self, m: Message, cap: usize) {
        let Ok(mut q) = self.outbox.lock() else {
            return;
        };
        if q.len() >= cap {
            q.pop_front();
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        q.push_back(m);
    }

    fn stats(&self) -> ClientStats {
        ClientStats {
            peer: self.peer.to_string(),
            subscriptions: self.subscriptions.load(Ordering::Relaxed),
            sent: self.sent.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
            bytes: self.bytes.load(Ordering::Relaxed),
            controls: self.controls.load(Ordering::Relaxed),
        }
    }

    fn subscribed(&self, channels: usize) -> bool {
        self.subs
            .lock()
            .map(|s| s.iter().take(channels).all(Option::is_some))
            .unwrap_or(false)
    }
}

struct Shared {
    channels: Vec<ChannelSpec>,
    info: String,
    advertise: String,
    clients: Mutex<Vec<Arc<Client>>>,
    backlog: usize,
    closing: AtomicBool,
    published: AtomicU64,
    controls: Mutex<Option<mpsc::Sender<Control>>>,
}

/// A running server.
pub struct Server {
    shared: Arc<Shared>,
    addr: SocketAddr,
    accept: Option<JoinHandle<()>>,
    threads: Arc<Mutex<Vec<JoinHandle<()>>>>,
}

/// Options of a server.
#[derive(Debug, Clone)]
pub struct Options {
    /// The name it gives clients.
    pub name: String,
    /// Playback control over this data range (ns), when the source can pause and seek.
    pub playback: Option<(u64, u64)>,
    /// Messages each client's outbox holds before the oldest go.
    pub backlog: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            name: "rlg-hil".into(),
            playback: None,
            backlog: 4096,
        }
    }
}

impl Server {
    /// Listen on `addr` and advertise `channels` to every client.
    pub fn start(addr: SocketAddr, channels: Vec<ChannelSpec>, opts: Options) -> Result<Self> {
        let listener = TcpListener::bind(addr)
            .with_context(|| format!("live view: listening on {addr} (is it in use?)"))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let mut caps = vec!["time"];
        let mut info = serde_json::json!({
            "op": "serverInfo",
            "name": opts.name,
            "capabilities": [],
            "supportedEncodings": [],
            "metadata": {"time": "simulated (the IMU sample counter's time base)"},
            "sessionId": format!("{}-{}", std::process::id(), now_ns()),
        });
        if let Some((a, b)) = opts.playback {
            caps.push("playbackControl");
            info["dataStartTime"] = time_json(a);
            info["dataEndTime"] = time_json(b);
        }
        info["capabilities"] = serde_json::json!(caps);
        let advertise = serde_json::json!({
            "op": "advertise",
            "channels": channels.iter().enumerate().map(|(i, c)| serde_json::json!({
                "id": i + 1,
                "topic": c.topic,
                "encoding": "json",
                "schemaName": c.schema_name,
                "schema": c.schema,
                "schemaEncoding": "jsonschema",
            })).collect::<Vec<_>>(),
        });
        let shared = Arc::new(Shared {
            channels,
            info: info.to_string(),
            advertise: advertise.to_string(),
            clients: Mutex::new(Vec::new()),
            backlog: opts.backlog.max(16),
            closing: AtomicBool::new(false),
            published: AtomicU64::new(0),
            controls: Mutex::new(None),
        });
        let threads: Arc<Mutex<Vec<JoinHandle<()>>>> = Arc::default();
        let accept = {
            let (shared, threads) = (shared.clone(), threads.clone());
            std::thread::Builder::new()
                .name("live-accept".into())
                .spawn(move || accept_loop(listener, shared, threads))
                .context("live view: starting the server")?
        };
        Ok(Self {
            shared,
            addr,
            accept: Some(accept),
            threads,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Playback control requests go to `tx`.
    pub fn on_control(&self, tx: mpsc::Sender<Control>) {
        if let Ok(mut c) = self.shared.controls.lock() {
            *c = Some(tx);
        }
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.live_clients().len()
    }

    fn live_clients(&self) -> Vec<Arc<Client>> {
        self.shared
            .clients
            .lock()
            .map(|c| {
                c.iter()
                    .filter(|c| !c.gone.load(Ordering::Relaxed))
                    .cloned()
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Wait (at most `limit`) until `n` clients have subscribed to every channel; whether they
    /// have.
    pub fn wait_for_subscribers(&self, n: usize, limit: Duration) -> bool {
        let until = Instant::now() + limit;
        loop {
            let ready = self
                .live_clients()
                .iter()
                .filter(|c| c.subscribed(self.shared.channels.len()))
                .count();
            if ready >= n {
                return true;
            }
            if Instant::now() > until {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Publish `payload` on channel `ch` (its index in the list given to [`Server::start`]) at
    /// time `t_ns`, to every client subscribed to it.
    pub fn publish(&self, ch: usize, t_ns: u64, payload: &[u8]) {
        self.shared.published.fetch_add(1, Ordering::Relaxed);
        for c in self.live_clients() {
            let sub = c
                .subs
                .lock()
                .ok()
                .and_then(|s| s.get(ch).copied().flatten());
            if let Some(sub) = sub {
                let mut b = Vec::with_capacity(13 + payload.len());
                b.push(1u8);
                b.extend_from_slice(&sub.to_le_bytes());
                b.extend_from_slice(&t_ns.to_le_bytes());
                b.extend_from_slice(payload);
                c.push(Message::Binary(b.into()), self.shared.backlog);
            }
        }
    }

    /// The server's time (the Time capability): every client.
    pub fn time(&self, t_ns: u64) {
        let mut b = Vec::with_capacity(9);
        b.push(2u8);
        b.extend_from_slice(&t_ns.to_le_bytes());
        for c in self.live_clients() {
            c.push(Message::Binary(b.clone().into()), self.shared.backlog);
        }
    }

    /// The playback state (answering `request_id`, when given): to the clients that have asked
    /// for playback (others may not know the message).
    pub fn playback_state(
        &self,
        status: Playback,
        t_ns: u64,
        speed: f32,
        did_seek: bool,
        request_id: Option<&str>,
    ) {
        let id = request_id.unwrap_or("").as_bytes();
        let mut b = Vec::with_capacity(18 + id.len());
        b.push(5u8);
        b.push(status as u8);
        b.extend_from_slice(&t_ns.to_le_bytes());
        b.extend_from_slice(&speed.to_le_bytes());
        b.push(u8::from(did_seek));
        b.extend_from_slice(&(id.len() as u32).to_le_bytes());
        b.extend_from_slice(id);
        for c in self.live_clients() {
            if c.controls.load(Ordering::Relaxed) > 0 {
                c.push(Message::Binary(b.clone().into()), self.shared.backlog);
            }
        }
    }

    /// Stop: each client gets what its outbox holds (for at most `linger`), then the
    /// connections close. What every client got.
    pub fn finish(mut self, linger: Duration) -> ServerStats {
        let until = Instant::now() + linger;
        while Instant::now() < until
            && self
                .live_clients()
                .iter()
                .any(|c| c.outbox.lock().map(|q| !q.is_empty()).unwrap_or(false))
        {
            std::thread::sleep(Duration::from_millis(20));
        }
        self.shared.closing.store(true, Ordering::Relaxed);
        if let Some(a) = self.accept.take() {
            let _ = a.join();
        }
        let threads = self
            .threads
            .lock()
            .map(|mut t| std::mem::take(&mut *t))
            .unwrap_or_default();
        for t in threads {
            let _ = t.join();
        }
        self.stats()
    }

    /// What the server has done so far.
    pub fn stats(&self) -> ServerStats {
        ServerStats {
            addr: self.addr.to_string(),
            published: self.shared.published.load(Ordering::Relaxed),
            clients: self
                .shared
                .clients
                .lock()
                .map(|c| c.iter().map(|c| c.stats()).collect())
                .unwrap_or_default(),
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.shared.closing.store(true, Ordering::Relaxed);
    }
}

fn now_ns() -> u128 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0)
}

fn time_json(ns: u64) -> serde_json::Value {
    serde_json::json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn accept_loop(
    listener: TcpListener,
    shared: Arc<Shared>,
    threads: Arc<Mutex<Vec<JoinHandle<()>>>>,
) {
    while !shared.closing.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, peer)) => {
                let shared = shared.clone();
                let t = std::thread::Builder::new()
                    .name(format!("live-{peer}"))
                    .spawn(move || {
                        if let Err(e) = serve(stream, peer, &shared) {
                            tracing::info!("live view: client {peer}: {e:#}");
                        }
                    });
                match t {
                    Ok(t) => {
                        if let Ok(mut v) = threads.lock() {
                            v.push(t);
                        }
                    }
                    Err(e) => tracing::warn!("live view: no thread for {peer}: {e}"),
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => {
                tracing::warn!("live view: accept: {e}");
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

/// The WebSocket handshake: the client must offer our subprotocol, which we then choose.
#[allow(clippy::result_large_err)] // tungstenite's callback signature
fn choose_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("Sec-WebSocket-Protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if !offered {
        let mut e = ErrorResponse::new(Some(format!(
            "this server speaks the {SUBPROTOCOL} subprotocol only"
        )));
        *e.status_mut() = tungstenite::http::StatusCode::BAD_REQUEST;
        return Err(e);
    }
    resp.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        tungstenite::http::HeaderValue::from_static(SUBPROTOCOL),
    );
    Ok(resp)
}

fn serve(stream: TcpStream, peer: SocketAddr, shared: &Shared) -> Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut ws = tungstenite::accept_hdr(stream, choose_subprotocol)
        .map_err(|e| anyhow::anyhow!("handshake: {e}"))?;
    ws.get_mut()
        .set_read_timeout(Some(Duration::from_millis(10)))?;
    // a viewer that stops reading but keeps its connection is let go, rather than hold this
    // thread (and the server's end) in a write
    ws.get_mut()
        .set_write_timeout(Some(Duration::from_secs(10)))?;
    let client = Arc::new(Client {
        peer,
        outbox: Mutex::new(VecDeque::new()),
        subs: Mutex::new(vec![None; shared.channels.len()]),
        subscriptions: AtomicU64::new(0),
        sent: AtomicU64::new(0),
        dropped: AtomicU64::new(0),
        bytes: AtomicU64::new(0),
        controls: AtomicU64::new(0),
        gone: AtomicBool::new(false),
    });
    ws.send(Message::Text(shared.info.clone().into()))?;
    ws.send(Message::Text(shared.advertise.clone().into()))?;
    if let Ok(mut c) = shared.clients.lock() {
        c.push(client.clone());
    }
    tracing::info!("live view: client {peer} connected");
    let r = client_loop(&mut ws, &client, shared);
    client.gone.store(true, Ordering::Relaxed);
    let _ = ws.close(None);
    let _ = ws.flush();
    tracing::info!(
        "live view: client {peer} gone ({} messages sent, {} dropped)",
        client.sent.load(Ordering::Relaxed),
        client.dropped.load(Ordering::Relaxed)
    );
    r
}

fn client_loop(
    ws: &mut tungstenite::WebSocket<TcpStream>,
    client: &Client,
    shared: &Shared,
) -> Result<()> {
    loop {
        match ws.read() {
            Ok(Message::Text(t)) => on_text(&t, client),
            Ok(Message::Binary(b)) => on_binary(&b, client, shared),
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => {
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
        let batch: Vec<Message> = client
            .outbox
            .lock()
            .map(|mut q| q.drain(..).collect())
            .unwrap_or_default();
        if !batch.is_empty() {
            for m in batch {
                client.bytes.fetch_add(m.len() as u64, Ordering::Relaxed);
                ws.write(m)?;
                client.sent.fetch_add(1, Ordering::Relaxed);
            }
            ws.flush()?;
        } else if shared.closing.load(Ordering::Relaxed) {
            return Ok(());
        }
    }
}

fn on_text(t: &str, client: &Client) {
    let Ok(v) = serde_json::from_str::<serde_json::Value>(t) else {
        tracing::info!("live view: client {}: not JSON: {t:.80}", client.peer);
        return;
    };
    let Ok(mut subs) = client.subs.lock() else {
        return;
    };
    match v["op"].as_str() {
        Some("subscribe") => {
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                let (Some(id), Some(ch)) = (s["id"].as_u64(), s["channelId"].as_u64()) else {
                    continue;
                };
                if let Some(slot) = (ch as usize).checked_sub(1).and_then(|i| subs.get_mut(i)) {
                    *slot = Some(id as u32);
                    client.subscriptions.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        Some("unsubscribe") => {
            for id in v["subscriptionIds"].as_array().into_iter().flatten() {
                let id = id.as_u64().map(|i| i as u32);
                for s in subs.iter_mut() {
                    if *s == id {
                        *s = None;
                    }
                }
            }
        }
        other => tracing::debug!("live view: client {}: op {other:?} ignored", client.peer),
    }
}

/// A playback control request (binary op 3): command u8, speed f32, had_seek u8, seek u64,
/// request id (u32 length, UTF-8).
fn on_binary(b: &[u8], client: &Client, shared: &Shared) {
    let Some((&3, rest)) = b.split_first() else {
        return;
    };
    if rest.len() < 18 {
        return;
    }
    let play = rest[0] == 0;
    let speed = f32::from_le_bytes([rest[1], rest[2], rest[3], rest[4]]);
    let had_seek = rest[5] != 0;
    let mut seek = [0u8; 8];
    seek.copy_from_slice(&rest[6..14]);
    let mut len = [0u8; 4];
    len.copy_from_slice(&rest[14..18]);
    let n = u32::from_le_bytes(len) as usize;
    let request_id = rest
        .get(18..18 + n)
        .map(|s| String::from_utf8_lossy(s).into_owned())
        .unwrap_or_default();
    client.controls.fetch_add(1, Ordering::Relaxed);
    let c = Control {
        play,
        speed,
        seek_ns: had_seek.then(|| u64::from_le_bytes(seek)),
        request_id,
    };
    if let Ok(tx) = shared.controls.lock()
        && let Some(tx) = tx.as_ref()
    {
        let _ = tx.send(c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> Vec<ChannelSpec> {
        vec![ChannelSpec {
            topic: "/x",
            schema_name: "x",
            schema: "{\"type\":\"object\"}",
        }]
    }

    fn connect(addr: SocketAddr) -> tungstenite::WebSocket<TcpStream> {
        let stream = TcpStream::connect(addr).expect("connects");
        let mut req =
            tungstenite::client::IntoClientRequest::into_client_request(format!("ws://{addr}/"))
                .expect("request");
        req.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            tungstenite::http::HeaderValue::from_static(SUBPROTOCOL),
        );
        let (ws, resp) = tungstenite::client(req, stream).expect("handshake");
        assert_eq!(
            resp.headers()
                .get("Sec-WebSocket-Protocol")
                .and_then(|v| v.to_str().ok()),
            Some(SUBPROTOCOL)
        );
        ws
    }

    fn text(ws: &mut tungstenite::WebSocket<TcpStream>) -> serde_json::Value {
        match ws.read().expect("a message") {
            Message::Text(t) => serde_json::from_str(&t).expect("JSON"),
            m => panic!("not text: {m:?}"),
        }
    }

    #[test]
    fn a_client_subscribes_and_gets_messages_with_their_time() {
        let s = Server::start("127.0.0.1:0".parse().unwrap(), spec(), Options::default())
            .expect("starts");
        let mut ws = connect(s.addr());
        let info = text(&mut ws);
        assert_eq!(info["op"], "serverInfo");
        assert!(
            info["capabilities"]
                .as_array()
                .unwrap()
                .contains(&"time".into())
        );
        let adv = text(&mut ws);
        assert_eq!(adv["channels"][0]["topic"], "/x");
        assert_eq!(adv["channels"][0]["schemaEncoding"], "jsonschema");
        let sub = r#"{"op":"subscribe","subscriptions":[{"id":7,"channelId":1}]}"#;
        ws.send(Message::Text(sub.into())).unwrap();
        assert!(s.wait_for_subscribers(1, Duration::from_secs(10)));
        s.publish(0, 1_500_000_000, b"{\"a\":1}");
        s.time(1_600_000_000);
        let Message::Binary(b) = ws.read().unwrap() else {
            panic!("binary")
        };
        assert_eq!(b[0], 1, "message data");
        assert_eq!(u32::from_le_bytes(b[1..5].try_into().unwrap()), 7);
        assert_eq!(
            u64::from_le_bytes(b[5..13].try_into().unwrap()),
            1_500_000_000
        );
        assert_eq!(&b[13..], b"{\"a\":1}");
        let Message::Binary(b) = ws.read().unwrap() else {
            panic!("binary")
        };
        assert_eq!((b[0], b.len()), (2, 9), "time");
        let st = s.finish(Duration::from_secs(5));
        assert_eq!(st.clients.len(), 1);
        assert_eq!((st.clients[0].sent, st.clients[0].dropped), (2, 0));
    }

    #[test]
    fn a_client_that_falls_behind_loses_its_oldest_messages_counted_and_holds_nobody() {
        let opts = Options {
            backlog: 16,
            ..Options::default()
        };
        let s = Server::start("127.0.0.1:0".parse().unwrap(), spec(), opts).expect("starts");
        let mut slow = connect(s.addr());
        let _ = (text(&mut slow), text(&mut slow));
        let sub = r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":1}]}"#;
        slow.send(Message::Text(sub.into())).unwrap();
        assert!(s.wait_for_subscribers(1, Duration::from_secs(10)));
        // the client reads nothing: the socket's buffers fill, then its outbox
        let payload = vec![b'x'; 64 * 1024];
        let n = 2000u64;
        for k in 0..n {
            s.publish(0, k, &payload);
        }
        let st = s.stats();
        let c = &st.clients[0];
        assert!(c.dropped > 0, "{c:?}");
        assert!(c.sent + c.dropped <= n, "{c:?}");
        assert_eq!(st.published, n);
        drop(slow);
        let st = s.finish(Duration::from_secs(1));
        let c = &st.clients[0];
        assert!(c.dropped > 0 && c.sent + c.dropped <= n, "{c:?}");
    }
}
