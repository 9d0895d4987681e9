//! `splat view`'s server: one page built into the binary (`viewer/page.html`) and a WebSocket
//! per tab on which the page sends cameras (JSON, the format of camera files) and the server
//! answers each with the frame as a JPEG and a line of stats. Only the page is served: no path
//! from a request reaches the file system. A camera that arrives while a frame renders replaces
//! the one waiting, so a slow client is sent the newest view, never a queue of old ones.

use anyhow::{Context, Result, bail};
use splat_runtime::io::camera::CameraFile;
use splat_runtime::{Camera, Frame};
use std::cell::RefCell;
use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};

/// The page, built into the binary.
const PAGE: &str = include_str!("viewer/page.html");

/// The largest message a client may send: a camera is a few hundred bytes.
const MOST_MESSAGE_BYTES: usize = 64 << 10;

/// How long a request may take to arrive: a client that connects and sends nothing does not
/// hold its thread for good (a WebSocket session, once open, waits as long as its tab).
const REQUEST_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// The most pixels a frame may have (4K): larger requests are refused with a message.
pub const MOST_PIXELS: u32 = 3840 * 2160;

/// How many ports past the asked one are tried when it is taken.
const PORTS_TRIED: u16 = 20;

/// Listens on `127.0.0.1:port`, or the next free port (saying so); port 0 takes any free one.
pub fn bind(port: u16) -> Result<TcpListener> {
    let last = if port == 0 {
        0
    } else {
        port.saturating_add(PORTS_TRIED)
    };
    for p in port..=last {
        match TcpListener::bind(("127.0.0.1", p)) {
            Ok(listener) => return Ok(listener),
            Err(e) if e.kind() == ErrorKind::AddrInUse && p < last => {
                eprintln!("port {p} is taken; trying {}", p + 1);
            }
            Err(e) => return Err(e).with_context(|| format!("listening on 127.0.0.1:{p}")),
        }
    }
    bail!("ports {port} to {last} are all taken: give a free one with --port")
}

/// A tab's stream of frames: the cameras it sends, the frames it is sent.
pub struct Session {
    socket: RefCell<WebSocket<TcpStream>>,
}

/// Serves each connection of `listener` on a thread of its own: the page, or (on `/ws`) a
/// session handed to `session` (which renders until it returns).
pub fn serve(listener: &TcpListener, session: &(dyn Fn(&Session) -> Result<()> + Sync)) {
    std::thread::scope(|scope| {
        for stream in listener.incoming() {
            let Ok(stream) = stream else { continue };
            scope.spawn(move || {
                if let Err(e) = connection(stream, session) {
                    eprintln!("viewer: {e:#}");
                }
            });
        }
    });
}

fn connection(stream: TcpStream, session: &dyn Fn(&Session) -> Result<()>) -> Result<()> {
    stream.set_read_timeout(Some(REQUEST_TIMEOUT))?;
    let mut head = [0u8; 8];
    let n = (stream.peek(&mut head)).context("a client that connected sent no request")?;
    if head[..n].starts_with(b"GET /ws ") || head[..n].starts_with(b"GET /ws?") {
        let config = WebSocketConfig::default()
            .max_message_size(Some(MOST_MESSAGE_BYTES))
            .max_frame_size(Some(MOST_MESSAGE_BYTES));
        let socket = tungstenite::accept_with_config(stream, Some(config))
            .map_err(|e| anyhow::anyhow!("WebSocket handshake: {e}"))?;
        socket.get_ref().set_read_timeout(None)?;
        let s = Session {
            socket: RefCell::new(socket),
        };
        let result = session(&s);
        s.socket.borrow_mut().close(None).ok();
        return match result {
            // The tab went away: not an error of the server's.
            Err(e) if e.downcast_ref::<Closed>().is_some() => Ok(()),
            other => other,
        };
    }
    page(stream)
}

/// Answers an HTTP request: the page at `/`, 404 for anything else.
fn page(mut stream: TcpStream) -> Result<()> {
    let mut request = Vec::new();
    let mut chunk = [0u8; 1024];
    while !request.windows(4).any(|w| w == b"\r\n\r\n") && request.len() < 16 << 10 {
        let n = (stream.read(&mut chunk)).context("a request that did not arrive whole")?;
        if n == 0 {
            break;
        }
        request.extend_from_slice(&chunk[..n]);
    }
    let line = String::from_utf8_lossy(&request);
    let path = line.split_whitespace().nth(1).unwrap_or("");
    let (status, kind, body) = match path {
        "/" | "/index.html" => ("200 OK", "text/html; charset=utf-8", PAGE),
        _ => ("404 Not Found", "text/plain", "not found\n"),
    };
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )?;
    Ok(())
}

/// The tab closed its socket.
#[derive(Debug)]
struct Closed;

impl std::fmt::Display for Closed {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("the tab closed")
    }
}

impl std::error::Error for Closed {}

impl Session {
    /// The newest camera the tab sent, waiting for one if none is pending; `None` when the tab
    /// has gone. A message that is not a camera is answered with an error and skipped.
    pub fn next_camera(&self) -> Option<Camera> {
        let mut latest = None;
        loop {
            let pending = latest.is_some();
            if pending {
                self.socket.borrow().get_ref().set_nonblocking(true).ok()?;
            }
            let read = self.socket.borrow_mut().read();
            if pending {
                self.socket.borrow().get_ref().set_nonblocking(false).ok()?;
            }
            match read {
                Ok(Message::Text(text)) => match parse_camera(text.as_str()) {
                    Ok(c) => latest = Some(c),
                    Err(e) => self.send_text(&error_json(&e.to_string())).ok()?,
                },
                Ok(Message::Binary(_)) => {
                    self.send_text(&error_json("send the camera as JSON text"))
                        .ok()?;
                }
                Ok(Message::Close(_)) => return None,
                Ok(_) => {}
                Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::WouldBlock => {
                    return latest;
                }
                Err(tungstenite::Error::Capacity(e)) => {
                    self.send_text(&error_json(&format!("message refused: {e}")))
                        .ok()?;
                    return None;
                }
                Err(_) => return None,
            }
        }
    }

    /// Sends `frame`'s color as a JPEG, then a line of stats about it.
    pub fn send_frame(&self, frame: &Frame, place: &str) -> Result<()> {
        let jpeg = encode_jpeg(frame)?;
        let mut socket = self.socket.borrow_mut();
        socket.send(Message::binary(jpeg)).map_err(|_| Closed)?;
        let s = &frame.stats;
        let stats = serde_json::json!({
            "visible": s.visible,
            "intersections": s.intersections,
            "width": frame.color.width,
            "height": frame.color.height,
            "on": place,
            "ms": {
                "preprocess": s.preprocess.as_secs_f64() * 1e3,
                "rasterize": s.rasterize.as_secs_f64() * 1e3,
                "shade": s.shade.as_secs_f64() * 1e3,
            },
        });
        socket
            .send(Message::text(stats.to_string()))
            .map_err(|_| Closed)?;
        Ok(())
    }

    fn send_text(&self, text: &str) -> Result<()> {
        let mut socket = self.socket.borrow_mut();
        socket.send(Message::text(text)).map_err(|_| Closed)?;
        Ok(())
    }
}

fn error_json(message: &str) -> String {
    serde_json::json!({ "error": message }).to_string()
}

/// A camera in the format of camera files, with at most [`MOST_PIXELS`].
pub fn parse_camera(text: &str) -> Result<Camera> {
    let file: CameraFile = serde_json::from_str(text).context("not a camera")?;
    if file.width.saturating_mul(file.height) > MOST_PIXELS {
        bail!(
            "{}x{} is past the viewer's {MOST_PIXELS} pixels: ask for less",
            file.width,
            file.height
        );
    }
    Ok(file.to_camera()?)
}

/// `frame`'s color as a JPEG of quality 90.
fn encode_jpeg(frame: &Frame) -> Result<Vec<u8>> {
    let c = &frame.color;
    let bytes: Vec<u8> = (c.data.iter())
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let mut out = Vec::new();
    let encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90);
    image::ImageEncoder::write_image(
        encoder,
        &bytes,
        c.width,
        c.height,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}
