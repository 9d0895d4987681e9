use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32) -> f32 {
        let mut y = x;
        while y > 1.0 {
            y = y * 0.5;
        }
        y
    }
}

fn main() {}
