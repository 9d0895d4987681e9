//! `splat bench`: both passes timed, on the CPU and on the device-resident GPU pipeline.

use crate::common::*;

#[test]
fn bench_times_both_passes_and_writes_the_raw_image_render_would() {
    let dir = temp();
    let size = ["--width", "64", "--height", "48"];
    let mut args = vec![
        "bench",
        "--backend",
        "cpu",
        "--iters",
        "1",
        "--threads",
        "1,2",
    ];
    args.extend(size);
    args.extend(["--raw-out", "ours.f32"]);
    let stdout = ok(&splat(&args, dir.path()));
    for needle in [
        "CPU, 1 thread",
        "CPU, 2 threads",
        "speed-up",
        "forward + backward",
    ] {
        assert!(stdout.contains(needle), "no `{needle}` in:\n{stdout}");
    }
    let mut args = vec!["render", "--backend", "cpu", "--out", "ref.npy"];
    args.extend(size);
    ok(&splat(&args, dir.path()));
    let raw: Vec<f32> = std::fs::read(dir.path().join("ours.f32"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let (shape, reference) = read_npy(&dir.path().join("ref.npy"));
    assert_eq!(shape, [48, 64, 3]);
    assert_eq!(raw, reference, "bench's raw image differs from render's");

    let out = dir.path().join("never.f32");
    let bad: [(&[&str], &str); 6] = [
        (&["--iters", "0"], "--iters"),
        (
            &["--tile", "7"],
            "--tile 7: the CPU backend takes tile sizes [8, 16, 32, 64]",
        ),
        (
            &["--shader-checks"],
            "--shader-checks is for the GPU's shaders",
        ),
        (&["--threads", "2,0"], "--threads 0"),
        (&["--scene", "missing.ply"], "missing.ply"),
        (&["--width", "0"], "image size 0x600 is out of range"),
    ];
    for (extra, needle) in bad {
        let mut args = vec!["bench", "--backend", "cpu", "--raw-out", "never.f32"];
        args.extend(extra);
        let run = splat(&args, dir.path());
        fails(&run, needle, &out);
        // Refused before any work: nothing printed as if it had started.
        assert!(
            run.stdout.is_empty(),
            "{:?}",
            String::from_utf8_lossy(&run.stdout)
        );
    }
    // Thread counts on the GPU (where there is an adapter, software ones included).
    let gpu = splat(&["bench", "--backend", "gpu", "--threads", "2"], dir.path());
    if !String::from_utf8_lossy(&gpu.stderr).contains("no GPU adapter") {
        fails(&gpu, "--threads is for the CPU's thread pools", &out);
    }
}

/// `bench --backend gpu` times device-resident frames; with `--shader-checks` it says the
/// shaders carry naga's run-time checks (`methods/benches/h200.sh` times both).
#[test]
fn gpu_bench_times_resident_frames_with_or_without_shader_checks() {
    let dir = temp();
    for (extra, checked) in [(None, false), (Some("--shader-checks"), true)] {
        let mut args = vec![
            "bench",
            "--backend",
            "gpu",
            "--iters",
            "1",
            "--width",
            "48",
            "--height",
            "32",
        ];
        args.extend(extra);
        let out = splat(&args, dir.path());
        if no_adapter(&out) {
            return;
        }
        let stdout = ok(&out);
        assert!(stdout.contains("GPU (device-resident)"), "{stdout}");
        assert_eq!(
            stdout.contains("naga's run-time checks"),
            checked,
            "{stdout}"
        );
    }
}
