//! `splat fit` under a real `mpirun` (OpenMPI; the CLI built with its `mpi` feature): ranks
//! that share each batch train the scene one process trains, bit for bit on the CPU and to the
//! same quality on GPUs; a killed rank ends the run within seconds and `--resume` goes on;
//! ranks that cannot read the dataset, or were given other settings, are refused before the
//! first step.

use super::common::*;
use std::time::{Duration, Instant};

/// `mpirun` with `ranks` ranks running `splat args` (as root where CI runs, one thread each:
/// the CPU backward's sums follow the thread count, so one process runs one thread too), or
/// `None` where there is none (a failure with `SPLAT_REQUIRE_MPI=1`).
fn mpirun(ranks: &[(usize, &[&str])], dir: &Path) -> Option<Command> {
    let found = Command::new("mpirun").arg("--version").output();
    let found = found.is_ok_and(|o| o.status.success()).then_some(());
    required(found, "SPLAT_REQUIRE_MPI", "no mpirun")?;
    let mut c = Command::new("mpirun");
    c.args(["--oversubscribe", "-x", "RAYON_NUM_THREADS"]);
    // MPMD: each part its own ranks and command line, `:` between them.
    for (k, (n, args)) in ranks.iter().enumerate() {
        if k > 0 {
            c.arg(":");
        }
        c.args(["-n", &n.to_string(), env!("CARGO_BIN_EXE_splat")])
            .args(*args);
    }
    c.current_dir(dir)
        .env("RAYON_NUM_THREADS", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    Some(c)
}

/// One process, one thread, as the ranks run.
fn alone(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_splat"))
        .args(args)
        .current_dir(dir)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap()
}

/// A densifying run on the built-in dataset: 640 views in batches of 4, density control's
/// refinement at step 600 (its statistics gathered from every rank), into `out`.
fn run(out: &str) -> Vec<&str> {
    let args = "fit --method 3dgs --backend cpu --steps 640 --batch 4 --checkpoint-every 80";
    let mut args: Vec<&str> = args.split(' ').collect();
    args.extend(["--out", out]);
    args
}

fn same_files(a: &Path, b: &Path) {
    for name in ["scene.ply", "metrics.csv"] {
        let (x, y) = (a.join(name), b.join(name));
        assert!(
            std::fs::read(&x).unwrap() == std::fs::read(&y).unwrap(),
            "{} and {} differ",
            x.display(),
            y.display()
        );
    }
}

/// Both ways of sharing a run: ranks that each hold the whole scene and share each batch's
/// views, and ranks that each hold a slice of the scene (`--sharded`) and exchange the views'
/// visible primitives and their gradients.
#[test]
fn two_ranks_sharing_each_batch_train_the_scene_one_process_trains_bit_for_bit() {
    let dir = temp();
    let Some(mut two) = mpirun(&[(2, &run("two"))], dir.path()) else {
        return;
    };
    let one = ok(&alone(&run("one"), dir.path()));
    let two = ok(&two.output().unwrap());
    same_files(&dir.path().join("one"), &dir.path().join("two"));
    assert!(two.contains("on the CPUs of 2 MPI ranks"), "{two}");
    assert!(two.contains("per batch"), "{two}");
    let sharded = [&run("sharded")[..], &["--sharded"]].concat();
    let sharded = ok(&mpirun(&[(2, &sharded)], dir.path())
        .unwrap()
        .output()
        .unwrap());
    same_files(&dir.path().join("one"), &dir.path().join("sharded"));
    assert!(
        sharded.contains("each with a slice of the scene"),
        "{sharded}"
    );
    assert!(
        sharded.contains("each rank held 1/2 of the scene"),
        "{sharded}"
    );
    // Density control acted on the gathered statistics.
    let primitives = fit_output(&dir.path().join("one"), 4, (112, 84))
        .scene
        .gaussians
        .len();
    assert_ne!(primitives, 2000, "{one}");
}

/// On GPUs (lavapipe in CI, one device per rank) each rank sums its views' gradients on its
/// device and the ranks add the sums, or (`--sharded`) each rank holds a slice of the scene
/// on its device and the ranks exchange the views' records: not bit for bit (a device's sums
/// are in no fixed order), but the same training: the held-out PSNR of 200 views in batches
/// of 2 within 0.1 dB of one GPU process's.
#[test]
fn two_gpu_ranks_train_like_one_gpu_process() {
    let dir = temp();
    let args = |out| {
        let args = "fit --method 3dgs --backend gpu --steps 200 --batch 2 --eval-every 0 --out";
        let mut args: Vec<&str> = args.split(' ').collect();
        args.push(out);
        args
    };
    let one = splat(&args("one"), dir.path());
    if no_adapter(&one) {
        return;
    }
    ok(&one);
    let Some(mut two) = mpirun(&[(2, &args("two"))], dir.path()) else {
        return;
    };
    let two = ok(&two.env_remove("XDG_RUNTIME_DIR").output().unwrap());
    assert!(two.contains("on the GPUs of 2 MPI ranks"), "{two}");
    let sharded = [&args("sharded")[..], &["--sharded"]].concat();
    let mut sharded = mpirun(&[(2, &sharded)], dir.path()).unwrap();
    let sharded = ok(&sharded.env_remove("XDG_RUNTIME_DIR").output().unwrap());
    assert!(
        sharded.contains("each with a slice of the scene"),
        "{sharded}"
    );
    let psnr = |out: &str| {
        let psnr = fit_output(&dir.path().join(out), 4, (112, 84)).psnr;
        psnr.last().unwrap().1
    };
    let one = psnr("one");
    for run in ["two", "sharded"] {
        let two = psnr(run);
        assert!(
            (one - two).abs() < 0.1,
            "one process {one} dB, two ranks ({run}) {two} dB"
        );
    }
}

#[test]
fn a_killed_rank_ends_the_run_within_seconds_and_resume_goes_on_to_the_same_scene() {
    let dir = temp();
    let Some(mut killed) = mpirun(&[(2, &run("killed"))], dir.path()) else {
        return;
    };
    let mut launch = (killed.stdout(std::process::Stdio::null()))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let checkpoint = dir.path().join("killed/checkpoint.bin");
    let started = Instant::now();
    while !checkpoint.exists() {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no checkpoint"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let rank_1 = rank_pid(launch.id(), 1);
    unsafe { libc::kill(rank_1 as i32, libc::SIGKILL) };
    let killed_at = Instant::now();
    let ended = loop {
        if let Some(status) = launch.try_wait().unwrap() {
            break status;
        }
        assert!(
            killed_at.elapsed() < Duration::from_secs(30),
            "rank 0 still runs 30 s after rank 1 was killed"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let waited = killed_at.elapsed();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut launch.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(!ended.success());
    assert!(
        stderr.contains("rank 1") && stderr.contains("signal 9"),
        "{stderr}"
    );
    eprintln!(
        "the run ended {:.1} s after rank 1 was killed",
        waited.as_secs_f64()
    );
    assert!(waited < Duration::from_secs(10), "{waited:?}");

    // The checkpoint is whole, and the same command with --resume ends where an
    // uninterrupted run ends.
    let mut resume = run("killed");
    resume.push("--resume");
    let resumed = ok(&mpirun(&[(2, &resume)], dir.path())
        .unwrap()
        .output()
        .unwrap());
    assert!(resumed.contains("resuming from"), "{resumed}");
    ok(&alone(&run("whole"), dir.path()));
    same_files(&dir.path().join("whole"), &dir.path().join("killed"));
}

/// Ctrl-C on `mpirun` (which sends the ranks SIGTERM) ends every rank after the same batch:
/// rank 0 writes that batch's checkpoint and says so, once, and no rank aborts.
#[test]
fn ctrl_c_on_mpirun_ends_every_rank_after_one_batch_with_its_checkpoint() {
    let dir = temp();
    let mut args = run("stopped");
    let steps = args.iter().position(|a| *a == "640").unwrap();
    args[steps] = "100000";
    let Some(mut c) = mpirun(&[(2, &args)], dir.path()) else {
        return;
    };
    let launch = (c.stdout(std::process::Stdio::piped()))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Stopped once the ranks train.
    std::thread::sleep(Duration::from_secs(8));
    unsafe { libc::kill(launch.id() as i32, libc::SIGINT) };
    let out = launch.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let needle = "stopped by SIGTERM after step ";
    assert_eq!(stderr.matches(needle).count(), 1, "{stderr}");
    assert!(!stderr.contains("MPI_ABORT"), "{stderr}");
    let step: usize = (stderr
        .split(needle)
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap())
    .parse()
    .unwrap();
    assert!(step > 0 && step.is_multiple_of(4), "{stderr}");
    let checkpoint = dir.path().join("stopped/checkpoint.bin");
    let saved = splat_runtime::train::Checkpoint::read(&checkpoint).unwrap();
    assert_eq!(saved.step, step);
}

/// The process id of rank `rank` among the children of `mpirun` (`launcher`).
fn rank_pid(launcher: u32, rank: usize) -> u32 {
    let started = Instant::now();
    loop {
        for entry in std::fs::read_dir("/proc").unwrap().flatten() {
            let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
                continue;
            };
            let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
            // The parent's pid is the fourth field, after the name in parentheses.
            let parent = stat
                .rsplit(')')
                .next()
                .and_then(|r| r.split_whitespace().nth(1));
            let environ = std::fs::read(entry.path().join("environ")).unwrap_or_default();
            let wanted = format!("OMPI_COMM_WORLD_RANK={rank}");
            let is_rank = (environ.split(|b| *b == 0)).any(|v| v == wanted.as_bytes());
            if parent == Some(&launcher.to_string()) && is_rank {
                return pid;
            }
        }
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "no rank {rank}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn ranks_that_cannot_read_the_dataset_or_were_given_other_settings_are_refused_before_training() {
    let dir = temp();
    tiny_dataset(&dir.path().join("tiny"), 3);
    let fit = |dataset: Option<&'static str>, batch: &'static str| {
        let mut args = vec![
            "fit",
            "--method",
            "3dgs",
            "--backend",
            "cpu",
            "--out",
            "out",
        ];
        args.extend(dataset);
        args.extend(["--batch", batch]);
        args
    };
    let cases: [(Vec<&str>, Vec<&str>, &str); 3] = [
        (
            fit(None, "2"),
            fit(Some("missing"), "2"),
            "1 of 2 ranks could not get dataset:\n  rank 1:",
        ),
        (
            fit(None, "2"),
            fit(Some("tiny"), "2"),
            "rank 1 has another dataset than rank 0",
        ),
        (
            fit(None, "2"),
            fit(None, "4"),
            "rank 1 has another run than rank 0: give every rank the same command line",
        ),
    ];
    for (first, second, needle) in cases {
        let Some(mut c) = mpirun(&[(1, &first), (1, &second)], dir.path()) else {
            return;
        };
        let out = c.output().unwrap();
        fails(&out, needle, &dir.path().join("out/scene.ply"));
        // Rank 0 says it, once.
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.matches(needle).count(), 1, "{stderr}");
    }
}
