//! `splat fit`: training on datasets and on the built-in views, its outputs, strategies, frozen
//! groups, checkpoints and resuming, interruption, and broken datasets refused by name.

use crate::common::*;

#[test]
fn fit_trains_on_a_dataset_and_writes_its_outputs() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = ["fit", "data", "--steps", "20", "--points", "200"];
    let stdout = ok(&splat(&[&args[..], &["--out", "out"]].concat(), dir.path()));
    assert!(
        stdout.contains("3 training and 3 test views of 16x16"),
        "{stdout}"
    );
    assert!(stdout.contains("PSNR"), "{stdout}");
    // Not a terminal: a progress line every 10 steps (a twentieth of the run, rounded up
    // to tens) instead of the bar.
    let lines: Vec<&str> = stdout
        .lines()
        .filter(|l| l.contains(" ms per step, loss "))
        .collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    assert!(lines[0].starts_with("step 10/20: ") && lines[1].starts_with("step 20/20: "));
    step_times_add_up(&stdout);
    let fit = fit_output(&dir.path().join("out"), 3, (16, 16));
    assert_eq!((fit.scene.sh_degree, fit.scene.gaussians.len()), (3, 200));
    // Step 0 (before training), then 20 steps; PSNR before and after only.
    assert_eq!(fit.rows, 21);
    assert_eq!(fit.psnr.iter().map(|p| p.0).collect::<Vec<_>>(), [0, 20]);

    // The same on the GPU loop, where there is an adapter (lavapipe in CI).
    let gpu = splat(
        &[&args[..], &["--out", "gpu", "--backend", "gpu"]].concat(),
        dir.path(),
    );
    if !no_adapter(&gpu) {
        let stdout = String::from_utf8_lossy(&gpu.stdout);
        assert!(stdout.contains("20 steps on the GPU"), "{stdout}");
        step_times_add_up(&stdout);
        let fit = fit_output(&dir.path().join("gpu"), 3, (16, 16));
        assert_eq!(fit.scene.gaussians.len(), 200);
    }
}

/// The table of where `splat fit`'s steps spent their time: the forward and backward blends
/// among its rows (lavapipe has timestamps), and its rows add up to the step (to the
/// rounding of their figures).
fn step_times_add_up(stdout: &str) {
    let rows: Vec<(&str, f64)> = stdout
        .lines()
        .skip_while(|l| !l.starts_with("Where a step's time went (mean of 20 steps"))
        .skip(3)
        .map_while(|l| {
            let cells: Vec<&str> = l.split(" | ").collect();
            let stage = cells.first()?.strip_prefix("| ")?;
            Some((stage, cells.get(1)?.parse().ok()?))
        })
        .collect();
    let (last, stages) = rows.split_last().expect(stdout);
    assert_eq!(last.0, "step", "{stdout}");
    for stage in ["shade", "backward blend"] {
        assert!(stages.iter().any(|s| s.0 == stage), "{stdout}");
    }
    let sum: f64 = stages.iter().map(|s| s.1).sum();
    assert!(
        (sum - last.1).abs() <= 0.005 * rows.len() as f64,
        "{stdout}"
    );
}

/// Ctrl-C during `splat fit` ends the run after the step in progress with its checkpoint and
/// metrics saved (and no result written); `--resume` goes on from that step, and SIGTERM (a
/// batch scheduler's stop) ends it as Ctrl-C does. On both loops (the GPU's where there is an
/// adapter); on the CPU's, resumed to the end, the run ends where one never stopped does.
#[cfg(unix)]
#[test]
fn an_interrupted_fit_saves_its_checkpoint_and_resumes_from_it() {
    use std::io::{BufRead, Read};
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    for (backend, steps) in [("cpu", "2000"), ("gpu", "400")] {
        let args = [
            "fit",
            "data",
            "--steps",
            steps,
            "--points",
            "100",
            "--backend",
            backend,
            "--eval-every",
            "0",
            "--checkpoint-every",
            "100000",
            "--out",
            backend,
        ];
        // Runs `fit`, sends `signal` at its first progress line: the step the stop message
        // names, or None where there is no GPU adapter.
        let interrupted = |extra: &[&str], signal: i32| -> Option<usize> {
            use std::os::unix::process::CommandExt;
            let mut command = Command::new(env!("CARGO_BIN_EXE_splat"));
            // SAFETY: only resets a signal's action between fork and exec. A test run
            // started in the background (`cmd &`) ignores SIGINT, and `fit` keeps an
            // ignored SIGINT ignored, as it should: the child gets the default back.
            unsafe {
                command.pre_exec(move || {
                    libc::signal(signal, libc::SIG_DFL);
                    Ok(())
                });
            }
            let mut child = command
                .args(args.iter().chain(extra))
                .current_dir(dir.path())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap();
            let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
            let first = lines
                .by_ref()
                .map(Result::unwrap)
                .find(|l| l.starts_with("step "));
            if first.is_some() {
                // SAFETY: a plain signal to the child's pid.
                assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0);
            }
            lines.for_each(drop);
            let mut stderr = String::new();
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut stderr)
                .unwrap();
            let status = child.wait().unwrap();
            assert!(
                !status.success() && !stderr.contains("panicked"),
                "{stderr}"
            );
            if first.is_none() && stderr.contains("no GPU adapter") {
                assert!(std::env::var("SPLAT_REQUIRE_GPU").map_or(true, |v| v != "1"));
                return None;
            }
            let name = if signal == libc::SIGTERM {
                "SIGTERM"
            } else {
                "Ctrl-C"
            };
            let stop = format!("stopped by {name} after step ");
            let step: usize = (stderr.split(&stop).nth(1))
                .and_then(|rest| rest.split(' ').next())
                .and_then(|k| k.parse().ok())
                .unwrap_or_else(|| panic!("no stop message in {stderr}"));
            assert!(
                stderr.contains("the same command with --resume goes on"),
                "{stderr}"
            );
            Some(step)
        };
        let out = dir.path().join(backend);
        // The metrics' last step: one row per step from 0.
        let last_row = || {
            let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
            let steps: Vec<usize> = (csv.lines().skip(1))
                .map(|l| l.split(',').next().unwrap().parse().unwrap())
                .collect();
            assert_eq!(steps, (0..steps.len()).collect::<Vec<_>>());
            steps.len() - 1
        };
        let Some(first) = interrupted(&[], libc::SIGINT) else {
            continue;
        };
        assert!(first < steps.parse().unwrap(), "{backend}");
        assert!(out.join("checkpoint.bin").exists());
        assert!(
            !out.join("scene.ply").exists() && !out.join("test").exists(),
            "an interrupted run wrote its result, or left a folder for it"
        );
        assert_eq!(last_row(), first);
        // Resumed, it goes on from there: its metrics continue the first run's, row for row.
        let second = interrupted(&["--resume"], libc::SIGTERM).unwrap();
        assert!(second > first, "{backend}: {second} after {first}");
        assert_eq!(last_row(), second);
        if backend == "cpu" {
            // Resumed to the end, twice stopped, the CPU's run ends on the very scene of a run
            // never stopped (the GPU's adds its gradients in the atomics' order).
            ok(&splat(&[&args[..], &["--resume"]].concat(), dir.path()));
            let whole = [&args[..args.len() - 1], &["whole"]].concat();
            ok(&splat(&whole, dir.path()));
            let scene = |run: &str| std::fs::read(dir.path().join(run).join("scene.ply")).unwrap();
            assert!(
                scene("cpu") == scene("whole"),
                "the resumed run's scene differs"
            );
            assert_eq!(last_row(), steps.parse::<usize>().unwrap());
        }
    }
}

/// `--strategy mcmc` starts the primitives as the MCMC paper does (opacity 0.5, not 3DGS's
/// 0.1) and trains; `--strategy fixed` keeps the count; an unknown strategy is refused.
#[test]
fn fit_takes_a_strategy() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = [
        "fit",
        "data",
        "--steps",
        "5",
        "--points",
        "100",
        "--backend",
        "cpu",
    ];
    let median_opacity = |out: &str| {
        let fit = fit_output(&dir.path().join(out), 3, (16, 16));
        let mut o: Vec<f32> = (fit.scene.gaussians.iter())
            .map(|g| 1.0 / (1.0 + (-g.opacity_logit).exp()))
            .collect();
        o.sort_by(f32::total_cmp);
        (o.len(), o[o.len() / 2])
    };
    for (strategy, out) in [("mcmc", "mcmc"), ("adc", "adc"), ("fixed", "fixed")] {
        let run = [&args[..], &["--strategy", strategy, "--out", out]].concat();
        ok(&splat(&run, dir.path()));
    }
    let (mcmc, adc) = (median_opacity("mcmc"), median_opacity("adc"));
    assert_eq!((mcmc.0, adc.0, median_opacity("fixed").0), (100, 100, 100));
    assert!(
        mcmc.1 > 0.4 && adc.1 < 0.2,
        "median opacity: MCMC {mcmc:?}, ADC {adc:?}"
    );
    let bad = splat(&[&args[..], &["--strategy", "greedy"]].concat(), dir.path());
    assert!(!bad.status.success());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(
        stderr.contains("possible values: adc, mcmc, fixed"),
        "{stderr}"
    );
}

/// `--freeze` keeps the named groups as they start and says which are trained; an unknown
/// group, or a frozen shape under density control, is refused by name.
#[test]
fn fit_freezes_the_groups_it_is_told_to() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = ["fit", "data", "--points", "100", "--backend", "cpu"];
    let shapes = ["--freeze", "mean,log_scale,rotation", "--strategy", "fixed"];
    let mut scenes = vec![];
    for steps in ["1", "5"] {
        let out = format!("frozen{steps}");
        let run = [&args[..], &shapes, &["--steps", steps, "--out", &out]].concat();
        let stdout = ok(&splat(&[&run[..], &["--explain"]].concat(), dir.path()));
        assert!(
            stdout.contains("training opacity_logit, sh; frozen: mean, log_scale, rotation"),
            "{stdout}"
        );
        // --explain names the gradients the backward pass computes and those it never does.
        let gradients = "gradients         opacity_logit, sh (never computed: mean, log_scale, rotation)\ncamera gradient   off (no ray adjoint per pixel)\nalpha cotangent   on";
        assert!(stdout.contains(gradients), "{stdout}");
        assert!(stdout.contains("density control   fixed"), "{stdout}");
        scenes.push(
            fit_output(&dir.path().join(&out), 3, (16, 16))
                .scene
                .gaussians,
        );
    }
    for (a, b) in scenes[0].iter().zip(&scenes[1]) {
        assert_eq!(
            (a.mean, a.log_scale, a.rotation),
            (b.mean, b.log_scale, b.rotation)
        );
    }
    assert!(scenes[0].iter().zip(&scenes[1]).any(|(a, b)| a.sh != b.sh));
    // Colors alone: no gradient flows through alpha, so the blend skips its cotangent.
    let colors = [
        &args[..],
        &["--freeze", "mean,log_scale,rotation,opacity_logit"],
        &[
            "--strategy",
            "fixed",
            "--steps",
            "1",
            "--out",
            "colors",
            "--explain",
        ],
    ]
    .concat();
    let stdout = ok(&splat(&colors, dir.path()));
    let alpha = "alpha cotangent   off (no gradient asked for flows through alpha)";
    assert!(stdout.contains(alpha), "{stdout}");
    let refused = |extra: &[&str], message: &str| {
        let run = [&args[..], &["--steps", "1", "--out", "refused"], extra].concat();
        fails(
            &splat(&run, dir.path()),
            message,
            &dir.path().join("refused/scene.ply"),
        );
    };
    refused(
        &["--freeze", "sh,colour"],
        "--freeze colour: 3dgs has no parameter group `colour`; its groups are mean, log_scale, rotation, opacity_logit, sh",
    );
    refused(
        &["--freeze", "log_scale"],
        "log_scale cannot stay frozen under density control (adc)",
    );
    // Checked before the dataset is read: a missing one is not what the error is about.
    let before_reading = ["fit", "nowhere", "--freeze", "colour", "--out", "refused"];
    fails(
        &splat(&before_reading, dir.path()),
        "--freeze colour: 3dgs has no parameter group",
        &dir.path().join("refused/scene.ply"),
    );
    refused(
        &[
            "--strategy",
            "fixed",
            "--freeze",
            "sh,mean,log_scale,rotation,opacity_logit",
        ],
        "--freeze mean,log_scale,rotation,opacity_logit,sh: those are all of 3dgs's parameter groups, which leaves nothing to train",
    );
    refused(
        &["--strategy", "fixed", "--max-primitives", "5"],
        "--max-primitives 5: the cap is on density control's growth, and --strategy fixed keeps the primitives it starts with",
    );
}

/// With no dataset, `splat fit` trains on views of the built-in planet; the test views are
/// measured every `--eval-every` steps, and training brings them closer.
#[test]
fn fit_without_a_dataset_trains_on_the_built_in_one() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "fit",
        "--backend",
        "cpu",
        "--steps",
        "60",
        "--points",
        "400",
        "--eval-every",
        "20",
    ];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("the built-in dataset: 28 training and 4 test views of 112x84"),
        "{stdout}"
    );
    let fit = fit_output(&dir.path().join("fit"), 4, (112, 84));
    assert_eq!(fit.rows, 61);
    let steps: Vec<usize> = fit.psnr.iter().map(|p| p.0).collect();
    assert_eq!(steps, [0, 20, 40, 60]);
    let (before, after) = (fit.psnr[0].1, fit.psnr[3].1);
    assert!(after > before + 3.0, "test PSNR {before} -> {after}");
}

/// `--resume` goes on from <out>/checkpoint.bin and keeps the metrics up to it; a checkpoint
/// of another run length, of another method, or damaged is refused by name.
#[test]
fn fit_resumes_from_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = ["fit", "data", "--points", "50", "--out", "out"];
    let first = [
        &args[..],
        &[
            "--steps",
            "20",
            "--checkpoint-every",
            "10",
            "--eval-every",
            "10",
        ],
    ]
    .concat();
    ok(&splat(&first, dir.path()));
    let out = dir.path().join("out");
    assert!(out.join("checkpoint.bin").exists());
    let stdout = ok(&splat(&[&args[..], &["--resume"]].concat(), dir.path()));
    assert!(
        stdout.contains("resuming from out/checkpoint.bin after step 20 of 20"),
        "{stdout}"
    );
    assert!(!stdout.contains("warning"), "{stdout}");
    let fit = fit_output(&out, 3, (16, 16));
    assert_eq!(fit.rows, 21);
    let steps: Vec<usize> = fit.psnr.iter().map(|p| p.0).collect();
    assert_eq!(steps, [0, 10, 20]);
    // Metrics cut short (edited since): the run resumes and says what its log misses.
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let cut: Vec<&str> = csv.lines().take(12).collect();
    std::fs::write(out.join("metrics.csv"), cut.join("\n")).unwrap();
    let stdout = ok(&splat(&[&args[..], &["--resume"]].concat(), dir.path()));
    assert!(
        stdout.contains(
            "warning: out/metrics.csv holds 10 of the checkpoint's 20 steps: the resumed run's metrics miss the others"
        ),
        "{stdout}"
    );
    // A start above the cap runs: the cap only stops growth.
    let capped = [
        "fit", "data", "--points", "50", "--out", "capped", "--steps", "2",
    ];
    let stdout = ok(&splat(
        &[&capped[..], &["--max-primitives", "1"]].concat(),
        dir.path(),
    ));
    assert!(
        stdout.contains("more than --max-primitives 1: the cap only stops growth"),
        "{stdout}"
    );

    let scene = std::fs::read(out.join("scene.ply")).unwrap();
    let refused = |extra: &[&str], needle: &str| {
        let out = splat(&[&args[..], &["--resume"], extra].concat(), dir.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(stderr.contains(needle), "{stderr}");
    };
    refused(
        &["--steps", "30"],
        "out/checkpoint.bin is a checkpoint of a 20-step run",
    );
    refused(
        &["--method", "3dgut"],
        "out/checkpoint.bin is a checkpoint of 3dgs, not of 3dgut",
    );
    refused(
        &["--strategy", "mcmc"],
        "out/checkpoint.bin is a checkpoint of a run with --strategy adc, not mcmc",
    );
    refused(
        &["--no-opacity-reset"],
        "a run with --strategy adc, not adc without opacity resets",
    );
    refused(&["--global-scale", "0.5"], "a run with scene extent");
    // Settings that change the steps: resumed with others, the run would train another way.
    let was = "a run on background 0 0 0, at most 4000000 primitives";
    refused(&["--white"], &format!("{was}, not on background 1 1 1,"));
    refused(
        &["--max-primitives", "1"],
        &format!("{was}, not on background 0 0 0, at most 1 primitives"),
    );
    refused(
        &["--freeze", "sh"],
        "not on background 0 0 0, at most 4000000 primitives, with sh frozen",
    );
    // Another batch is refused before the metrics are read in its batches (which would warn
    // of rows missing).
    let batched = splat(
        &[&args[..], &["--resume", "--batch", "2"]].concat(),
        dir.path(),
    );
    let stderr = String::from_utf8_lossy(&batched.stderr);
    assert!(!batched.status.success());
    assert!(stderr.contains("in batches of 2 views"), "{stderr}");
    let stdout = String::from_utf8_lossy(&batched.stdout);
    assert!(!stdout.contains("warning"), "{stdout}");
    // One bit changed in the parameters, past the header.
    let mut checkpoint = std::fs::read(out.join("checkpoint.bin")).unwrap();
    let at = checkpoint.len() / 2;
    checkpoint[at] ^= 1;
    std::fs::write(out.join("checkpoint.bin"), checkpoint).unwrap();
    refused(
        &[],
        "out/checkpoint.bin is damaged: its bytes do not match the checksum",
    );
    std::fs::write(out.join("checkpoint.bin"), "SPLATCK3 and then nothing").unwrap();
    refused(&[], "out/checkpoint.bin is damaged");
    for older in ["SPLATCK1", "SPLATCK2"] {
        std::fs::write(
            out.join("checkpoint.bin"),
            format!("{older} and then nothing"),
        )
        .unwrap();
        refused(&[], "out/checkpoint.bin was written by an earlier splat");
    }
    std::fs::write(out.join("checkpoint.bin"), "ply").unwrap();
    refused(&[], "out/checkpoint.bin is not a splat checkpoint");
    assert_eq!(
        std::fs::read(out.join("scene.ply")).unwrap(),
        scene,
        "nothing lost"
    );
}

#[test]
fn fit_refuses_a_missing_or_broken_dataset_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    fails(
        &splat(&["fit", "nowhere"], dir.path()),
        "cannot read nowhere: no such folder",
        &out,
    );
    std::fs::create_dir(dir.path().join("empty")).unwrap();
    fails(
        &splat(&["fit", "empty"], dir.path()),
        "neither transforms_train.json (Blender) nor transforms.json (nerfstudio)",
        &out,
    );
    tiny_dataset(&dir.path().join("data"), 2);
    std::fs::write(dir.path().join("data/transforms_test.json"), "{").unwrap();
    fails(
        &splat(&["fit", "data", "--steps", "2"], dir.path()),
        "transforms_test.json is not valid JSON",
        &out,
    );
    write(dir.path(), "file", b"");
    fails(
        &splat(&["fit", "file"], dir.path()),
        "cannot read file: a dataset is a folder, this is a file",
        &out,
    );
    tiny_dataset(&dir.path().join("bent"), 2);
    let json = dir.path().join("bent/transforms_train.json");
    let text = std::fs::read_to_string(&json).unwrap();
    std::fs::write(&json, text.replacen("[0, 1, 0, 0]", "[0, 2, 0, 0]", 1)).unwrap();
    fails(
        &splat(&["fit", "bent", "--steps", "2"], dir.path()),
        "transforms_train.json: frames[0].transform_matrix is not a rigid pose",
        &out,
    );
    tiny_dataset(&dir.path().join("small"), 2);
    let eight = image::RgbaImage::from_pixel(8, 8, image::Rgba([90, 120, 150, 255]));
    for split in ["train", "test"] {
        for k in 0..2 {
            eight
                .save(dir.path().join(format!("small/{split}/r_{k}.png")))
                .unwrap();
        }
    }
    fails(
        &splat(&["fit", "small", "--steps", "2"], dir.path()),
        "r_0.png is 8x8 pixels: training takes views of 11",
        &out,
    );
    tiny_dataset(&dir.path().join("good"), 2);
    fails(
        &splat(&["fit", "good", "--out", "file"], dir.path()),
        "--out file: it is a file",
        &out,
    );
    fails(
        &splat(&["fit", "good", "--out", "file/run"], dir.path()),
        "--out file/run: file is a file",
        &out,
    );
    // Found before training, not when the results are written at its end.
    std::fs::create_dir_all(dir.path().join("run/scene.ply")).unwrap();
    fails(
        &splat(&["fit", "good", "--out", "run"], dir.path()),
        "--out run: run/scene.ply is a folder, and the run writes its scene.ply there",
        &out,
    );
    // Refused before the dataset is read (this one does not exist).
    for (flag, value) in [
        ("--global-scale", "0"),
        ("--init-extent", "nan"),
        ("--init-size", "0"),
    ] {
        fails(
            &splat(&["fit", "missing", "--steps", "2", flag, value], dir.path()),
            &format!("{flag} must be a positive number, not"),
            &out,
        );
    }
    fails(
        &splat(&["fit", "missing", "--points", "0"], dir.path()),
        "--points must be at least 1",
        &out,
    );
    for color in ["0.5,0.5", "0.5,2,0.5", "gray"] {
        fails(
            &splat(&["fit", "good", "--init-color", color], dir.path()),
            &format!("`{color}` is not R,G,B"),
            &out,
        );
    }
    fails(
        &splat(
            &["fit", "good", "--strategy", "mcmc", "--no-opacity-reset"],
            dir.path(),
        ),
        "--no-opacity-reset is for --strategy adc",
        &out,
    );
}

#[test]
fn fit_starts_from_a_colmap_datasets_points() {
    let dir = tempfile::tempdir().unwrap();
    tiny_colmap_dataset(&dir.path().join("data"));
    let args = ["fit", "data", "--steps", "5", "--out", "out"];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("2 training and 1 test view of 16x16"),
        "{stdout}"
    );
    assert!(
        stdout.contains("starting from 40 of the dataset's 40 points"),
        "{stdout}"
    );
    let cloud = splat_runtime::io::ply::read(&dir.path().join("out/scene.ply")).unwrap();
    assert_eq!(cloud.gaussians.len(), 40);

    // --points caps the count.
    let args = [
        "fit", "data", "--steps", "1", "--points", "10", "--out", "out",
    ];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("starting from 10 of the dataset's 40 points"),
        "{stdout}"
    );

    // A lens with distortion: the views are cut from the pictures, and fit says so.
    let cameras = dir.path().join("data/sparse/0/cameras.txt");
    std::fs::write(cameras, "1 SIMPLE_RADIAL 16 16 20 8 8 0.2\n").unwrap();
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains(
            "1 test view of 14x14 (the lens distortion of 3 pictures taken out, 16x16 cropped to 14x14)"
        ),
        "{stdout}"
    );
}
