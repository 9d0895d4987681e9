use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32) -> f32 {
        let k = x as u32;
        k as f32 * x
    }
}

fn main() {}
