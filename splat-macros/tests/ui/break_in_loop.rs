use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32) -> f32 {
        let mut y = x;
        for i in 0..4 {
            y = y * x;
            break;
        }
        y
    }
}

fn main() {}
