//! `splat view`'s server: one page built into the binary (`viewer/page.html`) and a WebSocket
//! per tab (`viewer::tab`) on which the page asks for frames and turns knobs; every tab's
//! frames come from one shared renderer (`viewer::station`). Only the page is served: no path
//! from a request reaches the file system. Bound to 127.0.0.1 unless asked otherwise; a server
//! open to the network asks for a random token in the URL (as Jupyter does).

mod live;
mod picture;
mod station;
mod tab;

pub use live::Live;
pub use station::{Settings, Station};
pub use tab::Scene;

use anyhow::{Context, Result, bail};
use std::io::{ErrorKind, Read, Write};
use std::net::{IpAddr, TcpListener, TcpStream};
use tungstenite::protocol::WebSocketConfig;

/// The page, built into the binary.
const PAGE: &str = include_str!("viewer/page.html");

/// The largest message a client may send: a camera is a few hundred bytes.
const MOST_MESSAGE_BYTES: usize = 64 << 10;

/// How long a request may take to arrive: a client that connects and sends nothing does not
/// hold its thread for good (a WebSocket session, once open, waits as long as its tab).
const REQUEST_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// How many ports past the asked one are tried when it is taken.
const PORTS_TRIED: u16 = 20;

/// Listens on `host:port`, or the next free port (saying so); port 0 takes any free one.
pub fn bind(host: IpAddr, port: u16) -> Result<TcpListener> {
    let last = if port == 0 {
        0
    } else {
        port.saturating_add(PORTS_TRIED)
    };
    for p in port..=last {
        match TcpListener::bind((host, p)) {
            Ok(listener) => return Ok(listener),
            Err(e) if e.kind() == ErrorKind::AddrInUse && p < last => {
                eprintln!("port {p} is taken; trying {}", p + 1);
            }
            Err(e) => return Err(e).with_context(|| format!("listening on {host}:{p}")),
        }
    }
    bail!("ports {port} to {last} are all taken: give a free one with --port")
}

/// A token of 128 random bits, as hex: what a URL must carry to reach a server open to the
/// network.
pub fn new_token() -> Result<String> {
    let mut bits = [0u8; 16];
    getrandom::fill(&mut bits).map_err(|e| anyhow::anyhow!("no random token: {e}"))?;
    Ok(bits.iter().map(|b| format!("{b:02x}")).collect())
}

/// Serves each connection of `listener` on a thread of its own: the page, or (on `/ws`) a
/// tab's session; with a `token`, only to requests that carry it (`?token=...`). Renders
/// every tab's frames on `scene`'s station, until the station closes.
pub fn serve(listener: &TcpListener, scene: &Scene, token: Option<&str>) -> Result<()> {
    // Polled, so that a closed station ends the loop.
    listener.set_nonblocking(true)?;
    std::thread::scope(|scope| {
        scope.spawn(|| scene.station.run());
        while !scene.station.closed() {
            let stream = match listener.accept() {
                Ok((stream, _)) => stream,
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    std::thread::sleep(ACCEPT_POLL);
                    continue;
                }
                Err(_) => continue,
            };
            scope.spawn(move || {
                let served = stream.set_nonblocking(false).map_err(Into::into);
                if let Err(e) = served.and_then(|()| connection(stream, scene, token)) {
                    eprintln!("viewer: {e:#}");
                }
            });
        }
    });
    Ok(())
}

/// How often a listener with no connection waiting looks again.
const ACCEPT_POLL: std::time::Duration = std::time::Duration::from_millis(20);

fn connection(stream: TcpStream, scene: &Scene, token: Option<&str>) -> Result<()> {
    stream.set_read_timeout(Some(REQUEST_TIMEOUT))?;
    let mut head = [0u8; 1024];
    let n = (stream.peek(&mut head)).context("a client that connected sent no request")?;
    let line = String::from_utf8_lossy(&head[..n]);
    let target = line.lines().next().and_then(|l| l.split(' ').nth(1));
    let target = target.unwrap_or("");
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let allowed = token.is_none_or(|t| carries(query, t));
    if allowed && path == "/ws" {
        let config = WebSocketConfig::default()
            .max_message_size(Some(MOST_MESSAGE_BYTES))
            .max_frame_size(Some(MOST_MESSAGE_BYTES));
        let socket = tungstenite::accept_with_config(stream, Some(config))
            .map_err(|e| anyhow::anyhow!("WebSocket handshake: {e}"))?;
        socket.get_ref().set_read_timeout(None)?;
        return tab::run(socket, scene);
    }
    // Read the whole request before answering, so the client sees the answer, not a reset.
    let mut stream = stream;
    let mut request = Vec::new();
    let mut chunk = [0u8; 1024];
    while !request.windows(4).any(|w| w == b"\r\n\r\n") && request.len() < 16 << 10 {
        let n = (stream.read(&mut chunk)).context("a request that did not arrive whole")?;
        if n == 0 {
            break;
        }
        request.extend_from_slice(&chunk[..n]);
    }
    match path {
        _ if !allowed => respond(stream, "403 Forbidden", "text/plain", FORBIDDEN),
        "/" | "/index.html" => respond(stream, "200 OK", "text/html; charset=utf-8", PAGE),
        _ => respond(stream, "404 Not Found", "text/plain", "not found\n"),
    }
}

const FORBIDDEN: &str = "this splat view is open to the network and asks for its token: \
                         open the URL it printed (with ?token=...)\n";

/// Whether the query string `query` holds `token=<token>` (compared in constant time).
fn carries(query: &str, token: &str) -> bool {
    query.split('&').any(|pair| {
        pair.strip_prefix("token=").is_some_and(|given| {
            given.len() == token.len()
                && given
                    .bytes()
                    .zip(token.bytes())
                    .fold(0, |d, (a, b)| d | (a ^ b))
                    == 0
        })
    })
}

fn respond(mut stream: TcpStream, status: &str, kind: &str, body: &str) -> Result<()> {
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )?;
    Ok(())
}
