//! What every command promises of its outputs: written together or not at all, whole when a run is
//! killed mid-write, and a closed pipe ends a command quietly.

use crate::common::*;

/// `splat inspect | head` stops reading early: the command ends quietly, no panic.
/// A reader that stops early (`| head`) ends a command quietly, as other Unix tools end:
/// stopped by SIGPIPE, never a panic. The pipe is closed before the command starts, so its
/// first line meets it.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_a_command_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let dir = temp();
    let commands: [&[&str]; 2] = [
        &["inspect", "--method", "3dgeer"],
        &[
            "bench",
            "--backend",
            "cpu",
            "--width",
            "32",
            "--height",
            "24",
            "--iters",
            "1",
        ],
    ];
    for args in commands {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_splat"))
            .args(args)
            .current_dir(dir.path())
            .stdout(writer)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            out.status.signal(),
            Some(libc::SIGPIPE),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

/// A command's outputs that belong together (a picture and its depth, a scene and its camera)
/// appear together or not at all: a failure leaves what was there.
#[test]
fn outputs_that_belong_together_appear_together_or_not_at_all() {
    let dir = temp();
    let small = ["--width", "32", "--height", "24", "--backend", "cpu"];
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--out", "o.png"];
        args.extend_from_slice(&small);
        args.extend_from_slice(extra);
        splat(&args, dir.path())
    };
    ok(&render(&[]));
    let kept = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    let picture = kept("o.png");
    // What a failed `scene` would write over it is not this.
    let scene = write(dir.path(), "keep.ply", b"what was there");
    let scene = std::fs::read(scene).unwrap();
    let refused = |out: Output, needle: &str| {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(needle), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    };
    std::fs::create_dir(dir.path().join("o.depth.png")).unwrap();
    refused(
        render(&["--depth", "--method", "3dgut"]),
        "o.depth.png: it is a folder",
    );
    assert_eq!(kept("o.png"), picture, "the picture was replaced");
    // A file output that names a folder, or lies under a file, is refused before the work.
    let before_work = |out: Output, needle: &str| {
        assert!(
            out.stdout.is_empty(),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        refused(out, needle);
    };
    let bench = |raw: &str| {
        let args = ["bench", "--iters", "1", "--threads", "1", "--raw-out", raw];
        splat(&[&args[..], &small].concat(), dir.path())
    };
    before_work(bench("raw/"), "--raw-out raw/: it names a folder");
    before_work(
        bench("o.png/raw.f32"),
        "--raw-out o.png/raw.f32: o.png is a file",
    );
    before_work(
        splat(&["gallery", "--out", "o.depth.png"], dir.path()),
        "--out o.depth.png: it names a folder",
    );
    let scene_args = |camera: &'static str| ["scene", "--out", "keep.ply", "--camera-out", camera];
    // A camera under a file: no folder can be made there.
    refused(
        splat(&scene_args("o.png/c.json"), dir.path()),
        "writing o.png/c.json",
    );
    for same in ["keep.ply", "./keep.ply"] {
        refused(
            splat(&scene_args(same), dir.path()),
            "another output of the same command goes there",
        );
    }
    assert_eq!(kept("keep.ply"), scene, "the scene was replaced");
    // A fit whose renders cannot be written leaves the previous run's result (its last
    // checkpoint, with the metrics up to it, is written apart, before).
    tiny_dataset(&dir.path().join("data"), 2);
    let fit = [
        "fit",
        "data",
        "--steps",
        "2",
        "--backend",
        "cpu",
        "--out",
        "run",
    ];
    ok(&splat(&fit, dir.path()));
    // What the run would write is not this.
    write(dir.path(), "run/scene.ply", b"the previous result");
    std::fs::remove_file(dir.path().join("run/test/000.png")).unwrap();
    std::fs::create_dir(dir.path().join("run/test/000.png")).unwrap();
    refused(splat(&fit, dir.path()), "000.png: it is a folder");
    assert_eq!(
        kept("run/scene.ply"),
        b"the previous result",
        "the result was replaced"
    );
    let leftovers: Vec<_> = ["", "run", "run/test"]
        .iter()
        .flat_map(|d| std::fs::read_dir(dir.path().join(d)).unwrap())
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(splat_runtime::io::PARTIAL))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A run killed while it writes its output leaves the previous file whole: every output goes
/// to a temporary file in the same folder, renamed over the target once complete. The kill
/// comes from the kernel, mid-write and without a race: the run's file size limit (`ulimit
/// -f`, 64 blocks of 512 bytes) is below the new render's size, so the write past it gets
/// SIGXFSZ, which ends the process where it stands.
#[cfg(unix)]
#[test]
fn a_run_killed_while_writing_leaves_the_previous_output_whole() {
    use std::os::unix::process::ExitStatusExt;
    let dir = temp();
    let out = dir.path().join("render.exr");
    let args = |size: [&'static str; 2]| {
        let [w, h] = size;
        [
            "render",
            "--backend",
            "cpu",
            "--out",
            "render.exr",
            "--width",
            w,
            "--height",
            h,
        ]
    };
    ok(&splat(&args(["64", "48"]), dir.path()));
    let before = std::fs::read(&out).unwrap();
    let limit = 64 * 512;
    let run = Command::new("sh")
        .arg("-c")
        .arg("ulimit -c 0; ulimit -f 64; exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_splat"))
        .args(args(["320", "240"]))
        .current_dir(dir.path())
        .output()
        .expect("run splat");
    assert_eq!(
        run.status.signal(),
        Some(25), // SIGXFSZ
        "the run should die writing past its file size limit: {run:?}"
    );
    assert_eq!(
        std::fs::read(&out).unwrap(),
        before,
        "the previous output changed"
    );
    let partial: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| *p != out)
        .collect();
    assert_eq!(partial.len(), 1, "{partial:?}");
    let name = partial[0].file_name().unwrap().to_string_lossy();
    assert!(
        name.starts_with(".render.exr-") && name.ends_with(".partial"),
        "{name}"
    );
    assert_eq!(
        std::fs::metadata(&partial[0]).unwrap().len(),
        limit,
        "the kill came mid-write"
    );
}
