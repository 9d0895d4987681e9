//! How the CPU backend scales with threads: 3DGS on the render bench's scene, forward and
//! backward, per stage, in rayon pools of 1, 2, 4, ... threads up to the machine's cores; each
//! figure is the best of 3 after a warm-up, with the speed-up over one thread.
//!
//! `cargo bench -p splat-methods --bench scaling [-- N WIDTH HEIGHT]`

use splat_methods::gs3d::Method;
use splat_runtime::{FrameGrad, RenderOptions, backward, render_for_backward};
use std::time::{Duration, Instant};

mod common;
use common::{camera, scene, size_args};

const STAGES: [&str; 7] = [
    "preprocess",
    "rasterize",
    "shade",
    "forward",
    "backward blend",
    "reduce (workers' sums)",
    "project adjoint",
];

fn main() {
    let (n, w, h) = size_args(1_000_000, 1920, 1080);
    let params = scene(n);
    let camera = camera(w, h);
    let opts = RenderOptions::default();
    let pixels = (w * h) as usize;
    let grad = FrameGrad {
        color: vec![1.0 / pixels as f32; pixels * 3],
        alpha: None,
        depth: None,
    };
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    println!("3DGS, {n} Gaussians (SH degree 3), {w}x{h}, tile 16; {cores} cores");
    let run = || {
        let t = Instant::now();
        let (frame, state) = render_for_backward::<Method>(&params, &camera, &opts).unwrap();
        let forward = t.elapsed();
        let g = backward::<Method>(&state, &params, &camera, &grad).unwrap();
        let s = frame.stats;
        [
            s.preprocess,
            s.rasterize,
            s.shade,
            forward,
            g.stats.blend,
            g.stats.reduce,
            g.stats.project,
        ]
    };
    let threads: Vec<usize> = std::iter::successors(Some(1), |t| Some(t * 2))
        .take_while(|t| *t <= cores)
        .collect();
    let mut rows = vec![];
    for &t in &threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        let best = pool.install(|| {
            run();
            (0..3)
                .map(|_| run())
                .fold([Duration::MAX; STAGES.len()], |b, r| {
                    std::array::from_fn(|k| b[k].min(r[k]))
                })
        });
        rows.push(best);
    }
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    print!("\n| stage |");
    for t in &threads {
        print!(" {t} thread{} (ms) |", if *t == 1 { "" } else { "s" });
    }
    println!(" speed-up at {} |", threads.last().unwrap());
    println!("|---|{}---:|", "---:|".repeat(threads.len()));
    for (k, name) in STAGES.iter().enumerate() {
        print!("| {name} |");
        for r in &rows {
            print!(" {:.1} |", ms(r[k]));
        }
        println!(" {:.2}x |", ms(rows[0][k]) / ms(rows.last().unwrap()[k]));
    }
}
