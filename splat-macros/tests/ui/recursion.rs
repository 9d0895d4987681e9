use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32) -> f32 {
        g(x)
    }

    fn g(x: f32) -> f32 {
        g(x * 0.5)
    }
}

fn main() {}
