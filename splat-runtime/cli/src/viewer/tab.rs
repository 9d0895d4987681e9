//! One tab's WebSocket session. The page sends JSON text: a camera (the format of camera
//! files) or `{"view": K, "compare": "render" | "side" | "difference"}` (a dataset view) asks
//! for a frame; `{"settings": {...}}` changes some of the shared settings. The server answers
//! a frame with the image (binary, JPEG) and then `{"frame": stats}`; a settings change with
//! `{"settings": ...}`; anything it cannot do with `{"error": why}`, the session going on. On
//! connecting the page is sent `{"scene": ...}`: what it shows and offers. A camera that
//! arrives while a frame renders replaces the one waiting, so a slow client is sent the newest
//! view, never a queue of old ones. While a scene trains (`splat fit --view`), the tab is sent
//! `{"training": status}` as the run moves and the last frame again as the scene changes;
//! `{"pause": true | false}` holds and resumes the run.

use super::live::Live;
use super::picture::{self, Compare};
use super::station::{Output, Rendered, Station};
use anyhow::{Context, Result, anyhow, bail};
use serde::Deserialize;
use splat_runtime::glam::Vec3;
use splat_runtime::io::camera::CameraFile;
use splat_runtime::io::dataset::Shot;
use splat_runtime::train::{fit::composite, loss};
use splat_runtime::{Camera, Image};
use std::io::ErrorKind;
use std::net::TcpStream;
use std::time::Instant;
use tungstenite::{Message, WebSocket};

/// The most pixels a frame may have (4K): larger requests are refused with a message.
pub const MOST_PIXELS: u32 = 3840 * 2160;

/// How often a tab of a scene in training looks for a newer scene and status.
const LIVE_POLL: std::time::Duration = std::time::Duration::from_millis(200);

/// What the tabs of one `splat view` look at.
pub struct Scene<'a> {
    pub station: Station<'a>,
    /// A dataset's views a tab can snap to, with their pictures (none for a lone scene).
    pub views: Vec<Shot>,
    /// What the pictures and renders are composited on to compare them.
    pub background: Vec3,
    /// What the page is told first: the scene, its views, the choices it offers.
    pub intro: serde_json::Value,
    /// The run training the scene, if it trains.
    pub live: Option<Live>,
}

/// What a tab asks for a frame of.
#[derive(Clone, Copy)]
enum Ask {
    Camera(Camera),
    View { index: usize, compare: Compare },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ViewAsk {
    view: usize,
    #[serde(default)]
    compare: Compare,
}

/// A tab's socket, the last view's picture it loaded, what it was last sent.
struct Tab<'s> {
    socket: WebSocket<TcpStream>,
    scene: &'s Scene<'s>,
    picture: Option<(usize, Image)>,
    /// The last frame asked for, and the version of the scene it showed.
    shown: Option<(Ask, u64)>,
    /// The version of the training status last sent.
    status: u64,
}

/// Serves one tab until it closes (or the station does).
pub fn run(socket: WebSocket<TcpStream>, scene: &Scene) -> Result<()> {
    if scene.live.is_some() {
        socket.get_ref().set_read_timeout(Some(LIVE_POLL))?;
    }
    let mut tab = Tab {
        socket,
        scene,
        picture: None,
        shown: None,
        status: 0,
    };
    let mut intro = scene.intro.clone();
    intro["settings"] = serde_json::to_value(scene.station.settings())?;
    intro["training"] = scene.live.as_ref().map(Live::json).into();
    let mut sent = tab.send(Message::text(
        serde_json::json!({ "scene": intro }).to_string(),
    ));
    while sent.is_ok() {
        let Some(ask) = tab.next_ask() else { break };
        let answer = match ask {
            Ask::Camera(camera) => tab.frame(camera),
            Ask::View { index, compare } => tab.view(index, compare),
        };
        sent = match answer {
            Ok((image, stats, version)) => {
                tab.shown = Some((ask, version));
                let stats = serde_json::json!({ "frame": stats }).to_string();
                (tab.send(Message::binary(image))).and_then(|_| tab.send(Message::text(stats)))
            }
            Err(e) => tab.send_error(&format!("{e:#}")),
        };
    }
    tab.socket.close(None).ok();
    Ok(())
}

/// Stats of a rendered frame, as the page shows them.
fn stats(r: &Rendered) -> serde_json::Value {
    let s = &r.frame.stats;
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    serde_json::json!({
        "visible": s.visible,
        "primitives": s.primitives,
        "intersections": s.intersections,
        "width": r.frame.color.width,
        "height": r.frame.color.height,
        "on": r.place,
        "ms": { "preprocess": ms(s.preprocess), "rasterize": ms(s.rasterize), "shade": ms(s.shade) },
        "settings": r.settings,
        "explain": r.explain,
    })
}

impl Tab<'_> {
    /// A frame of `camera` as the settings show it, its stats and the scene's version.
    fn frame(&self, camera: Camera) -> Result<(Vec<u8>, serde_json::Value, u64)> {
        let asked = Instant::now();
        let r = self.scene.station.render(camera)?;
        let rendered = asked.elapsed();
        let image = picture::shown(&r.frame, r.settings.output)?;
        let jpeg = picture::jpeg(&image)?;
        let mut stats = stats(&r);
        stats["wall_ms"] = serde_json::json!({
            "render": rendered.as_secs_f64() * 1e3,
            "encode": (asked.elapsed() - rendered).as_secs_f64() * 1e3,
        });
        Ok((jpeg, stats, r.scene_version))
    }

    /// A frame of dataset view `index` shown against its picture, with its PSNR.
    fn view(
        &mut self,
        index: usize,
        compare: Compare,
    ) -> Result<(Vec<u8>, serde_json::Value, u64)> {
        let views = &self.scene.views;
        let Some(shot) = views.get(index) else {
            bail!(match views.len() {
                0 => "this scene has no dataset views (`splat view DATASET --scene S.ply`)"
                    .to_string(),
                n => format!("view {index}: there are {n} (0 to {})", n - 1),
            });
        };
        check_size(shot.camera.size.x as u32, shot.camera.size.y as u32)?;
        if self.picture.as_ref().is_none_or(|(k, _)| *k != index) {
            let picture = shot
                .load(self.scene.background)
                .with_context(|| format!("view {index}"))?;
            self.picture = Some((index, picture.into_image()));
        }
        let picture = &self.picture.as_ref().expect("loaded").1;
        let r = self.scene.station.render(shot.camera)?;
        let color = composite(
            r.frame.color.clone(),
            r.frame.alpha.as_ref(),
            self.scene.background,
        );
        let psnr = loss::psnr(&color, picture)?;
        let image = match (compare, r.settings.output) {
            (Compare::Difference, _) | (_, Output::Rgb) => color,
            _ => picture::shown(&r.frame, r.settings.output)?.into_owned(),
        };
        let image = picture::compared(image, picture, compare);
        let mut stats = stats(&r);
        stats["view"] = serde_json::json!({
            "index": index,
            "name": shot.path.file_name().map(|n| n.to_string_lossy()),
            "psnr": psnr,
            "compare": format!("{compare:?}").to_lowercase(),
            "camera": CameraFile::from_camera(&shot.camera),
        });
        Ok((picture::jpeg(&image)?, stats, r.scene_version))
    }

    fn send(&mut self, message: Message) -> Result<()> {
        self.socket
            .send(message)
            .map_err(|e| anyhow!("the tab went: {e}"))
    }

    fn send_error(&mut self, why: &str) -> Result<()> {
        self.send(Message::text(
            serde_json::json!({ "error": why }).to_string(),
        ))
    }

    /// The newest frame the tab asks for, waiting for one if none is pending, with every
    /// settings change before it made; `None` once the tab has gone. A message that is neither
    /// is answered with an error and skipped.
    fn next_ask(&mut self) -> Option<Ask> {
        let mut latest = None;
        loop {
            let pending = latest.is_some();
            if pending {
                self.socket.get_ref().set_nonblocking(true).ok()?;
            }
            let read = self.socket.read();
            if pending {
                self.socket.get_ref().set_nonblocking(false).ok()?;
            }
            match read {
                Ok(Message::Text(text)) => match self.take(text.as_str()) {
                    Ok(Some(ask)) => latest = Some(ask),
                    Ok(None) => {}
                    Err(e) => self.send_error(&format!("{e:#}")).ok()?,
                },
                Ok(Message::Binary(_)) => self.send_error("send JSON text").ok()?,
                Ok(Message::Close(_)) => return None,
                Ok(_) => {}
                Err(tungstenite::Error::Io(e)) if e.kind() == ErrorKind::WouldBlock && pending => {
                    return latest;
                }
                // Nothing from the tab for a while, while the scene trains.
                Err(tungstenite::Error::Io(e))
                    if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) =>
                {
                    if let Some(again) = self.poll_live().ok()? {
                        return Some(again);
                    }
                }
                Err(tungstenite::Error::Capacity(e)) => {
                    self.send_error(&format!("message refused: {e}")).ok()?;
                    return None;
                }
                Err(_) => return None,
            }
        }
    }

    /// While the scene trains: sends the run's status if it moved; the last frame asked for
    /// again if the scene changed since. An error once the station closes.
    fn poll_live(&mut self) -> Result<Option<Ask>> {
        let station = &self.scene.station;
        if station.closed() {
            bail!("the viewer closed");
        }
        let Some(live) = &self.scene.live else {
            return Ok(None);
        };
        if live.version() != self.status {
            self.status = live.version();
            let status = serde_json::json!({ "training": live.json() }).to_string();
            self.send(Message::text(status))?;
        }
        Ok(match self.shown {
            Some((ask, version)) if version != station.scene_version() => Some(ask),
            _ => None,
        })
    }

    /// A message taken in: a frame asked for, or a settings change made (and answered).
    fn take(&mut self, text: &str) -> Result<Option<Ask>> {
        let message: serde_json::Value = serde_json::from_str(text).context("not JSON")?;
        if let Some(change) = message.get("settings") {
            let settings = self.scene.station.change(change)?;
            let answer = serde_json::json!({ "settings": settings }).to_string();
            self.send(Message::text(answer))?;
            return Ok(None);
        }
        if let Some(pause) = message.get("pause") {
            let (Some(live), Some(pause)) = (&self.scene.live, pause.as_bool()) else {
                bail!(
                    "pause (true or false) holds a run of `splat fit --view`; this scene does not train"
                );
            };
            live.pause(pause);
            return Ok(None);
        }
        if message.get("view").is_some() {
            let ask: ViewAsk = serde_json::from_value(message).context("not a view")?;
            return Ok(Some(Ask::View {
                index: ask.view,
                compare: ask.compare,
            }));
        }
        Ok(Some(Ask::Camera(parse_camera(message)?)))
    }
}

/// A camera in the format of camera files, with at most [`MOST_PIXELS`].
fn parse_camera(message: serde_json::Value) -> Result<Camera> {
    let file: CameraFile = serde_json::from_value(message).context("not a camera")?;
    check_size(file.width, file.height)?;
    Ok(file.to_camera()?)
}

fn check_size(width: u32, height: u32) -> Result<()> {
    if width.saturating_mul(height) > MOST_PIXELS {
        bail!("{width}x{height} is past the viewer's {MOST_PIXELS} pixels: ask for less");
    }
    Ok(())
}
