//! What `splat view` takes per frame and what `splat fit --view` costs a training step, on
//! this machine (the CPU backend unless `-- gpu`).
//!
//! Frame latency, from a camera sent over the WebSocket to its frame decoded by the client
//! (as the page does: one camera in flight), split into render (the station, as the tab sees
//! it), encode (JPEG), send (the rest until the frame's last byte arrives) and decode; and
//! the frames per second delivered that way. For the built-in scene and the benches'
//! procedural scene of 300k Gaussians at 1280x720, beside the renderer's own stage times
//! (its baseline in the same run). Then `splat fit` on the built-in dataset without and with
//! `--view` (a tab open, following the scene as it trains).
//!
//! `cargo bench -p splat-cli --bench viewer [-- gpu] [-- N WIDTH HEIGHT]` (300000 1280 720;
//! `SPLAT`: the `splat` binary, default the one built beside the bench).

#[path = "../../../methods/benches/common/mod.rs"]
mod common;

use splat_runtime::io::camera::CameraFile;
use splat_runtime::io::ply::{self, GaussianCloud, ToStored};
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::Message;

/// The `splat` binary: `SPLAT`, or the one built with the bench.
fn splat() -> String {
    std::env::var("SPLAT").unwrap_or_else(|_| env!("CARGO_BIN_EXE_splat").to_string())
}

type Socket = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

const FRAMES: usize = 20;

/// `splat ARGS`, once it prints its page's URL: the process and the page's port.
fn serving(args: &[&str]) -> (Child, u16) {
    let mut child = Command::new(splat())
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .expect("splat runs");
    let mut stdout = BufReader::new(child.stdout.take().expect("its output"));
    let mut line = String::new();
    while !line.contains("http://") {
        line.clear();
        assert!(stdout.read_line(&mut line).expect("a line") > 0, "no URL");
    }
    // Its output drained, so it never blocks on a full pipe.
    std::thread::spawn(move || std::io::copy(&mut stdout, &mut std::io::sink()));
    let port = line
        .split("http://127.0.0.1:")
        .nth(1)
        .and_then(|r| r.split('/').next()?.parse().ok());
    (child, port.expect("a port"))
}

fn connect(port: u16) -> Socket {
    tungstenite::connect(format!("ws://127.0.0.1:{port}/ws"))
        .expect("the page's socket")
        .0
}

/// The next frame's bytes, when its last byte arrived, and the stats after it.
fn next_frame(ws: &mut Socket) -> (Vec<u8>, Instant, serde_json::Value) {
    let (bytes, at) = loop {
        match ws.read().expect("a message") {
            Message::Binary(b) => break (b.to_vec(), Instant::now()),
            Message::Text(t) => assert!(!t.contains("\"error\""), "{t}"),
            _ => {}
        }
    };
    loop {
        if let Message::Text(t) = ws.read().expect("its stats") {
            let m: serde_json::Value = serde_json::from_str(&t).expect("JSON");
            if let Some(stats) = m.get("frame") {
                return (bytes, at, stats.clone());
            }
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The latency row of one scene (`scene`: a PLY, or none for the built-in one).
fn latency(label: &str, scene: Option<&Path>, backend: &str, size: (f32, f32)) {
    let mut args = vec![
        "view",
        "--method",
        "3dgs",
        "--port",
        "0",
        "--backend",
        backend,
    ];
    let path = scene.map(|p| p.to_string_lossy().into_owned());
    args.extend(path.as_deref());
    let (mut server, port) = serving(&args);
    let mut ws = connect(port);
    let camera = match scene {
        Some(_) => common::camera(size.0, size.1),
        None => {
            let orbit = splat_runtime::glam::Vec3::new(0.0, 1.0, -6.0);
            let mut c = common::camera(size.0, size.1);
            c.translation = -orbit;
            c
        }
    };
    let json = serde_json::to_string(&CameraFile::from_camera(&camera)).expect("a camera");
    let mut rows: Vec<[f64; 6]> = vec![];
    let started = Instant::now();
    for k in 0..FRAMES + 2 {
        let sent = Instant::now();
        ws.send(Message::text(json.clone())).expect("sent");
        let (jpeg, arrived, stats) = next_frame(&mut ws);
        let decoded = image::load_from_memory(&jpeg).expect("a JPEG");
        let decoded_at = Instant::now();
        assert_eq!(decoded.width(), size.0 as u32);
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let wall = &stats["wall_ms"];
        let (render, encode) = (
            wall["render"].as_f64().unwrap(),
            wall["encode"].as_f64().unwrap(),
        );
        let stage = |s: &str| stats["ms"][s].as_f64().unwrap();
        let stages = stage("preprocess") + stage("rasterize") + stage("shade");
        let send = ms(arrived - sent) - render - encode;
        let (decode, done) = (ms(decoded_at - arrived), ms(decoded_at - sent));
        // The first two warm the renderer up.
        if k >= 2 {
            rows.push([stages, render, encode, send, decode, done]);
        }
    }
    let fps = (FRAMES + 2) as f64 / started.elapsed().as_secs_f64();
    let col = |i: usize| median(rows.iter().map(|r| r[i]).collect());
    println!(
        "| {label} | {}x{} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {fps:.1} | {:.2} |",
        size.0,
        size.1,
        col(0),
        col(1),
        col(2),
        col(3),
        col(4),
        col(5),
        col(5) / col(0),
    );
    server.kill().ok();
    server.wait().ok();
}

/// `splat fit` on the built-in dataset for `steps`, with a tab following `--view` or not:
/// its wall time per step.
fn fit_ms_per_step(backend: &str, steps: usize, view: bool, dir: &Path) -> f64 {
    let steps_arg = steps.to_string();
    let out = dir.join(if view { "viewed" } else { "plain" });
    let out = out.to_string_lossy().into_owned();
    let mut args = vec![
        "fit",
        "--steps",
        &steps_arg,
        "--backend",
        backend,
        "--out",
        &out,
    ];
    let started = Instant::now();
    if !view {
        let run = Command::new(env!("CARGO_BIN_EXE_splat"))
            .args(&args)
            .stdout(Stdio::null())
            .status();
        assert!(run.expect("splat fit runs").success());
        return started.elapsed().as_secs_f64() * 1e3 / steps as f64;
    }
    args.extend(["--view", "--port", "0"]);
    let (mut run, port) = serving(&args);
    let mut ws = connect(port);
    let camera = CameraFile::from_camera(&common::camera(640.0, 480.0));
    ws.send(Message::text(serde_json::to_string(&camera).expect("JSON")))
        .expect("sent");
    // Follow the scene until the run ends and closes the page.
    while ws.read().is_ok() {}
    assert!(run.wait().expect("splat fit ends").success());
    started.elapsed().as_secs_f64() * 1e3 / steps as f64
}

fn main() {
    let gpu = std::env::args().any(|a| a == "gpu");
    let backend = if gpu { "gpu" } else { "cpu" };
    let n = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(300_000);
    let dir = tempfile::tempdir().expect("a temporary folder");
    let ply_path = dir.path().join("procedural.ply");
    let cloud = GaussianCloud::new(
        3,
        common::scene(n).iter().map(ToStored::to_stored).collect(),
    );
    ply::write(&ply_path, &cloud).expect("the scene written");

    println!(
        "splat view on {backend}, {} threads: median of {FRAMES} frames (ms), one camera in flight",
        rayon::current_num_threads()
    );
    println!(
        "| scene | size | stages | render | encode | send | decode | camera to decoded frame | frames/s | x stages |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    latency("built-in (9,400)", None, backend, (1280.0, 720.0));
    latency(
        &format!("procedural ({n})"),
        Some(&ply_path),
        backend,
        (1280.0, 720.0),
    );

    let steps = 600;
    let plain = fit_ms_per_step(backend, steps, false, dir.path());
    let viewed = fit_ms_per_step(backend, steps, true, dir.path());
    println!(
        "\nsplat fit on the built-in dataset, {steps} steps on {backend} (wall time per step, start and final evaluation included):"
    );
    println!("| run | ms per step |\n|---|---:|");
    println!("| without --view | {plain:.2} |");
    println!(
        "| --view, a 640x480 tab following it (scene every 50 steps) | {viewed:.2} ({:+.1}%) |",
        100.0 * (viewed / plain - 1.0)
    );
}
