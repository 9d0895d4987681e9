//! The feasibility step of the hardware backward (issue 63): a fragment shader's
//! read-modify-write of its pixel in rasterization order, through wgpu's device and a raw
//! Vulkan pass (`splat_gpu::programmable_blend`). Prints, per order, how many pixels end
//! differently from the fold in draw order and what the pass took.
//!
//! `cargo run --release -p splat-gpu --example raster_order -- [width height draws runs]`

use splat_gpu::programmable_blend::{self, Order};

fn main() {
    let args: Vec<u32> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("a number"))
        .collect();
    let arg = |i: usize, default: u32| args.get(i).copied().unwrap_or(default);
    let (width, height, draws, runs) = (arg(0, 256), arg(1, 256), arg(2, 256), arg(3, 5));
    let support = programmable_blend::support().unwrap_or_else(|e| panic!("{e}"));
    println!("{support:?}");
    let gpu = match programmable_blend::open() {
        Ok(Some(gpu)) => gpu,
        Ok(None) => {
            eprintln!("the adapter lacks rasterization-order attachment access");
            std::process::exit(2);
        }
        Err(e) => panic!("{e}"),
    };
    let want = programmable_blend::fold_in_order(width, height, draws);
    let reached = programmable_blend::reached_by_draw(width, height, draws);
    let fragments: u64 = reached.iter().map(|&r| u64::from(r)).sum();
    println!(
        "{}: {width}x{height}, {draws} draws, {fragments} fragments kept of {}",
        gpu.adapter,
        width as u64 * height as u64 * draws as u64
    );
    for order in [Order::Rasterization, Order::Unspecified] {
        for run in 0..runs {
            let fold = programmable_blend::fold(&gpu, width, height, draws, order)
                .unwrap_or_else(|e| panic!("{e}"));
            let (got, time) = (&fold.values, fold.time);
            let wrong = got.iter().zip(&want).filter(|(g, w)| g != w).count();
            assert_eq!(fold.reached, reached, "fragments per draw");
            println!(
                "{order:?} run {run}: {wrong} of {} pixels differ from the fold in draw order; {:.2} ms ({:.1} ns per fragment)",
                got.len(),
                time.as_secs_f64() * 1e3,
                time.as_secs_f64() * 1e9 / fragments as f64
            );
        }
    }
}
