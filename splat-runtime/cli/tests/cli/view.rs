//! `splat view`: the page and nothing else over HTTP; over its WebSocket, a frame for each
//! camera equal to `splat render` of that camera (and knobs) within JPEG's error; settings
//! shared by every tab; dataset views beside their pictures, with `splat eval`'s PSNR; bad
//! messages answered with an error while the session and the server go on; a tab that leaves
//! mid-frame; a token asked for when open to the network.

use crate::common::*;
use splat_runtime::Camera;
use splat_runtime::glam::{Mat3, Vec2, Vec3};
use splat_runtime::io::camera::CameraFile;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use tungstenite::Message;

/// A running `splat view` (killed when dropped), its port and the line it printed; its output
/// is kept open, as a terminal's would be.
struct Server(
    std::process::Child,
    u16,
    String,
    #[allow(dead_code)] BufReader<std::process::ChildStdout>,
);

impl Drop for Server {
    fn drop(&mut self) {
        self.0.kill().ok();
        self.0.wait().ok();
    }
}

fn start() -> Server {
    start_with(&["--port", "0", "--backend", "cpu"], Path::new("."))
}

/// `splat view ARGS` run in `dir`, once it prints its URL.
fn start_with(args: &[&str], dir: &Path) -> Server {
    serving(&[&["view"], args].concat(), dir)
}

/// `splat ARGS` run in `dir`, once it prints a URL: its port and that line.
fn serving(args: &[&str], dir: &Path) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_splat"))
        .args(args)
        .current_dir(dir)
        .env_remove("XDG_RUNTIME_DIR")
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    while !line.contains("http://") {
        line.clear();
        assert!(stdout.read_line(&mut line).unwrap() > 0, "no URL printed");
    }
    let port = line
        .split("http://")
        .nth(1)
        .and_then(|rest| rest.split('/').next()?.rsplit(':').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    Server(child, port, line, stdout)
}

fn get(port: u16, path: &str) -> String {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    out
}

type Socket = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

fn connect(port: u16) -> Socket {
    tungstenite::connect(format!("ws://127.0.0.1:{port}/ws"))
        .unwrap()
        .0
}

fn send(ws: &mut Socket, message: serde_json::Value) {
    ws.send(Message::text(message.to_string())).unwrap();
}

/// A view of the built-in scene from off its axis.
fn camera(width: u32, height: u32) -> Camera {
    let eye = Vec3::new(2.0, 1.0, -5.5);
    let forward = (-eye).normalize();
    let right = -Vec3::Y.cross(forward).normalize();
    let rotation = Mat3::from_cols(right, forward.cross(right), forward).transpose();
    Camera {
        rotation,
        translation: -(rotation * eye),
        focal: Vec2::splat(0.8 * width as f32),
        principal: Vec2::new(width as f32 / 2.0, height as f32 / 2.0),
        size: Vec2::new(width as f32, height as f32),
        ..Default::default()
    }
}

fn json(c: &Camera) -> String {
    serde_json::to_string(&CameraFile::from_camera(c)).unwrap()
}

/// How far `got` is from `splat render` of `dir`'s camera.json (with `knobs`): the mean and
/// the largest difference per channel, in [0, 1].
fn off_splat_render(dir: &Path, got: &image::RgbImage, knobs: &[&str]) -> (f64, f64) {
    let args = [
        "render",
        "--camera",
        "camera.json",
        "--out",
        "r.png",
        "--backend",
        "cpu",
    ];
    ok(&splat(&[&args[..], knobs].concat(), dir));
    let want = image::open(dir.join("r.png")).unwrap().to_rgb8();
    difference(got, &want)
}

/// The next message of kind `kind` ("frame", "settings", "scene" or "error"), as JSON; frames'
/// images and other messages are passed over.
fn next(ws: &mut Socket, kind: &str) -> serde_json::Value {
    loop {
        if let Message::Text(t) = ws.read().unwrap() {
            let message: serde_json::Value = serde_json::from_str(&t).unwrap();
            if let Some(body) = message.get(kind) {
                return body.clone();
            }
            assert!(message.get("error").is_none(), "{message}");
        }
    }
}

/// The next answer that is not about the scene or settings (a frame's stats or an error).
fn next_text(ws: &mut Socket) -> String {
    loop {
        if let Message::Text(t) = ws.read().unwrap()
            && !t.starts_with("{\"scene\"")
            && !t.starts_with("{\"settings\"")
        {
            return t.to_string();
        }
    }
}

/// The next frame, decoded.
fn next_frame(ws: &mut Socket) -> image::RgbImage {
    loop {
        match ws.read().unwrap() {
            Message::Binary(b) => return image::load_from_memory(&b).unwrap().to_rgb8(),
            Message::Text(t) => assert!(!t.contains("\"error\""), "{t}"),
            _ => {}
        }
    }
}

#[test]
fn the_page_and_nothing_else_over_http() {
    let server = start();
    let page = get(server.1, "/");
    assert!(
        page.starts_with("HTTP/1.1 200") && page.contains("new WebSocket"),
        "{page}"
    );
    for path in ["/../Cargo.toml", "/etc/passwd", "/page.html", "/%2e%2e/x"] {
        let answer = get(server.1, path);
        assert!(answer.starts_with("HTTP/1.1 404"), "{path}: {answer}");
    }
}

#[test]
fn frames_match_splat_render_within_jpeg_error() {
    let dir = temp();
    let server = start();
    let cam = camera(160, 120);
    let mut ws = connect(server.1);
    ws.send(Message::text(json(&cam))).unwrap();
    let frame = next_frame(&mut ws);
    let stats = next_text(&mut ws);
    assert!(
        stats.contains("\"visible\"") && stats.contains("the CPU"),
        "{stats}"
    );
    assert_eq!(frame.dimensions(), (160, 120));

    std::fs::write(dir.path().join("camera.json"), json(&cam)).unwrap();
    let (mean, most) = off_splat_render(dir.path(), &frame, &[]);
    println!("JPEG frame against splat render: mean {mean:.4}, largest {most:.3}");
    // JPEG at quality 90 on a 160 x 120 render of the built-in scene: measured mean 0.0053,
    // largest 0.094 (at sharp edges, where JPEG's 8x8 blocks ring).
    assert!(mean < 0.01 && most < 0.3, "mean {mean}, largest {most}");
}

#[test]
fn bad_messages_are_answered_and_the_session_goes_on() {
    let server = start();
    let mut ws = connect(server.1);
    for bad in [
        "not json",
        "{\"width\": 3}",
        &json(&camera(100_000, 100_000)),
    ] {
        ws.send(Message::text(bad)).unwrap();
        let answer = next_text(&mut ws);
        assert!(answer.contains("\"error\""), "{bad}: {answer}");
    }
    ws.send(Message::binary(vec![1, 2, 3])).unwrap();
    assert!(next_text(&mut ws).contains("JSON text"));
    ws.send(Message::text(json(&camera(64, 48)))).unwrap();
    assert_eq!(next_frame(&mut ws).dimensions(), (64, 48));

    // A message past the limit ends that session, not the server.
    ws.send(Message::text("x".repeat(1 << 20))).ok();
    drop(ws);
    // A tab that leaves mid-frame.
    let mut gone = connect(server.1);
    gone.send(Message::text(json(&camera(640, 480)))).unwrap();
    drop(gone);
    let mut ws = connect(server.1);
    ws.send(Message::text(json(&camera(32, 24)))).unwrap();
    assert_eq!(next_frame(&mut ws).dimensions(), (32, 24));
}

/// A knob turned in one tab changes every tab's frames, as the same flag of `splat render`
/// does; a knob set wrong is refused with the settings left as they were.
#[test]
fn settings_are_the_knobs_of_splat_render_shared_by_every_tab() {
    let dir = temp();
    let server = start();
    let cam = camera(160, 120);
    std::fs::write(dir.path().join("camera.json"), json(&cam)).unwrap();
    let (mut one, mut two) = (connect(server.1), connect(server.1));
    let scene = next(&mut two, "scene");
    assert_eq!(
        scene["settings"]["p_max"],
        serde_json::Value::Null,
        "{scene}"
    );
    assert!(scene["methods"].as_array().unwrap().len() > 1, "{scene}");
    send(&mut two, serde_json::json!({ "settings": { "p_max": 2 } }));
    assert_eq!(next(&mut two, "settings")["p_max"], 2);

    one.send(Message::text(json(&cam))).unwrap();
    let frame = next_frame(&mut one);
    let stats = next(&mut one, "frame");
    assert_eq!(stats["settings"]["p_max"], 2, "{stats}");
    assert!(
        stats["explain"].as_str().unwrap().contains("method"),
        "{stats}"
    );
    let (mean, most) = off_splat_render(dir.path(), &frame, &["--p-max", "2"]);
    println!("P_max 2 against splat render --p-max 2: mean {mean:.4}, largest {most:.3}");
    assert!(mean < 0.01 && most < 0.3, "mean {mean}, largest {most}");
    // The knob shows: the frame is far from the one with every primitive.
    let (apart, _) = off_splat_render(dir.path(), &frame, &[]);
    assert!(
        apart > 4.0 * mean,
        "P_max 2 moved the frame by only {apart}"
    );

    for bad in [
        serde_json::json!({ "method": "nope" }),
        serde_json::json!({ "sh_degree": 9 }),
        serde_json::json!({ "p_max": 0 }),
        serde_json::json!({ "t_min": 1.5 }),
        serde_json::json!({ "precision": "f8" }),
        serde_json::json!({ "colour": 1 }),
        serde_json::json!(7),
    ] {
        send(&mut one, serde_json::json!({ "settings": bad }));
        let answer = next_text(&mut one);
        assert!(answer.contains("\"error\""), "{bad}: {answer}");
    }
    send(
        &mut one,
        serde_json::json!({ "settings": { "p_max": null, "output": "depth" } }),
    );
    assert_eq!(next(&mut one, "settings")["output"], "depth");
    two.send(Message::text(json(&cam))).unwrap();
    let depth = next_frame(&mut two);
    let stats = next(&mut two, "frame");
    assert_eq!(
        stats["settings"]["p_max"],
        serde_json::Value::Null,
        "{stats}"
    );
    let (apart, _) = off_splat_render(dir.path(), &depth, &[]);
    assert!(
        apart > 0.05,
        "the depth output looks like the color: {apart}"
    );
}

/// A dataset's views, each beside its picture, with the PSNR `splat eval` measures of it.
#[test]
fn dataset_views_show_beside_their_pictures_with_eval_psnr() {
    let dir = temp();
    let args = [
        "dataset", "--out", "planet", "--views", "16", "--width", "40", "--height", "30",
    ];
    ok(&splat(&args, dir.path()));
    let args = [
        "fit",
        "planet",
        "--steps",
        "30",
        "--out",
        "out",
        "--backend",
        "cpu",
    ];
    ok(&splat(&args, dir.path()));
    let args = [
        "eval",
        "planet",
        "--scene",
        "out/scene.ply",
        "--method",
        "3dgs",
    ];
    ok(&splat(
        &[&args[..], &["--out", "eval", "--backend", "cpu"]].concat(),
        dir.path(),
    ));
    let rows = csv_rows(&dir.path().join("eval/eval.csv"));

    let args = [
        "planet",
        "--scene",
        "out/scene.ply",
        "--method",
        "3dgs",
        "--port",
        "0",
    ];
    let server = start_with(&[&args[..], &["--backend", "cpu"]].concat(), dir.path());
    let mut ws = connect(server.1);
    let scene = next(&mut ws, "scene");
    let views = scene["views"].as_array().unwrap();
    assert_eq!(views.len(), rows.len(), "{scene}");
    for (k, compare, width) in [(1, "side", 80), (0, "difference", 40), (1, "render", 40)] {
        send(
            &mut ws,
            serde_json::json!({ "view": k, "compare": compare }),
        );
        let frame = next_frame(&mut ws);
        assert_eq!(frame.dimensions(), (width, 30), "{compare}");
        let view = &next(&mut ws, "frame")["view"];
        let psnr = view["psnr"].as_f64().unwrap();
        let eval: f64 = rows[k][2].parse().unwrap();
        assert!(
            (psnr - eval).abs() < 1e-3,
            "view {k}: {psnr} dB, splat eval {eval}"
        );
        assert_eq!(view["camera"]["width"], 40, "{view}");
    }
    send(&mut ws, serde_json::json!({ "view": 99 }));
    assert!(next_text(&mut ws).contains("there are"), "no such view");

    // Without a dataset there is no view to snap to.
    let server = start();
    let mut ws = connect(server.1);
    send(&mut ws, serde_json::json!({ "view": 0 }));
    assert!(next_text(&mut ws).contains("no dataset views"));
}

/// A scene that does not load is refused before anything is served, naming the file.
#[test]
fn a_scene_that_does_not_load_is_refused() {
    let dir = temp();
    write(
        dir.path(),
        "broken.ply",
        b"ply\nformat ascii 1.0\nend_header\n",
    );
    let nothing = dir.path().join("nothing");
    let args = ["view", "broken.ply", "--method", "3dgs", "--port", "0"];
    fails(&splat(&args, dir.path()), "broken.ply", &nothing);
    std::fs::create_dir(dir.path().join("empty")).unwrap();
    let args = ["view", "empty", "--method", "3dgs", "--port", "0"];
    fails(&splat(&args, dir.path()), "without scene.ply", &nothing);
    let args = [
        "view",
        "empty",
        "--scene",
        "broken.ply",
        "--method",
        "3dgs",
        "--port",
        "0",
    ];
    fails(&splat(&args, dir.path()), "empty", &nothing);
}

/// Open to the network, the page and its socket ask for the token printed in the URL.
#[test]
fn open_to_the_network_it_asks_for_a_token() {
    let server = start_with(
        &["--host", "0.0.0.0", "--port", "0", "--backend", "cpu"],
        Path::new("."),
    );
    let token = server
        .2
        .split("?token=")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap();
    assert_eq!(token.len(), 32, "{}", server.2);
    assert!(get(server.1, "/").starts_with("HTTP/1.1 403"));
    assert!(get(server.1, "/?token=0123").starts_with("HTTP/1.1 403"));
    let page = get(server.1, &format!("/?token={token}"));
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    assert!(tungstenite::connect(format!("ws://127.0.0.1:{}/ws", server.1)).is_err());
    let url = format!("ws://127.0.0.1:{}/ws?token={token}", server.1);
    let mut ws = tungstenite::connect(url).unwrap().0;
    ws.send(Message::text(json(&camera(32, 24)))).unwrap();
    assert_eq!(next_frame(&mut ws).dimensions(), (32, 24));
}

/// `splat fit --view`: the page shows the scene as it trains (frames come again, changed, with
/// no camera sent), the run's status, and holds the run while paused; the run ends as it
/// would without the page.
#[test]
fn fit_view_shows_the_run_as_it_trains_and_pauses_it() {
    let dir = temp();
    let args = [
        "fit",
        "--steps",
        "400",
        "--view",
        "--view-every",
        "10",
        "--port",
        "0",
    ];
    let mut server = serving(
        &[&args[..], &["--backend", "cpu", "--out", "out"]].concat(),
        dir.path(),
    );
    let mut ws = connect(server.1);
    let scene = next(&mut ws, "scene");
    assert_eq!(scene["training"]["steps"], 400, "{scene}");
    ws.send(Message::text(json(&camera(64, 48)))).unwrap();
    let first = next_frame(&mut ws);
    // Frames of the scene as it trains arrive with no camera sent again.
    let mut later = next_frame(&mut ws);
    for _ in 0..5 {
        later = next_frame(&mut ws);
    }
    let (apart, _) = difference(&first, &later);
    assert!(
        apart > 0.0,
        "the frames did not change as the scene trained"
    );

    send(&mut ws, serde_json::json!({ "pause": true }));
    let held = loop {
        let t = next(&mut ws, "training");
        if t["paused"] == true {
            break t["step"].as_u64().unwrap();
        }
    };
    // For 1.5 s no step runs: every status that comes says at most the step held (and the
    // one in progress when the pause arrived).
    for t in statuses_within(&mut ws, std::time::Duration::from_millis(1500)) {
        assert!(
            t["step"].as_u64().unwrap() <= held + 1,
            "{t} after pausing at {held}"
        );
    }
    send(&mut ws, serde_json::json!({ "pause": false }));
    let status = loop {
        let t = next(&mut ws, "training");
        if t["paused"] == false && t["step"].as_u64().unwrap() > held + 1 {
            break t;
        }
    };
    assert!(status["loss"].as_array().unwrap().len() > 2, "{status}");
    assert!(status["primitives"].as_u64().unwrap() > 0, "{status}");
    // The run goes on to its end and writes its results; the page goes with it.
    assert!(server.0.wait().unwrap().success());
    let csv = std::fs::read_to_string(dir.path().join("out/metrics.csv")).unwrap();
    // The header, the test views before the first step, a row per step.
    assert_eq!(csv.lines().count(), 2 + 400);
    assert!(dir.path().join("out/scene.ply").is_file());
}

/// The training statuses that arrive over `time`.
fn statuses_within(ws: &mut Socket, time: std::time::Duration) -> Vec<serde_json::Value> {
    let tcp = |ws: &mut Socket| match ws.get_mut() {
        tungstenite::stream::MaybeTlsStream::Plain(s) => s.try_clone().unwrap(),
        _ => unreachable!("a plain connection"),
    };
    let end = std::time::Instant::now() + time;
    let mut seen = vec![];
    while let Some(left) = end.checked_duration_since(std::time::Instant::now()) {
        tcp(ws)
            .set_read_timeout(Some(left.max(std::time::Duration::from_millis(1))))
            .unwrap();
        match ws.read() {
            Ok(Message::Text(t)) => {
                let m: serde_json::Value = serde_json::from_str(&t).unwrap();
                seen.extend(m.get("training").cloned());
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                break;
            }
            Err(e) => panic!("{e}"),
        }
    }
    tcp(ws).set_read_timeout(None).unwrap();
    seen
}

/// The page in a real browser (headless Chromium driven by `tests/browser/view.mjs`): the first
/// frame arrives and shows what `splat render` renders from the camera the page reports; a
/// drag orbits to a new camera and its frame arrives. Needs node, Chromium and
/// `npm install` in `tests/browser` (`.ci/run` installs them); skipped without them unless
/// `SPLAT_REQUIRE_BROWSER=1`.
#[test]
fn the_page_shows_splat_renders_in_chromium() {
    let Some(browser) = browser() else { return };
    let dir = temp();
    let server = start();
    let url = format!("http://127.0.0.1:{}/", server.1);
    let run = Command::new("node")
        .arg(browser.join("view.mjs"))
        .args([url.as_str(), dir.path().to_str().unwrap()])
        .output()
        .unwrap();
    let report = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{report}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(report.contains("\"moved\":true"), "{report}");
    assert!(report.contains("\"knobSameCamera\":true"), "{report}");
    assert!(report.contains("\"pMax\":\"2\""), "{report}");
    assert!(
        report.contains("method"),
        "the panel shows no effects: {report}"
    );

    let shot = image::open(dir.path().join("frame.png")).unwrap().to_rgb8();
    let (mean, most) = off_splat_render(dir.path(), &shot, &[]);
    println!("Chromium's screenshot against splat render: mean {mean:.4}, largest {most:.3}");
    // JPEG at quality 90, decoded by Chromium: measured mean 0.0022, largest 0.10.
    assert!(mean < 0.01 && most < 0.3, "mean {mean}, largest {most}");

    // After P_max 2 is typed in the panel: `splat render --p-max 2` of the same camera.
    std::fs::copy(
        dir.path().join("moved.json"),
        dir.path().join("camera.json"),
    )
    .unwrap();
    let shot = image::open(dir.path().join("knob.png")).unwrap().to_rgb8();
    let (mean, most) = off_splat_render(dir.path(), &shot, &["--p-max", "2"]);
    println!("with P_max 2 against splat render --p-max 2: mean {mean:.4}, largest {most:.3}");
    assert!(mean < 0.01 && most < 0.3, "mean {mean}, largest {most}");
    let (apart, _) = off_splat_render(dir.path(), &shot, &[]);
    assert!(
        apart > 4.0 * mean,
        "P_max 2 moved the frame by only {apart}"
    );

    // The path the page saved is one `splat video` flies.
    let args = [
        "video",
        "--method",
        "3dgs",
        "--path",
        "path.json",
        "--frames",
        "4",
    ];
    let out = ok(&splat(
        &[&args[..], &["--out", "path.mp4", "--backend", "cpu"]].concat(),
        dir.path(),
    ));
    assert!(out.contains("4 frames of 640x400"), "{out}");
}
