//! Whether a dataset's views, and training on them, fit in the host memory left, checked
//! from the pictures' headers before any is decoded: a dataset too big is refused with the
//! `--downscale` that fits, instead of loading for minutes and being killed by the kernel.
//! Likewise the points a run starts from, the views `splat dataset` renders, and a render.

use anyhow::{Result, bail};
use splat_runtime::io::dataset::{Footprint, Shots};
use splat_runtime::train::fit::CPU_STEP_BYTES_PER_PIXEL;
use std::path::Path;

/// The largest `--downscale` suggested.
const LARGEST_FACTOR: u32 = 32;

/// What a run takes of host memory at its peak.
#[derive(Clone, Copy, Debug)]
pub struct Demand {
    /// Pictures decoded at a time while loading.
    pub threads: usize,
    /// Bytes per pixel of its view that a training step takes on the host; `None` where
    /// training runs on a GPU.
    pub step: Option<u64>,
}

impl Demand {
    /// The peak for views of footprint `f`: loading them, or training on them.
    fn of(&self, f: &Footprint) -> u64 {
        let training = self.step.map_or(0, |s| f.training(s));
        f.peak(self.threads).max(training)
    }
}

/// Refuses `chosen`, the dataset's shots `full` taken `factor` times smaller, when loading or
/// training on them would take more than `room` bytes; the error names the smallest larger
/// factor that fits.
pub fn check_room(
    name: &str,
    (full, chosen): (&Shots, &Shots),
    factor: u32,
    room: u64,
    demand: Demand,
) -> Result<()> {
    let views = chosen.train.len() + chosen.test.len();
    let demand = Demand {
        threads: demand.threads.clamp(1, views.max(1)),
        ..demand
    };
    let footprint = |f: u32| -> Result<Footprint> { Ok(full.clone().downscaled(f)?.footprint()?) };
    let need = chosen.footprint()?;
    if demand.of(&need) <= room {
        return Ok(());
    }
    let mut suggestion = format!("not even --downscale {factor} fits");
    for f in factor + 1..=LARGEST_FACTOR {
        // A factor that leaves a picture without a pixel is no suggestion.
        let Ok(smaller) = footprint(f) else { break };
        suggestion = format!("not even --downscale {f} fits");
        if demand.of(&smaller) <= room {
            let peak = bytes(demand.of(&smaller));
            suggestion = format!("--downscale {f} would take about {peak}");
            break;
        }
    }
    let (held, room) = (bytes(need.held), bytes(room));
    let threads = demand.threads;
    let why = match demand.step {
        Some(step) if need.training(step) > need.peak(threads) => format!(
            "training on its {views} views on the CPU takes about {} of memory ({held} held by the views, {} for a step on the largest, of {} pixels)",
            bytes(need.training(step)),
            bytes(step * need.largest),
            need.largest,
        ),
        _ => format!(
            "loading its {views} views takes about {} of memory ({held} held by the views for the run, up to {} for each of the {threads} pictures decoded at a time)",
            bytes(need.peak(threads)),
            bytes(need.decoding),
        ),
    };
    bail!("{name}: {why}, and {room} is available: {suggestion}")
}

/// Copies of each primitive's words that training holds: the primitives, their words as the
/// optimizer sees them, the step's gradient of each, Adam's two moments, and one more for the
/// frame's per-primitive data.
const PRIMITIVE_COPIES: u64 = 6;

/// Refuses to start training from `primitives` primitives of `words` 4-byte words each when
/// holding them would take more than `room` bytes.
pub fn check_start(primitives: usize, words: usize, room: u64) -> Result<()> {
    let need = (primitives as u64)
        .saturating_mul(words as u64 * 4)
        .saturating_mul(PRIMITIVE_COPIES);
    if need > room {
        bail!(
            "--points {primitives}: training {primitives} primitives of {words} words takes about {} of memory, and {} is available",
            bytes(need),
            bytes(room)
        );
    }
    Ok(())
}

/// Bytes per pixel a rendered view holds until `splat dataset` writes them all: f32 RGB
/// and coverage.
const RENDERED_VIEW_BYTES_PER_PIXEL: u64 = 16;

/// Refuses to render `views` views of `width` x `height` pixels for a dataset when holding
/// them (and rendering one more) would take more than `room` bytes.
pub fn check_rendered_views(views: usize, width: u32, height: u32, room: u64) -> Result<()> {
    let pixels = u64::from(width) * u64::from(height);
    let need = (views as u64)
        .saturating_mul(pixels)
        .saturating_mul(RENDERED_VIEW_BYTES_PER_PIXEL)
        .saturating_add(pixels * CPU_STEP_BYTES_PER_PIXEL);
    if need > room {
        bail!(
            "--views {views} of {width}x{height}: the views are held until the dataset is written, about {} of memory, and {} is available",
            bytes(need),
            bytes(room)
        );
    }
    Ok(())
}

/// Bytes per pixel a render takes on the host at its peak: the frame's outputs, the tiles'
/// lists and the encoded file. Measured on the built-in scene between 4096 and 8192 pixels
/// square (peak resident memory): 59 for color written as PNG, 76 with depth and alpha written
/// as EXR.
const RENDER_BYTES_PER_PIXEL: u64 = 80;

/// Refuses to render a `width` x `height` frame when it would take more than `room` bytes.
pub fn check_render(width: u32, height: u32, room: u64) -> Result<()> {
    let need = u64::from(width) * u64::from(height) * RENDER_BYTES_PER_PIXEL;
    if need > room {
        bail!(
            "rendering {width}x{height} pixels takes about {} of memory, and {} is available",
            bytes(need),
            bytes(room)
        );
    }
    Ok(())
}

/// A size for people: "1.4 TB", "12.3 GB", "450.0 MB", "36.9 kB".
fn bytes(n: u64) -> String {
    let (scale, unit) = match n {
        n if n >= 1_000_000_000_000 => (1e12, "TB"),
        n if n >= 1_000_000_000 => (1e9, "GB"),
        n if n >= 1_000_000 => (1e6, "MB"),
        _ => (1e3, "kB"),
    };
    format!("{:.1} {unit}", n as f64 / scale)
}

/// The bytes this process can still take from the host: the kernel's estimate of what is
/// available without swapping, plus free swap, and no more than its control groups' memory
/// limits leave. `None` where the system says nothing (not Linux).
pub fn available() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let field = |name: &str| -> Option<u64> {
        let line = meminfo
            .lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(':'))?;
        let kilobytes: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
        Some(kilobytes * 1024)
    };
    let system = field("MemAvailable")? + field("SwapFree").unwrap_or(0);
    Some(cgroup_room().map_or(system, |room| room.min(system)))
}

/// This process's peak resident memory so far, in bytes (`VmHWM`); `None` where the system
/// does not say (not Linux).
pub fn peak_resident() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    let kilobytes: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    Some(kilobytes * 1024)
}

/// The least room this process's control groups leave under their memory limits (cgroup v2,
/// or v1's memory controller); `None` where none sets one.
fn cgroup_room() -> Option<u64> {
    let cgroups = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let mut least = None;
    // Lines are `id:controllers:path`; v2's has no controllers.
    for line in cgroups.lines() {
        let mut fields = line.splitn(3, ':').skip(1);
        let (Some(controllers), Some(own)) = (fields.next(), fields.next()) else {
            continue;
        };
        let (root, files) = match controllers {
            "" => ("/sys/fs/cgroup", ["memory.max", "memory.current"]),
            c if c.split(',').any(|c| c == "memory") => (
                "/sys/fs/cgroup/memory",
                ["memory.limit_in_bytes", "memory.usage_in_bytes"],
            ),
            _ => continue,
        };
        let room = room_under(Path::new(root), own, files);
        least = lesser(least, room);
    }
    least
}

/// The least room the group at `own` under `root`, or any of its ancestors (a limit
/// anywhere above binds too), leaves: its limit less its use, as `files` name them.
fn room_under(root: &Path, own: &str, [limit, usage]: [&str; 2]) -> Option<u64> {
    let read = |dir: &Path, file: &str| -> Option<u64> {
        // v2 writes "max" where there is no limit, which parses as none.
        std::fs::read_to_string(dir.join(file))
            .ok()?
            .trim()
            .parse()
            .ok()
    };
    let mut dir = root.join(own.trim_start_matches('/'));
    let mut least: Option<u64> = None;
    loop {
        if let (Some(max), Some(used)) = (read(&dir, limit), read(&dir, usage)) {
            least = lesser(least, Some(max.saturating_sub(used)));
        }
        if dir == root || !dir.pop() {
            return least;
        }
    }
}

/// The lesser of two bounds, either of which may be missing.
fn lesser(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_runtime::glam::Vec2;
    use splat_runtime::io::dataset::Shot;
    use splat_runtime::types::Camera;

    /// 3 views of 64 x 48 8-bit pictures hold 4 bytes per pixel.
    fn shots(dir: &Path) -> Shots {
        let (w, h) = (64, 48);
        let shot = |k: usize| {
            let path = dir.join(format!("{k}.png"));
            image::RgbImage::new(w, h).save(&path).unwrap();
            let camera = Camera {
                size: Vec2::new(w as f32, h as f32),
                ..Default::default()
            };
            Shot::new(path, camera)
        };
        Shots {
            train: (0..2).map(shot).collect(),
            test: vec![shot(2)],
            points: vec![],
        }
    }

    /// Loading with 2 pictures decoded at a time, training on a GPU.
    const LOADING: Demand = Demand {
        threads: 2,
        step: None,
    };

    #[test]
    fn a_dataset_is_refused_with_the_downscale_that_fits() {
        let dir = tempfile::tempdir().unwrap();
        let shots = shots(dir.path());
        let peak = |f| {
            shots
                .clone()
                .downscaled(f)
                .unwrap()
                .footprint()
                .unwrap()
                .peak(2)
        };
        let (full, half, third) = (peak(1), peak(2), peak(3));
        assert!(full > half && half > third, "{full} {half} {third}");
        check_room("d", (&shots, &shots), 1, full, LOADING).unwrap();
        let err = check_room("d", (&shots, &shots), 1, half, LOADING)
            .unwrap_err()
            .to_string();
        let held = bytes(3 * 64 * 48 * 4);
        let want = format!(
            "d: loading its 3 views takes about {} of memory ({held} held by the views for the run",
            bytes(full)
        );
        assert!(err.starts_with(&want), "{err}");
        assert!(err.ends_with(&format!("--downscale 2 would take about {}", bytes(half))));
        // Asked for 2 already, with room for 3.
        let halved = shots.clone().downscaled(2).unwrap();
        let err = check_room("d", (&shots, &halved), 2, third, LOADING)
            .unwrap_err()
            .to_string();
        assert!(err.ends_with(&format!("--downscale 3 would take about {}", bytes(third))));
        // Factors are tried up to 32.
        let err = check_room("d", (&shots, &shots), 1, 10, LOADING)
            .unwrap_err()
            .to_string();
        assert!(err.ends_with("not even --downscale 32 fits"), "{err}");
    }

    /// Training on the CPU adds a step's buffers on the largest view to the views: where that
    /// is more than loading takes, it is what is checked, and what the error explains.
    #[test]
    fn training_on_the_cpu_counts_a_step_on_the_largest_view() {
        let dir = tempfile::tempdir().unwrap();
        let shots = shots(dir.path());
        let need = shots.footprint().unwrap();
        let (held, pixels) = (3 * 64 * 48 * 4, 64 * 48);
        assert_eq!((need.held, need.largest), (held, pixels));
        let cpu = Demand {
            step: Some(CPU_STEP_BYTES_PER_PIXEL),
            ..LOADING
        };
        let training = held + CPU_STEP_BYTES_PER_PIXEL * pixels;
        assert!(training > need.peak(2), "the step is what binds here");
        check_room("d", (&shots, &shots), 1, training, cpu).unwrap();
        // Room to load, not to train: refused on the CPU, not on a GPU.
        check_room("d", (&shots, &shots), 1, training - 1, LOADING).unwrap();
        let err = check_room("d", (&shots, &shots), 1, training - 1, cpu)
            .unwrap_err()
            .to_string();
        let step = bytes(CPU_STEP_BYTES_PER_PIXEL * pixels);
        let want = format!(
            "d: training on its 3 views on the CPU takes about {} of memory ({} held by the views, {step} for a step on the largest, of 3072 pixels)",
            bytes(training),
            bytes(held),
        );
        assert!(err.starts_with(&want), "{err}");
        let halved = shots.clone().downscaled(2).unwrap().footprint().unwrap();
        let peak = bytes(cpu.of(&halved));
        assert!(
            err.ends_with(&format!("--downscale 2 would take about {peak}")),
            "{err}"
        );
    }

    #[test]
    fn a_start_that_cannot_be_held_is_refused() {
        check_start(1000, 59, 1000 * 59 * 4 * PRIMITIVE_COPIES).unwrap();
        let err = check_start(99_999_999_999, 59, 20_000_000_000)
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "--points 99999999999: training 99999999999 primitives of 59 words takes about 141.6 TB of memory, and 20.0 GB is available"
        );
    }

    #[test]
    fn a_dataset_too_big_to_hold_is_not_rendered() {
        check_rendered_views(80, 200, 200, 1 << 30).unwrap();
        let err = check_rendered_views(1_000_000_000, 11, 11, 1 << 30)
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("--views 1000000000 of 11x11: the views are held until the dataset is written, about 1.9 TB of memory"),
            "{err}"
        );
    }

    #[test]
    fn a_frame_too_big_to_hold_is_not_rendered() {
        check_render(8192, 8192, 8 << 30).unwrap();
        let err = check_render(16384, 16384, 8 << 30).unwrap_err().to_string();
        assert_eq!(
            err,
            "rendering 16384x16384 pixels takes about 21.5 GB of memory, and 8.6 GB is available"
        );
    }

    #[test]
    fn this_machine_says_how_much_memory_is_left() {
        let room = available().expect("Linux says what memory is available");
        assert!(room > 0);
    }
}
