use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32, n: u32) -> f32 {
        let mut y = x;
        for _ in 0..n {
            y = y * x;
        }
        y
    }
}

fn main() {}
