use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(a: [f32; 4], i: u32) -> f32 {
        a[i]
    }
}

fn main() {}
